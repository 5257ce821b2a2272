"""Print-ready ``tags.pdf``: every placed tag at its exact physical size, tiled when the paper
is too small.

Units are millimetres on paper (PDF points = mm x 72 / 25.4; reportlab draws in points with
exact floating-point coordinates). A tag's *sheet* is the drawn square (black square plus the
white quiet zone, edge :func:`markerplace.tagfamily.outer_size`) and, under it, the caption of
:func:`markerplace.report.printable.caption_for` (the caption marks the bottom edge).

Per tag, in placement order:

* **fits the paper** (sheet inside the printable area, portrait or landscape): one page, the
  sheet centred, a 100 mm check bar in the bottom margin ("print at 100 %").
* **larger than the paper**: a *page map* (the whole tag scaled down with the tile grid, tile
  names A1, A2, ... row letter from the top, column number from the left, the caption and the
  instructions), then one page per tile at exact size. Neighbouring tiles share an
  ``overlap``-wide strip of identical content; alignment crosshairs (thin cyan circles and
  crosses) sit at the same tag coordinates on both tiles of every strip, so laying one tile
  over the other with the crosshairs on top of each other restores the tag exactly. Each tile
  page names the tile, its neighbours and the tag, and has the check bar.
* ``paper="none"``: one page per tag at the sheet's own size plus a white margin (for a print
  shop or a plotter).

Every page names its tag (placement order and id); a tile page also names its tile (row and
column of rows x columns). :func:`markerplace.report.sheets.sheet_plan` says which pages hold which tag before anything is
written (placement.csv lists them); :func:`write_tags_pdf` logs the sheets per tag and in all,
and advises (an INFO line) when a tag takes more than ``MAX_SHEETS_PER_TAG`` sheets, with what the alternatives
cost (:mod:`markerplace.report.sheets`, which also has the tiling geometry).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Sequence

from markerplace.report.printable import black_runs, caption_for, tag_modules
from markerplace.report.sheets import MARGIN_MM, PAPERS_MM, TileLayout, caption_block_mm, check_paper, sheet_advice, sheet_plan
from markerplace.runtime.atomic_io import atomic_path
from markerplace.tagfamily import outer_size

log = logging.getLogger(__name__)

CHECK_BAR_MM = 100.0
"""Length of the printed check bar (measure it: the print is exact when it is 100 mm)."""
MARK_RGB = (0.0, 1.0, 1.0)
"""Alignment marks in cyan: visible on black and white, light enough for the detector."""
PT_PER_MM = 72.0 / 25.4


class _Pdf:
    """A reportlab canvas with a top-left millimetre coordinate helper."""

    def __init__(self, path: Path, title: str):
        from reportlab.pdfgen.canvas import Canvas

        self.c = Canvas(str(path), invariant=1, pageCompression=1)
        self.c.setTitle(title)
        self.c.setCreator("markerplace")
        self.h = 0.0

    def page(self, size_mm: tuple[float, float]) -> None:
        self.c.setPageSize((size_mm[0] * PT_PER_MM, size_mm[1] * PT_PER_MM))
        self.h = size_mm[1]

    def xy(self, x: float, y: float) -> tuple[float, float]:
        """Points from millimetres measured from the page's top-left corner (y down)."""
        return x * PT_PER_MM, (self.h - y) * PT_PER_MM

    def text(self, x: float, y: float, s: str, size_mm: float, anchor: str = "left") -> None:
        self.c.setFont("Helvetica", size_mm * PT_PER_MM)
        px, py = self.xy(x, y)
        {"left": self.c.drawString, "centre": self.c.drawCentredString, "right": self.c.drawRightString}[anchor](px, py, s)

    def modules(self, tag_id: int, x0: float, y0: float, edge: float, clip=None) -> None:
        """The tag (quiet zone included) as one filled path, square top-left at (x0, y0) mm;
        ``clip`` (x, y, w, h) mm limits the drawing (tiles)."""
        c = self.c
        bits = tag_modules(tag_id)
        n = bits.shape[0]
        cell = edge / n
        c.saveState()
        if clip is not None:
            p = c.beginPath()
            px, py = self.xy(clip[0], clip[1] + clip[3])
            p.rect(px, py, clip[2] * PT_PER_MM, clip[3] * PT_PER_MM)
            c.clipPath(p, stroke=0, fill=0)
        c.setFillColorRGB(1, 1, 1)
        px, py = self.xy(x0, y0 + edge)
        c.rect(px, py, edge * PT_PER_MM, edge * PT_PER_MM, stroke=0, fill=1)
        path = c.beginPath()
        for r, col, end in black_runs(bits):
            px, py = self.xy(x0 + col * cell, y0 + (r + 1) * cell)
            path.rect(px, py, (end - col) * cell * PT_PER_MM, cell * PT_PER_MM)
        c.setFillColorRGB(0, 0, 0)
        c.drawPath(path, stroke=0, fill=1)
        c.restoreState()

    def check_bar(self, page_mm: tuple[float, float]) -> None:
        """A 100 mm bar, 2 mm high, in the bottom margin, with its label."""
        x, y = (page_mm[0] - CHECK_BAR_MM) / 2, page_mm[1] - MARGIN_MM / 2
        self.c.setFillColorRGB(0, 0, 0)
        px, py = self.xy(x, y)
        self.c.rect(px, py, CHECK_BAR_MM * PT_PER_MM, 1.5 * PT_PER_MM, stroke=0, fill=1)
        self.text(page_mm[0] / 2, y + 4.0, "this bar is 100 mm when printed at 100 % (actual size)", 2.6, "centre")

    def mark(self, x: float, y: float) -> None:
        """An alignment crosshair at (x, y) mm: a 3 mm circle and a 10 mm cross."""
        c = self.c
        c.setStrokeColorRGB(*MARK_RGB)
        c.setLineWidth(0.35 * PT_PER_MM)
        px, py = self.xy(x, y)
        c.circle(px, py, 3.0 * PT_PER_MM, stroke=1, fill=0)
        c.line(px - 5 * PT_PER_MM, py, px + 5 * PT_PER_MM, py)
        c.line(px, py - 5 * PT_PER_MM, px, py + 5 * PT_PER_MM)


