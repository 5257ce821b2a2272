"""How ``tags.pdf`` is laid out, before anything is drawn: papers, the tiling of a tag larger
than its paper (:func:`tile_layout`, the geometry tests reassemble tiled tags from), which pages
hold which tag (:func:`sheet_plan`, listed in placement.csv) and what printing costs in sheets
(:func:`sheet_advice`). :mod:`markerplace.report.pdf` draws the pages.

Units are millimetres on paper.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from markerplace.errors import UserError
from markerplace.report.printable import caption_for
from markerplace.tagfamily import outer_size

PAPERS_MM = {"a4": (210.0, 297.0), "letter": (215.9, 279.4), "a3": (297.0, 420.0)}
"""Portrait paper sizes (width, height), millimetres."""
PAPER_CHOICES = (*PAPERS_MM, "none")
MARGIN_MM = 12.0
"""White margin on every side of a page (office printers leave 4-6 mm unprinted)."""
OVERLAP_MM = 20.0
"""Width of the strip neighbouring tiles share."""
MAX_SHEETS_PER_TAG = 4
"""A tag that takes more sheets than this (page map included) gets a warning with alternatives."""


@dataclass(frozen=True)
class Tile:
    """One printed tile of a tag.

    Attributes:
        name: ``A1`` = top row, left column (row letter from the top, column number from the left).
        row, col: indices from the top-left.
        region: (x0, y0, x1, y1) millimetres on the tag square, origin at its top-left corner,
            y down: the part of the tag this tile shows (overlap strips included).
        page_origin: (x, y) millimetres from the page's top-left corner to the region's top-left.
    """

    name: str
    row: int
    col: int
    region: tuple[float, float, float, float]
    page_origin: tuple[float, float]


@dataclass(frozen=True)
class TileLayout:
    """How one tag square of edge ``edge`` mm is cut into ``rows`` x ``cols`` tiles on pages
    of ``page`` (width, height) mm; ``steps`` (x, y) is the distance between tile origins."""

    edge: float
    page: tuple[float, float]
    rows: int
    cols: int
    steps: tuple[float, float]
    overlap: float
    tiles: tuple[Tile, ...]

    def marks(self) -> list[tuple[float, float]]:
        """Alignment-mark centres (x, y) in tag millimetres: two per shared strip and tile edge."""
        out = []
        sx, sy = self.steps
        h_tile, w_tile = sy + self.overlap, sx + self.overlap
        for c in range(1, self.cols):  # vertical strips between columns
            x = c * sx + self.overlap / 2
            for r in range(self.rows):
                out += [(x, r * sy + f * h_tile) for f in (0.3, 0.7)]
        for r in range(1, self.rows):  # horizontal strips between rows
            y = r * sy + self.overlap / 2
            for c in range(self.cols):
                out += [(c * sx + f * w_tile, y) for f in (0.3, 0.7)]
        return out


def _split(edge: float, avail: float, overlap: float) -> tuple[int, float]:
    """(n, step): n tiles of width step + overlap <= avail covering [0, edge]."""
    if edge <= avail:
        return 1, edge
    n = math.ceil((edge - overlap) / (avail - overlap))
    return n, (edge - overlap) / n


def tile_layout(edge_mm: float, paper: str, margin: float = MARGIN_MM, overlap: float = OVERLAP_MM) -> TileLayout:
    """Tiling of a tag square of ``edge_mm`` onto ``paper`` (a name of :data:`PAPERS_MM`),
    portrait or landscape, whichever needs fewer pages (portrait on a tie). Tiles are all the
    same size and centred on their pages."""
    best = None
    for page in (PAPERS_MM[paper], PAPERS_MM[paper][::-1]):
        aw, ah = page[0] - 2 * margin, page[1] - 2 * margin
        cols, sx = _split(edge_mm, aw, overlap)
        rows, sy = _split(edge_mm, ah, overlap)
        if best is None or rows * cols < best[0]:
            best = (rows * cols, page, rows, cols, sx, sy)
    _, page, rows, cols, sx, sy = best
    w = sx + (overlap if cols > 1 else 0.0)
    h = sy + (overlap if rows > 1 else 0.0)
    origin = ((page[0] - w) / 2, (page[1] - h) / 2)
    tiles = tuple(Tile(f"{chr(65 + r) if r < 26 else 'R' + str(r + 1)}{c + 1}", r, c,
                       (c * sx, r * sy, c * sx + w, r * sy + h), origin)
                  for r in range(rows) for c in range(cols))
    return TileLayout(edge_mm, page, rows, cols, (sx, sy), overlap if rows * cols > 1 else 0.0, tiles)


def caption_block_mm(edge_mm: float, lines: Sequence[str]) -> tuple[float, float, float]:
    """(strip height, line pitch, font size) of the caption under a sheet of ``edge_mm``, as in
    :func:`markerplace.report.printable.tag_svg`."""
    line_mm = max(6.0, 0.04 * edge_mm)
    font = min(0.75 * line_mm, 0.95 * edge_mm / (0.55 * max(1, max(len(t) for t in lines))))
    return line_mm * (len(lines) + 0.5), line_mm, font


def _sheet_fits(sheet: tuple[float, float], paper: str) -> tuple[float, float] | None:
    """The page (portrait first, then landscape) whose printable area holds the sheet, or None."""
    for page in (PAPERS_MM[paper], PAPERS_MM[paper][::-1]):
        if sheet[0] <= page[0] - 2 * MARGIN_MM and sheet[1] <= page[1] - 2 * MARGIN_MM:
            return page
    return None


@dataclass(frozen=True)
class TagSheets:
    """Where one tag goes in ``tags.pdf``.

    Attributes:
        sheet: (width, height) mm of the tag's sheet (the square with its quiet zone, and the caption).
        page: (width, height) mm of its page (single page or ``paper="none"``), None when tiled.
        layout: its :class:`TileLayout` when tiled (a page map, then one page per tile), else None.
        first_page: 1-based number of its first page in the file.
    """

    sheet: tuple[float, float]
    page: tuple[float, float] | None
    layout: TileLayout | None
    first_page: int

    @property
    def count(self) -> int:
        """Sheets of paper the tag takes (a tiled tag's page map included)."""
        return 1 if self.layout is None else 1 + len(self.layout.tiles)

    @property
    def pages(self) -> list[int]:
        """1-based page numbers of the tag in ``tags.pdf``."""
        return list(range(self.first_page, self.first_page + self.count))

    @property
    def tiles(self) -> tuple[int, int]:
        """(rows, columns) of its tiles; (1, 1) on one page."""
        return (1, 1) if self.layout is None else (self.layout.rows, self.layout.cols)


def check_paper(paper: str) -> str:
    paper = str(paper).lower()
    if paper not in PAPER_CHOICES:
        raise UserError(f"--paper {paper!r} is not a paper size; use one of {', '.join(PAPER_CHOICES)}")
    return paper


def _tag_sheets(rec: dict, paper: str, first_page: int) -> TagSheets:
    edge = 1000.0 * outer_size(rec["size"])
    strip = caption_block_mm(edge, caption_for(rec))[0]
    sheet = (edge, edge + strip)
    if paper == "none":
        return TagSheets(sheet, (sheet[0] + 2 * MARGIN_MM, sheet[1] + 2 * MARGIN_MM), None, first_page)
    page = _sheet_fits(sheet, paper)
    if page is not None:
        return TagSheets(sheet, page, None, first_page)
    return TagSheets(sheet, None, tile_layout(edge, paper), first_page)


def sheet_plan(records: Sequence[dict], paper: str = "a4") -> list[TagSheets]:
    """Where each marker record goes in ``tags.pdf`` (one :class:`TagSheets` per record, in order)."""
    paper = check_paper(paper)
    out, page = [], 1
    for rec in records:
        out.append(_tag_sheets(rec, paper, page))
        page += out[-1].count
    return out


def _sheets_words(t: TagSheets, paper: str) -> str:
    if t.layout is None:
        return "1 sheet" if paper != "none" else f"1 page of {t.page[0]:.0f} x {t.page[1]:.0f} mm"
    return f"{t.count} {paper.upper()} sheets (a page map and {t.layout.rows} x {t.layout.cols} tiles to tape)"


def sheet_advice(records: Sequence[dict], paper: str) -> tuple[str, str | None]:
    """What printing ``records`` on ``paper`` takes, in words: (summary, warning or None).

    The warning (when a tag takes more than :data:`MAX_SHEETS_PER_TAG` sheets) offers A3, a print
    shop (``--paper none``) and the largest ``--tag-size`` that fits the limit on ``paper``, with
    the detection range it costs (roughly proportional to the tag's size).
    """
    paper = check_paper(paper)
    plan = sheet_plan(records, paper)
    total = sum(t.count for t in plan)
    groups: dict[tuple[float, str], int] = {}
    for r, t in zip(records, plan):
        key = (float(r["size"]), _sheets_words(t, paper))
        groups[key] = groups.get(key, 0) + 1
    where = "pages of their own size" if paper == "none" else paper.upper()
    summary = (f"tags.pdf: {len(records)} tag(s) on {where}: "
               + "; ".join(f"{n} tag(s) of {size:g} m, {words} each" for (size, words), n in groups.items())
               + f"; {total} sheet(s) in all")
    big = [(r, t) for r, t in zip(records, plan) if t.count > MAX_SHEETS_PER_TAG]
    if not big:
        return summary, None
    rec, worst = max(big, key=lambda rt: rt[1].count)
    options = []
    if paper != "a3":
        a3 = sheet_plan(records, "a3")
        options.append(f"--paper a3 ({max(t.count for t in a3)} sheets per tag, {sum(t.count for t in a3)} in all)")
    sheet = _tag_sheets(rec, "none", 1).page
    options.append(f"--paper none for a print shop or a plotter (one {sheet[0]:.0f} x {sheet[1]:.0f} mm page per tag)")
    size = float(rec["size"])
    fit = next((c / 100 for c in range(int(size * 100) - 1, 4, -1)
                if _tag_sheets({**rec, "size": c / 100}, paper, 1).count <= MAX_SHEETS_PER_TAG), None)
    if fit is not None:
        n = _tag_sheets({**rec, "size": fit}, paper, 1).count
        options.append(f"a smaller --tag-size: {fit:.2f} m takes {n} {paper.upper()} sheet(s) per tag, but detection "
                       f"range is roughly proportional to tag size, so it is seen from about {100 * fit / size:.0f} % "
                       f"as far as a {size:g} m tag")
    warning = (f"tags.pdf: a {size:g} m tag takes {worst.count} {paper.upper()} sheets to print and tape "
               f"({len(big)} such tag(s), {sum(t.count for _, t in big)} sheets); for fewer sheets use "
               + "; or ".join(options))
    return summary, warning
