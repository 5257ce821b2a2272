"""The official tag36h11 images of AprilRobotics/apriltag-imgs (tests/data/apriltag_imgs), the
outside reference the tag tests compare with; never markerplace's own drawing."""

from __future__ import annotations

import numpy as np
from PIL import Image

from . import DATA

OFFICIAL_DIR = DATA / "apriltag_imgs"
OFFICIAL_IDS = (0, 3, 17, 101, 586)
"""Ids whose official image is kept in OFFICIAL_DIR."""


def official_png(tag_id: int) -> np.ndarray:
    """(10, 10) uint8 official image (white ring, black border, data bits; row 0 = top edge)."""
    return np.array(Image.open(OFFICIAL_DIR / f"tag36_11_{tag_id:05d}.png").convert("L"))


def official_square(tag_id: int, side_px: int) -> np.ndarray:
    """(side_px, side_px) uint8 black square of the official image (8 x 8 cells without the
    white ring), scaled by nearest neighbour; row 0 is the tag's top edge as printed."""
    cells = official_png(tag_id)[1:-1, 1:-1]
    idx = (np.arange(side_px) * 8) // side_px
    return np.ascontiguousarray(cells[idx][:, idx])
