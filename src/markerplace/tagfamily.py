"""AprilTag tag36h11 images, drawn as the family defines them, and their geometry on a marker quad.

The bitmaps come from the family's published code table, kept as data in ``tag36h11.json``
beside this module (587 codes and the bit layout of ``tag36h11.c`` in AprilRobotics/apriltag,
BSD 2-Clause; the file names its source). They are drawn the way the AprilTag library's
``apriltag_to_image`` draws them, which is also how the official images of
AprilRobotics/apriltag-imgs were made: bit ``i`` of a code (most significant first) is white at
column ``bit_x[i]``, row ``bit_y[i]`` of the 8 x 8 black square, row 0 being the tag's top edge
as printed. ``tests/render/test_tags.py`` compares every id cell by cell with the AprilTag C
library's own ``apriltag_to_image`` (the one pupil-apriltags ships), so the table cannot drift
from the family the detectors decode.

Hand-written because no installable library draws the official tag36h11 bitmaps: OpenCV's
``DICT_APRILTAG_36h11`` holds the same codes turned by 180 degrees (a tag printed from it and
hung "top edge up" is reported turned by 180 degrees about its normal by every detector that
follows the family).

Image layout (one side, in bits): ``QUIET_BITS`` white | 8 bits of tag (1 black border bit,
6 x 6 data bits, 1 black border bit) | ``QUIET_BITS`` white. The marker ``size`` (metres) is
the edge of the 8-bit black square (AprilTag convention); the drawn quad, white quiet zone
included, has edge :func:`outer_size` ``(size)``.

Corner order: :func:`markerplace.geometry.marker_corners_local` lists the black-square corners
in the detector's order (the AprilTag library's ``apriltag_detection.p``, pupil-apriltags'
``Detection.corners``): bottom-left, bottom-right, top-right, top-left as a facing viewer sees
the tag, counter-clockwise in the image. No permutation is needed anywhere.
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

from markerplace.errors import UserError

TAG_BITS = 8
"""Bits across the black square (6 data bits + a 1-bit black border on each side)."""
QUIET_BITS = 2
"""Bits of white quiet zone drawn around the black square on each side (the official images
have 1; a wider quiet zone detects more reliably and changes nothing else)."""
NUM_TAGS = 587
"""Number of ids in tag36h11."""
DRAWING_VERSION = "tag36h11-official-1"
"""Goes into the cache key of every stage whose artifacts hold pixels of drawn tags, so caches
made with an earlier drawing (OpenCV's bitmaps, turned by 180 degrees) are not reused."""
FAMILY_TABLE = Path(__file__).with_name("tag36h11.json")
"""The published code table of tag36h11 (see the module docstring)."""


def outer_size(size: float) -> float:
    """Edge (metres) of the drawn quad, quiet zone included, for a black square of ``size`` metres."""
    return size * (TAG_BITS + 2 * QUIET_BITS) / TAG_BITS


@lru_cache(maxsize=1)
def family_table() -> dict:
    """The tag36h11 code table: ``codes`` (587 ints), ``bit_x``/``bit_y`` (36 ints each, cells
    of the 8 x 8 black square), ``nbits``, ``width_at_border``, ``source``, ``license``."""
    data = json.loads(FAMILY_TABLE.read_text())
    data["codes"] = [int(c, 16) for c in data["codes"]]
    if len(data["codes"]) != NUM_TAGS or data["width_at_border"] != TAG_BITS:
        raise RuntimeError(f"{FAMILY_TABLE} is not the tag36h11 table (reinstall markerplace)")
    return data


def tag_cells(tag_id: int) -> np.ndarray:
    """(8, 8) bool of the black square of ``tag_id``, True = white; row 0 is the tag's top edge
    as printed, column 0 its left edge (as a facing viewer sees it)."""
    tag_id = int(tag_id)
    if not 0 <= tag_id < NUM_TAGS:
        raise UserError(f"tag id {tag_id} is outside tag36h11 (0..{NUM_TAGS - 1}): pick another id")
    table = family_table()
    code, nbits = table["codes"][tag_id], table["nbits"]
    cells = np.zeros((TAG_BITS, TAG_BITS), dtype=bool)
    for i, (x, y) in enumerate(zip(table["bit_x"], table["bit_y"])):
        if (code >> (nbits - 1 - i)) & 1:
            cells[y, x] = True
    return cells


def tag_image(tag_id: int, pixels_per_bit: int = 8) -> np.ndarray:
    """tag36h11 image with a white quiet zone.

    Args:
        tag_id: id in tag36h11, 0..586.
        pixels_per_bit: image pixels per tag bit.

    Returns:
        (H, W) uint8 image, H = W = (8 + 2 * QUIET_BITS) * pixels_per_bit; 0 = black, 255 =
        white; row 0 is the tag's top edge (towards the marker's +y), as the official images.
    """
    return _tag_image_cached(int(tag_id), int(pixels_per_bit)).copy()


@lru_cache(maxsize=64)
def _tag_image_cached(tag_id: int, pixels_per_bit: int) -> np.ndarray:
    if pixels_per_bit < 1:
        raise ValueError("pixels_per_bit must be >= 1")
    bits = np.pad(tag_cells(tag_id), QUIET_BITS, mode="constant", constant_values=True)
    out = np.where(bits, 255, 0).astype(np.uint8)
    out = np.repeat(np.repeat(out, pixels_per_bit, axis=0), pixels_per_bit, axis=1)
    out.setflags(write=False)
    return out