def _single_page(pdf: _Pdf, rec: dict, page: tuple[float, float], with_bar: bool) -> None:
    edge = 1000.0 * outer_size(rec["size"])
    lines = caption_for(rec)
    strip, pitch, font = caption_block_mm(edge, lines)
    pdf.page(page)
    x0, y0 = (page[0] - edge) / 2, (page[1] - edge - strip) / 2
    pdf.modules(rec["tag_id"], x0, y0, edge)
    pdf.c.setFillColorRGB(0, 0, 0)
    for i, line in enumerate(lines):
        pdf.text(page[0] / 2, y0 + edge + (i + 1) * pitch, line, font, "centre")
    if with_bar:
        pdf.check_bar(page)
    pdf.c.showPage()


def _tag_name(rec: dict) -> str:
    """How every page names its tag: ``"tag #2, id 7"`` (placement order, tag36h11 id)."""
    return f"tag #{rec['order']}, id {rec['tag_id']}"


def _page_map(pdf: _Pdf, rec: dict, lay: TileLayout, paper: str) -> None:
    """The overview page of a tiled tag: scaled tag, tile grid, caption, instructions."""
    page = PAPERS_MM[paper]
    pdf.page(page)
    c = pdf.c
    c.setFillColorRGB(0, 0, 0)
    y = MARGIN_MM + 6
    pdf.text(MARGIN_MM, y, f"Page map of {_tag_name(rec)}: {lay.rows} x {lay.cols} tiles on {paper.upper()} "
                           f"({lay.rows} rows, {lay.cols} columns)", 5.0)
    for line in caption_for(rec)[1:-1]:
        y += 6
        pdf.text(MARGIN_MM, y, line, 3.6)
    box = min(page[0] - 2 * MARGIN_MM, page[1] * 0.5)
    scale = box / lay.edge
    bx, by = (page[0] - box) / 2, y + 8
    pdf.modules(rec["tag_id"], bx, by, box)
    c.setStrokeColorRGB(0.9, 0.1, 0.1)
    c.setLineWidth(0.4 * PT_PER_MM)
    for t in lay.tiles:
        x0, y0, x1, y1 = (v * scale for v in t.region)
        px, py = pdf.xy(bx + x0, by + y1)
        c.rect(px, py, (x1 - x0) * PT_PER_MM, (y1 - y0) * PT_PER_MM, stroke=1, fill=0)
    c.setFillColorRGB(0.9, 0.1, 0.1)
    for t in lay.tiles:
        x0, y0, x1, y1 = (v * scale for v in t.region)
        pdf.text(bx + (x0 + x1) / 2, by + (y0 + y1) / 2 + 2, t.name, 6.0, "centre")
    c.setFillColorRGB(0, 0, 0)
    pdf.text(page[0] / 2, by + box + 5, "this edge down", 3.6, "centre")
    y = by + box + 12
    steps = [
        "1. Print every page at 100 % (actual size, no 'fit to page'); the bar at the bottom of each page must be 100 mm.",
        "2. Lay the tiles out as above: rows A, B, ... from the top, columns 1, 2, ... from the left.",
        f"3. Neighbouring tiles share a {lay.overlap:.0f} mm strip with cyan crosshairs: trim the white margin of one",
        "    tile along the printed edge, lay it over its neighbour so every crosshair sits exactly on its twin,",
        "    and tape from the back. Work row by row, then join the rows.",
        f"4. The assembled black square must measure {1000 * rec['size']:.0f} mm; hang it with row "
        f"{lay.tiles[-1].name[0]} at the bottom (marked 'this edge down').",
    ]
    for s in steps:
        pdf.text(MARGIN_MM, y, s, 3.0)
        y += 5
    pdf.check_bar(page)
    c.showPage()


