"""Print-ready tag sheets: one SVG per placed marker, at its exact physical size.

Each file is a vector drawing (millimetre units, so any printer or print shop reproduces the
size exactly) of the tag36h11 pattern with its white quiet zone (:func:`markerplace.tagfamily.
outer_size`), and below it a caption strip: placement order, tag id, black-square size, where
it hangs (storey, wall, height, distance along the wall) and "this edge down". The caption is
outside the quiet zone, so it never touches the pattern, and it marks the tag's bottom edge:
hang the sheet caption-side down.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence
from xml.sax.saxutils import escape

import numpy as np

from markerplace.report.instructions import caption_lines
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import atomic_path
from markerplace.tagfamily import QUIET_BITS, TAG_BITS, outer_size, tag_image


def tag_modules(tag_id: int) -> np.ndarray:
    """(B, B) bool, True = black, of the tag with its quiet zone; B = TAG_BITS + 2 QUIET_BITS.

    Row 0 is the tag's top edge.
    """
    return tag_image(tag_id, pixels_per_bit=1) < 128


def black_runs(modules: np.ndarray) -> list[tuple[int, int, int]]:
    """Horizontal runs of black modules, one rectangle each when drawn: (row, first column, end
    column (exclusive)) for every run in the (n, n) bool ``modules`` (True = black), row by row."""
    runs = []
    n = modules.shape[1]
    for r in range(modules.shape[0]):
        c = 0
        while c < n:
            if modules[r, c]:
                end = c
                while end < n and modules[r, end]:
                    end += 1
                runs.append((r, c, end))
                c = end
            else:
                c += 1
    return runs


def tag_svg(tag_id: int, size_m: float, caption: Sequence[str]) -> str:
    """SVG document of one tag at physical size.

    Args:
        tag_id: tag36h11 id.
        size_m: black-square edge, metres.
        caption: lines of text printed under the quiet zone.

    Returns:
        SVG text; width = outer edge and height = outer edge + caption strip, in mm. Black
        modules are drawn as horizontal runs of rectangles on a white background; the caption
        font is as large as the strip allows while the longest line fits the width.
    """
    modules = tag_modules(tag_id)
    bits = TAG_BITS + 2 * QUIET_BITS
    edge_mm = outer_size(size_m) * 1000.0
    cell = edge_mm / bits
    lines = list(caption) or [""]
    line_mm = max(6.0, 0.04 * edge_mm)
    strip = line_mm * (len(lines) + 0.5)
    # about 0.55 em per glyph in a sans-serif font: keep the longest line inside the width
    font = min(0.75 * line_mm, 0.95 * edge_mm / (0.55 * max(1, max(len(t) for t in lines))))
    rects = [f'<rect x="{c * cell:.4f}" y="{r * cell:.4f}" width="{(c1 - c) * cell:.4f}" height="{cell:.4f}"/>'
             for r, c, c1 in black_runs(modules)]
    height = edge_mm + strip
    texts = [f'<text x="{edge_mm / 2:.4f}" y="{edge_mm + (i + 1) * line_mm:.4f}" xml:space="preserve" '
             f'font-family="sans-serif" font-size="{font:.3f}" text-anchor="middle" fill="black">'
             f'{escape(t)}</text>' for i, t in enumerate(lines)]
    return "\n".join([
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{edge_mm:.3f}mm" height="{height:.3f}mm" '
        f'viewBox="0 0 {edge_mm:.4f} {height:.4f}">',
        f'<rect x="0" y="0" width="{edge_mm:.4f}" height="{height:.4f}" fill="white"/>',
        '<g fill="black" shape-rendering="crispEdges">', *rects, "</g>", *texts, "</svg>", ""])


def caption_for(record: dict) -> list[str]:
    """Caption lines of a ``placement.json`` marker record: order, id and size; where it hangs
    (from its ``install`` object: storey, wall, height above the floor, distance to the nearer
    corner or door edge); "this edge down" (:func:`markerplace.report.instructions.caption_lines`)."""
    return caption_lines(record)


def write_tag_sheets(folder: str | Path, records: Sequence[dict]) -> list[Path]:
    """Write ``NN_tag<id>.svg`` for each marker record (see :func:`caption_for`), atomically;
    SVGs an earlier plan wrote in ``folder`` that are not part of this one are removed (other
    files are left alone: :func:`markerplace.runtime.run_folder.remove_stale`).

    Returns the written paths in placement order.
    """
    folder = Path(folder)
    paths = []
    for rec in records:
        path = folder / f"{rec['order']:02d}_tag{rec['tag_id']}.svg"
        with atomic_path(path) as tmp:
            tmp.write_text(tag_svg(rec["tag_id"], rec["size"], caption_for(rec)))
        paths.append(path)
    run_folder.remove_stale(folder, paths, "*.svg")
    return paths
