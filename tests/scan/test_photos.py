"""Photos for `check --photos`: the camera from EXIF (a JPEG written with a known focal length),
from --intrinsics, or a one-line error."""

from __future__ import annotations

import json
import math

import pytest
from PIL import Image

from markerplace.errors import UserError
from markerplace.scan.photos import exif_intrinsics, list_photos, load_photo

EXIF_IFD = 0x8769


def _jpeg(path, size=(400, 300), **tags):
    exif = Image.Exif()
    sub = exif.get_ifd(EXIF_IFD)
    for tag, value in tags.items():
        sub[int(tag, 16)] = value
    Image.new("RGB", size, (120, 130, 140)).save(path, exif=exif)
    return path


def test_focal_from_35mm_equivalent(tmp_path):
    """f_px = f35 x image diagonal / 35 mm film diagonal (43.27 mm)."""
    intr = exif_intrinsics(_jpeg(tmp_path / "a.jpg", **{"0xA405": 26}))
    assert intr.fx == pytest.approx(26 * 500 / math.hypot(36, 24)) and intr.fy == intr.fx
    assert (intr.width, intr.height, intr.cx, intr.cy) == (400, 300, 199.5, 149.5)


def test_focal_from_focal_length_and_sensor_resolution(tmp_path):
    """4.2 mm lens, 1000 px per cm on the sensor (unit 3 = cm), photo at half the sensor's width."""
    path = _jpeg(tmp_path / "b.jpg", **{"0x920A": 4.2, "0xA20E": 1000.0, "0xA210": 3, "0xA002": 800})
    assert exif_intrinsics(path).fx == pytest.approx(4.2 * 100.0 * 400 / 800)


def test_turned_photo_swaps_width_and_height(tmp_path):
    exif = Image.Exif()
    exif[0x0112] = 6  # rotate 90 deg clockwise to view
    exif.get_ifd(EXIF_IFD)[0xA405] = 28
    Image.new("RGB", (400, 300)).save(tmp_path / "c.jpg", exif=exif)
    photo = list_photos(tmp_path)[0]
    assert (photo.intrinsics.width, photo.intrinsics.height) == (300, 400)
    assert load_photo(photo).shape == (400, 300, 3)


def test_no_focal_needs_intrinsics(tmp_path):
    (tmp_path / "p").mkdir()
    Image.new("RGB", (64, 48)).save(tmp_path / "p" / "x.png")
    assert exif_intrinsics(tmp_path / "p" / "x.png") is None
    with pytest.raises(UserError, match="pass --intrinsics"):
        list_photos(tmp_path / "p")
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"width": 128, "height": 96, "fx": 100, "fy": 100, "cx": 63.5, "cy": 47.5}))
    intr = list_photos(tmp_path / "p", cam)[0].intrinsics  # half the size: scaled
    assert (intr.width, intr.fx, intr.cx) == (64, 50.0, 31.5)
    cam.write_text(json.dumps({"width": 100, "height": 100, "fx": 100, "fy": 100, "cx": 50, "cy": 50}))
    with pytest.raises(UserError, match="another aspect ratio"):
        list_photos(tmp_path / "p", cam)


def test_empty_or_missing_folder(tmp_path):
    with pytest.raises(UserError, match="no JPEG or PNG photo"):
        list_photos(tmp_path)
    with pytest.raises(UserError, match="no such folder"):
        list_photos(tmp_path / "absent")


def test_a_frame_folder_is_read_by_its_layout_reader(tiny_frames):
    """An RGB-D frame folder: its own cameras (no EXIF needed), its images as the reader loads them."""
    photos = list_photos(tiny_frames)
    assert len(photos) == 40 and len({p.key for p in photos}) == 40
    rgb = load_photo(photos[0])
    assert rgb.shape == (photos[0].intrinsics.height, photos[0].intrinsics.width, 3)


def test_photos_under_the_output_folder_are_not_photos(tmp_path):
    _jpeg(tmp_path / "a.jpg", **{"0xA405": 26})
    (tmp_path / "check" / "photos").mkdir(parents=True)
    _jpeg(tmp_path / "check" / "photos" / "tag_1.jpg", **{"0xA405": 26})
    assert [p.name for p in list_photos(tmp_path)] == ["a.jpg", "check/photos/tag_1.jpg"]
    assert [p.name for p in list_photos(tmp_path, exclude=tmp_path / "check")] == ["a.jpg"]
