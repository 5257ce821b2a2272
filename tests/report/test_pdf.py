"""tags.pdf: exact physical size at 300 dpi (pdftoppm), every tag detected back, tiled tags
reassembled from their pages by the tiling geometry."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers import printed_tags
from markerplace.errors import UserError
from markerplace.report.pdf import write_tags_pdf
from markerplace.report.printable import caption_for
from markerplace.report.sheets import MARGIN_MM, PAPERS_MM, caption_block_mm, tile_layout
from markerplace.tagfamily import outer_size

DPI = 300
PX_PER_MM = DPI / 25.4


def record(order, tag_id, size):
    return {"order": order, "tag_id": tag_id, "family": "tag36h11", "size": size,
            "position": [1.0 * order, 2.0, 1.5], "yaw_deg": 90.0}


def rasterize(pdf: Path, out: Path, dpi: int = DPI) -> list[np.ndarray]:
    return printed_tags.rasterize(pdf, out, dpi)


def black_bbox_mm(img: np.ndarray) -> tuple[float, float]:
    """Width and height (mm) of the bounding box of the dark (< 128) pixels."""
    ys, xs = np.nonzero(img < 128)
    return (xs.max() - xs.min() + 1) / PX_PER_MM, (ys.max() - ys.min() + 1) / PX_PER_MM


def detect(img: np.ndarray, shrink: int = 1) -> list[int]:
    import cv2

    from markerplace.localization.tags import make_detector

    if shrink > 1:
        img = cv2.resize(img, (img.shape[1] // shrink, img.shape[0] // shrink), interpolation=cv2.INTER_AREA)
    return sorted(d.tag_id for d in make_detector().detect(np.ascontiguousarray(img)))


def crop_mm(img: np.ndarray, x: float, y: float, w: float, h: float) -> np.ndarray:
    return printed_tags.crop_mm(img, PX_PER_MM, x, y, w, h)


@pytest.fixture(scope="module")
def a4_pages(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pdf")
    recs = [record(1, 5, 0.12), record(2, 7, 0.4)]
    n = write_tags_pdf(folder / "tags.pdf", recs, "a4")
    pages = rasterize(folder / "tags.pdf", folder)
    assert len(pages) == n
    return recs, pages


def test_single_page_tag_is_exact_and_detected(a4_pages):
    recs, pages = a4_pages
    page = pages[0]
    w, h = PAPERS_MM["a4"]
    assert abs(page.shape[0] - h * PX_PER_MM) < 1 and abs(page.shape[1] - w * PX_PER_MM) < 1
    edge = 1000 * outer_size(0.12)
    strip = caption_block_mm(edge, caption_for(recs[0]))[0]
    x0, y0 = (w - edge) / 2, (h - edge - strip) / 2
    tag = crop_mm(page, x0 - 2, y0 - 2, edge + 4, edge + 4)  # the square and its quiet zone only
    bw, bh = black_bbox_mm(tag)
    assert abs(bw - 120.0) < 0.5 and abs(bh - 120.0) < 0.5, (bw, bh)
    assert detect(page) == [5]
    below = crop_mm(page, 0, y0 + edge + 1, w, strip)  # the caption is printed under the tag
    assert (below < 128).mean() > 0.002


def test_tiled_tag_reassembles_exactly_and_is_detected(a4_pages):
    recs, pages = a4_pages
    lay = tile_layout(1000 * outer_size(0.4), "a4")
    assert len(pages) == 1 + 1 + len(lay.tiles)  # single page, page map, tiles
    tiles = pages[2:]
    for t, img in zip(lay.tiles, tiles):  # every tile fits the printable area of its page
        x0, y0, x1, y1 = t.region
        assert abs(img.shape[0] - lay.page[1] * PX_PER_MM) < 1 and abs(img.shape[1] - lay.page[0] * PX_PER_MM) < 1
        assert t.page_origin[0] >= MARGIN_MM - 1e-9 and t.page_origin[1] >= MARGIN_MM - 1e-9
        assert t.page_origin[0] + x1 - x0 <= lay.page[0] - MARGIN_MM + 1e-9
        assert detect(img) == []  # no tile alone is a tag
    canvas = printed_tags.tape_tiles(lay, {t.name: img for t, img in zip(lay.tiles, tiles)}, PX_PER_MM)
    crops = {}
    for t, img in zip(lay.tiles, tiles):
        x0, y0, x1, y1 = t.region
        crops[t.row, t.col] = crop_mm(img, *t.page_origin, x1 - x0, y1 - y0)
    # shared strips print the same content (pattern and crosshairs) on both neighbours
    ov = int(lay.overlap * PX_PER_MM) - 2
    for (r, c), crop in crops.items():
        if (r, c + 1) in crops:
            right = crops[r, c + 1]
            a, b = crop[:, -ov:], right[:, 1:ov + 1]
            m = min(len(a), len(b))
            assert np.mean(np.abs(a[:m].astype(int) - b[:m].astype(int)) > 100) < 0.01
            assert (a < 250).any()  # the strip holds something to align (crosshairs at least)
    bw, bh = black_bbox_mm(canvas)
    assert abs(bw - 400.0) < 0.5 and abs(bh - 400.0) < 0.5, (bw, bh)
    assert detect(canvas, shrink=4) == [7]


def test_paper_none_gives_one_page_per_tag_at_its_own_size(tmp_path):
    recs = [record(1, 11, 0.2), record(2, 12, 0.1)]
    assert write_tags_pdf(tmp_path / "tags.pdf", recs, "none") == 2
    pages = rasterize(tmp_path / "tags.pdf", tmp_path)
    for rec, page in zip(recs, pages):
        edge = 1000 * outer_size(rec["size"])
        strip = caption_block_mm(edge, caption_for(rec))[0]
        assert abs(page.shape[1] / PX_PER_MM - (edge + 2 * MARGIN_MM)) < 0.2
        assert abs(page.shape[0] / PX_PER_MM - (edge + strip + 2 * MARGIN_MM)) < 0.2
        tag = crop_mm(page, MARGIN_MM - 2, MARGIN_MM - 2, edge + 4, edge + 4)
        bw, bh = black_bbox_mm(tag)
        assert abs(bw - 1000 * rec["size"]) < 0.5 and abs(bh - 1000 * rec["size"]) < 0.5
        assert detect(page, shrink=2) == [rec["tag_id"]]


@pytest.mark.parametrize("paper", ["a4", "letter", "a3"])
@pytest.mark.parametrize("edge", [150.0, 300.0, 615.0, 1500.0])
def test_tiles_cover_the_tag_with_shared_strips(paper, edge):
    lay = tile_layout(edge, paper)
    pw, ph = lay.page
    xs = sorted({t.region[0] for t in lay.tiles}) + [edge]
    for t in lay.tiles:
        x0, y0, x1, y1 = t.region
        assert x1 - x0 <= pw - 2 * MARGIN_MM + 1e-9 and y1 - y0 <= ph - 2 * MARGIN_MM + 1e-9
        assert 0 <= x0 < x1 <= edge + 1e-9 and 0 <= y0 < y1 <= edge + 1e-9
    assert max(t.region[2] for t in lay.tiles) == pytest.approx(edge)
    assert max(t.region[3] for t in lay.tiles) == pytest.approx(edge)
    if lay.cols > 1:  # neighbours overlap by exactly the strip
        a = [t for t in lay.tiles if t.row == 0]
        for left, right in zip(a, a[1:]):
            assert left.region[2] - right.region[0] == pytest.approx(lay.overlap)
        assert all(lay.overlap / 2 < m[0] % lay.steps[0] + lay.steps[0] for m in lay.marks())
    assert len(xs) == lay.cols + 1


def test_bad_paper_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match="--paper"):
        write_tags_pdf(tmp_path / "t.pdf", [record(1, 1, 0.1)], "b5")
