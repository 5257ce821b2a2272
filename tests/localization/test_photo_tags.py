"""Detections cached per photo: a re-run with more photos detects only in the new ones."""

from __future__ import annotations

import json

import numpy as np

from markerplace.localization.photo_tags import detect_photos, draw_detection
from markerplace.scan.photos import list_photos
from markerplace.tagfamily import tag_image


def _photo(path, tag_id: int, x: int):
    from PIL import Image

    canvas = np.full((240, 320), 255, np.uint8)
    tag = tag_image(tag_id, 8)  # the square and its quiet zone, 8 px a bit
    canvas[40:40 + tag.shape[0], x:x + tag.shape[1]] = tag
    Image.fromarray(canvas).convert("RGB").save(path)


def test_cache_detects_only_new_photos(tmp_path):
    photos, cache = tmp_path / "photos", tmp_path / "cache"
    photos.mkdir()
    cache.mkdir()
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"width": 320, "height": 240, "fx": 300, "fy": 300, "cx": 159.5, "cy": 119.5}))
    _photo(photos / "a.png", 3, 20)
    _photo(photos / "b.png", 7, 150)
    dets, fresh = detect_photos(list_photos(photos, cam), cache, progress=False)
    assert fresh == 2 and [[d.tag_id for d in ds] for ds in dets] == [[3], [7]]
    _photo(photos / "c.png", 11, 60)
    again, fresh = detect_photos(list_photos(photos, cam), cache, progress=False)
    assert fresh == 1 and [[d.tag_id for d in ds] for ds in again] == [[3], [7], [11]]
    assert np.allclose(again[0][0].corners, dets[0][0].corners, atol=1e-3)
    _photo(photos / "a.png", 5, 20)  # a photo replaced: its content, not its name, is the key
    last, fresh = detect_photos(list_photos(photos, cam), cache, progress=False)
    assert fresh == 1 and last[0][0].tag_id == 5
    assert len(list(cache.glob("*.json"))) == 4


def test_detection_drawn_on_a_crop(tmp_path):
    (tmp_path / "p").mkdir()
    _photo(tmp_path / "p" / "a.png", 3, 20)
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"width": 320, "height": 240, "fx": 300, "fy": 300, "cx": 159.5, "cy": 119.5}))
    photo = list_photos(tmp_path / "p", cam)[0]
    det = detect_photos([photo], tmp_path, progress=False)[0][0][0]
    draw_detection(photo, det.corners, 3, tmp_path / "tag_3.png")
    from PIL import Image

    img = np.asarray(Image.open(tmp_path / "tag_3.png"))
    green = (img[..., 1] > 180) & (img[..., 0] < 60) & (img[..., 2] < 60)
    assert green.sum() > 50 and img.shape[0] < 240
