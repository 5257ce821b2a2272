"""tags.pdf as a person gets it: pages rasterized by poppler's pdftoppm, words read by
pdftotext, tiles taped together. Shared by the PDF tests and the install round trip."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
from PIL import Image


def rasterize(pdf: Path, out: Path, dpi: int, first: int | None = None, last: int | None = None) -> list[np.ndarray]:
    """Grey pages of ``pdf`` at ``dpi`` (pdftoppm, anti-aliased as a screen or printer would);
    ``first``/``last``: 1-based page range (default all)."""
    assert shutil.which("pdftoppm"), "pdftoppm missing: scripts/setup.sh installs poppler-utils"
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("p-*.pgm"):
        old.unlink()
    cmd = ["pdftoppm", "-r", str(dpi), "-gray"]
    if first is not None:
        cmd += ["-f", str(first), "-l", str(last if last is not None else first)]
    subprocess.run([*cmd, str(pdf), str(out / "p")], check=True)
    return [np.asarray(Image.open(p)) for p in sorted(out.glob("p-*.pgm"), key=lambda p: int(p.stem.split("-")[-1]))]


def page_text(pdf: Path, page: int) -> str:
    """The words of one page (1-based) as pdftotext reads them."""
    assert shutil.which("pdftotext"), "pdftotext missing: scripts/setup.sh installs poppler-utils"
    return subprocess.run(["pdftotext", "-f", str(page), "-l", str(page), "-layout", str(pdf), "-"],
                          check=True, capture_output=True, text=True).stdout


def crop_mm(img: np.ndarray, px_per_mm: float, x: float, y: float, w: float, h: float) -> np.ndarray:
    """The part of a page image from (x, y) mm (top-left, y down), w x h mm."""
    r0, c0 = int(round(y * px_per_mm)), int(round(x * px_per_mm))
    return img[r0:r0 + int(round(h * px_per_mm)), c0:c0 + int(round(w * px_per_mm))]


def tape_tiles(layout, tiles: dict[str, np.ndarray], px_per_mm: float) -> np.ndarray:
    """Tape tiled pages into the whole square (quiet zone included), as the page map says: each
    tile's printed region (``layout.tiles``: its place on the page and in the square) laid over
    its neighbours' shared strips. ``tiles``: tile name (``A1``, ...) -> page image.

    Returns (n, n) uint8, n = the square's edge in pixels; row 0 is the top (row A).
    """
    n = int(round(layout.edge * px_per_mm))
    canvas = np.full((n, n), 255, np.uint8)
    for t in layout.tiles:
        x0, y0, x1, y1 = t.region
        crop = crop_mm(tiles[t.name], px_per_mm, *t.page_origin, x1 - x0, y1 - y0)
        r0, c0 = int(round(y0 * px_per_mm)), int(round(x0 * px_per_mm))
        canvas[r0:r0 + crop.shape[0], c0:c0 + crop.shape[1]] = crop[: n - r0, : n - c0]
    return canvas


TILE_WORDS = re.compile(r"tag #(\d+), id (\d+) - tile ([A-Z]+\d+): row (\d+) of (\d+), column (\d+) of (\d+)")
"""What a tile page says about itself (pdf.py's footer)."""