def _tile_pages(pdf: _Pdf, rec: dict, lay: TileLayout) -> None:
    names = {(t.row, t.col): t.name for t in lay.tiles}
    marks = lay.marks()
    for t in lay.tiles:
        pdf.page(lay.page)
        x0, y0, x1, y1 = t.region
        ox, oy = t.page_origin
        pdf.modules(rec["tag_id"], ox - x0, oy - y0, lay.edge, clip=(ox, oy, x1 - x0, y1 - y0))
        for mx, my in marks:
            if x0 <= mx <= x1 and y0 <= my <= y1:
                pdf.mark(ox + mx - x0, oy + my - y0)
        c = pdf.c
        c.setStrokeColorRGB(0.6, 0.6, 0.6)  # trim corners: where the printed region ends
        c.setLineWidth(0.2 * PT_PER_MM)
        for cx, cy in ((ox, oy), (ox + x1 - x0, oy), (ox, oy + y1 - y0), (ox + x1 - x0, oy + y1 - y0)):
            for dx, dy in ((-4, 0), (4, 0), (0, -4), (0, 4)):
                inside = (ox <= cx + dx <= ox + x1 - x0) and (oy <= cy + dy <= oy + y1 - y0)
                if not inside:
                    c.line(*pdf.xy(cx, cy), *pdf.xy(cx + dx, cy + dy))
        around = [f"{side} {names[(t.row + dr, t.col + dc)]}" for side, dr, dc in
                  (("above", -1, 0), ("left", 0, -1), ("right", 0, 1), ("below", 1, 0))
                  if (t.row + dr, t.col + dc) in names]
        c.setFillColorRGB(0, 0, 0)
        pdf.text(MARGIN_MM, oy - 6, f"{_tag_name(rec)}  -  tile {t.name}: row {t.row + 1} of {lay.rows}, column "
                                    f"{t.col + 1} of {lay.cols}  -  {', '.join(around)}", 3.2)
        if t.row == lay.rows - 1:
            pdf.text(ox + (x1 - x0) / 2, oy + (y1 - y0) + 4, "this edge down", 3.2, "centre")
        pdf.check_bar(lay.page)
        c.showPage()


def write_tags_pdf(path: str | Path, records: Sequence[dict], paper: str = "a4") -> int:
    """Write ``tags.pdf`` for ``placement.json`` marker records (see module docstring), atomically;
    log the sheets it takes first (and advise when a tag takes too many: :func:`sheet_advice`; an
    INFO line, so ``--quiet`` hides it).

    Args:
        path: output file.
        records: dicts with ``order``, ``tag_id``, ``family``, ``size`` (metres) and either an
            ``install`` object (:mod:`markerplace.report.instructions`) or ``position`` and
            ``yaw_deg`` (the caption's fields).
        paper: ``a4``, ``letter``, ``a3`` or ``none`` (one page per tag at its own size).

    Returns:
        The number of pages (the last page of :func:`sheet_plan`).
    """
    paper = check_paper(paper)
    plan = sheet_plan(records, paper)
    if records:
        summary, warning = sheet_advice(records, paper)
        log.info("%s", summary)
        if warning:  # advice on the print volume, not a problem: --quiet hides it
            log.info("%s", warning)
    with atomic_path(path) as tmp:
        pdf = _Pdf(tmp, "markerplace tags")
        for rec, t in zip(records, plan):
            if t.layout is None:
                _single_page(pdf, rec, t.page, with_bar=paper != "none")
            else:
                _page_map(pdf, rec, t.layout, paper)
                _tile_pages(pdf, rec, t.layout)
        pages = sum(t.count for t in plan)
        if not records:
            pdf.page(PAPERS_MM.get(paper, PAPERS_MM["a4"]))
            pdf.text(MARGIN_MM, MARGIN_MM + 6, "no tags placed", 5.0)
            pdf.c.showPage()
            pages = 1
        pdf.c.save()
    return pages
