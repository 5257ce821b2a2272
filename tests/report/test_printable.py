"""Print-ready tag SVGs: exact physical size, the right pattern (detected back), captions."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from markerplace.report.printable import caption_for, tag_modules, tag_svg, write_tag_sheets
from markerplace.tagfamily import outer_size

NS = "{http://www.w3.org/2000/svg}"


def rasterize(svg: str, px_per_mm: float) -> np.ndarray:
    """Draw the SVG's black rectangles (the tag part only) into a uint8 image."""
    root = ET.fromstring(svg)
    w = float(root.get("width").removesuffix("mm"))
    img = np.full((int(round(w * px_per_mm)),) * 2, 255, np.uint8)
    for g in root.iter(f"{NS}g"):
        for r in g.iter(f"{NS}rect"):
            x0, y0 = float(r.get("x")) * px_per_mm, float(r.get("y")) * px_per_mm
            x1 = x0 + float(r.get("width")) * px_per_mm
            y1 = y0 + float(r.get("height")) * px_per_mm
            img[int(round(y0)):int(round(y1)), int(round(x0)):int(round(x1))] = 0
    return img


@pytest.mark.parametrize("tag_id, size", [(0, 0.4), (17, 0.15), (586, 0.41)])
def test_svg_has_physical_size_and_detects_as_its_id(tag_id, size) -> None:
    from markerplace.localization.tags import make_detector

    svg = tag_svg(tag_id, size, ["caption & <text>", "second line"])
    root = ET.fromstring(svg)  # well-formed, caption escaped
    width = float(root.get("width").removesuffix("mm"))
    height = float(root.get("height").removesuffix("mm"))
    assert width == pytest.approx(1000 * outer_size(size), abs=1e-3)
    assert height > width
    assert "caption &amp; &lt;text&gt;" in svg
    # the caption's longest line fits the sheet width in a real sans-serif font
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    line = "#12  tag36h11 id 586  black square 410 mm" + "x" * 30
    long_caption = tag_svg(tag_id, size, [line, "short"])
    font = float(re.search(r'font-size="([0-9.]+)"', long_caption).group(1))
    assert TextPath((0, 0), line, size=font, prop=FontProperties(family=["sans-serif"])).get_extents().width <= width
    assert long_caption.count("<text ") == 2
    img = rasterize(svg, px_per_mm=240 / width)
    # the drawn modules are the tag's: compare with the reference bits, module by module
    bits = tag_modules(tag_id).shape[0]
    cell = img.shape[0] / bits
    centres = ((np.arange(bits) + 0.5) * cell).astype(int)
    assert np.array_equal(img[np.ix_(centres, centres)] == 0, tag_modules(tag_id))
    dets = make_detector().detect(np.pad(img, 20, constant_values=255))
    assert [d.tag_id for d in dets] == [tag_id]


def test_write_tag_sheets_names_captions_and_cleanup(tmp_path) -> None:
    rec = dict(order=3, tag_id=17, family="tag36h11", size=0.4, position=[1.0, 2.5, 1.5], yaw_deg=90.0)
    assert caption_for(rec) == ["#3  tag36h11 id 17  black square 400 mm",
                                "tag centre (1.00, 2.50, 1.50) m, facing 90 deg", "this edge down"]
    install = {"storey": 1, "room": "study", "wall": "north", "facing": "south", "surface": "wall", "height_m": 1.5,
               "measure_from": "right", "left": {"reference": "corner", "distance_m": 2.0},
               "right": {"reference": "door edge", "distance_m": 0.45}}
    assert caption_for({**rec, "install": install}) == [
        "#3  tag36h11 id 17  black square 400 mm", "storey 1, north wall of the study (faces south)",
        "centre 1.50 m above the floor; 0.45 m from the door edge on the right", "this edge down"]
    (tmp_path / "tags").mkdir()
    (tmp_path / "tags" / "logo.svg").write_text("someone else's drawing")
    write_tag_sheets(tmp_path / "tags", [{**rec, "order": 1, "tag_id": 5}])  # an earlier plan's sheet
    paths = write_tag_sheets(tmp_path / "tags", [rec, {**rec, "order": 4, "tag_id": 18}])
    assert [p.name for p in paths] == ["03_tag17.svg", "04_tag18.svg"]
    # the earlier plan's sheet is gone, a file markerplace did not write stays
    assert sorted(p.name for p in (tmp_path / "tags").iterdir()) == ["03_tag17.svg", "04_tag18.svg", "logo.svg"]
    assert (tmp_path / "tags" / "logo.svg").read_text() == "someone else's drawing"
    assert re.search(r"#4  tag36h11 id 18", paths[1].read_text())
