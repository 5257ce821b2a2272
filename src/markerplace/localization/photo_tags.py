"""Tag detections of photos, cached per photo, and a photo's crop with a detection drawn.

The cache is one JSON file per photo, ``CACHE_DIR/<key>.json``, named by the SHA-256 of the
photo's file (:attr:`markerplace.scan.photos.Photo.key`) and holding the detector version: a
re-run with more photos detects only in the new ones, a photo edited in place is detected
again. Each file holds the image size and per detection the tag id, its 4 corners (pixels,
the detector's order) and decoding margin.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from markerplace.jsonfile import read_json
from markerplace.localization.tags import QUAD_DECIMATE, TagDetection, detect_tags
from markerplace.progress import track
from markerplace.runtime.atomic_io import write_image, write_json
from markerplace.scan.photos import Photo, load_photo

log = logging.getLogger(__name__)

__all__ = ["DETECTOR_VERSION", "detect_photos", "draw_detection"]

DETECTOR_VERSION = f"pupil-apriltags tag36h11 decimate={QUAD_DECIMATE} hamming<=1 v1"


def _to_json(photo: Photo, dets: list[TagDetection]) -> dict:
    return {"detector": DETECTOR_VERSION, "name": photo.name,
            "width": photo.intrinsics.width, "height": photo.intrinsics.height,
            "detections": [{"tag_id": d.tag_id, "corners": np.asarray(d.corners).round(4).tolist(),
                            "decision_margin": round(d.decision_margin, 3), "hamming": d.hamming} for d in dets]}


def _from_json(data) -> list[TagDetection] | None:
    try:
        if data.get("detector") != DETECTOR_VERSION:
            return None
        return [TagDetection(int(d["tag_id"]), np.asarray(d["corners"], float).reshape(4, 2),
                             np.asarray(d["corners"], float).reshape(4, 2).mean(axis=0), float(d["decision_margin"]),
                             int(d["hamming"])) for d in data["detections"]]
    except (AttributeError, KeyError, TypeError, ValueError):
        return None


def detect_photos(photos: list[Photo], cache_dir: Path, progress: bool = True) -> tuple[list[list[TagDetection]], int]:
    """Per photo its tag36h11 detections (:func:`~markerplace.localization.tags.detect_tags`),
    read from ``cache_dir`` when there (module docstring). Returns (detections per photo, how
    many photos were detected anew)."""
    cache_dir = Path(cache_dir)
    out, fresh = [], 0
    for photo in track(photos, "tags in photos", "photo", enabled=progress):
        path = cache_dir / f"{photo.key}.json"
        dets = _from_json(read_json(path, f"detection cache {path}")) if path.is_file() else None
        if dets is None:
            dets = detect_tags(load_photo(photo))
            write_json(path, _to_json(photo, dets))
            fresh += 1
        out.append(dets)
    return out, fresh


def draw_detection(photo: Photo, corners: np.ndarray, tag_id: int, path: Path, max_side: int = 480) -> None:
    """Write a crop of ``photo`` around one detection, its outline drawn (green, the bottom edge
    red) and its id written, at most ``max_side`` pixels a side."""
    import cv2

    rgb = load_photo(photo).copy()
    c = np.asarray(corners, float)
    H, W = rgb.shape[:2]
    span = max(float(np.ptp(c[:, 0])), float(np.ptp(c[:, 1])), 8.0)
    lo = np.maximum(np.floor(c.min(axis=0) - 0.8 * span), 0).astype(int)
    hi = np.minimum(np.ceil(c.max(axis=0) + 0.8 * span), [W, H]).astype(int)
    thick = max(1, int(round(span / 40)))
    pts = np.round(c).astype(np.int32)
    cv2.polylines(rgb, [pts.reshape(-1, 1, 2)], True, (0, 220, 0), thick, cv2.LINE_AA)
    cv2.line(rgb, tuple(pts[0]), tuple(pts[1]), (230, 0, 0), thick, cv2.LINE_AA)  # BL-BR: the bottom edge
    crop = rgb[lo[1]:hi[1], lo[0]:hi[0]]
    s = min(1.0, max_side / max(crop.shape[:2]))
    if s < 1.0:
        crop = cv2.resize(crop, (max(1, int(crop.shape[1] * s)), max(1, int(crop.shape[0] * s))),
                          interpolation=cv2.INTER_AREA)
    cv2.putText(crop, f"tag {tag_id}", (4, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 0), 2, cv2.LINE_AA)
    write_image(path, crop)
