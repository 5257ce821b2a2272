"""AprilTag tag36h11 images and their geometry on a marker quad.

Image layout (one side, in bits): ``QUIET_BITS`` white | 8 bits of tag (1 black border bit,
6 x 6 data bits, 1 black border bit) | ``QUIET_BITS`` white. The marker ``size`` (metres) is
the edge of the 8-bit black square (AprilTag convention); the drawn quad, white quiet zone
included, has edge :func:`outer_size` ``(size)``.

The images come from OpenCV's aruco module (``DICT_APRILTAG_36h11``); ids agree with
pupil-apriltags' ``tag36h11`` (checked by detection in ``tests/test_render_tags.py``).

pupil-apriltags' corners of rendered tags sit about 0.3-0.5 px right/below
:func:`markerplace.geometry.project` of the true corners (its sub-pixel convention; OpenCV's
centres pixels at integers), well within 1 px.

Corner order: :func:`markerplace.geometry.marker_corners_local` lists the black-square corners
top-left, top-right, bottom-right, bottom-left as a facing viewer sees them (OpenCV's ArUco
order). pupil-apriltags reports ``Detection.corners`` in a different order (established by
detection of rendered tags, see the tests): top-right, top-left, bottom-left, bottom-right as
the viewer sees the tag, i.e. our indices ``PUPIL_TO_MARKER_CORNERS`` = (1, 0, 3, 2). So
``detection.corners[i]`` matches ``marker.corners_world()[PUPIL_TO_MARKER_CORNERS[i]]``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from ..errors import UserError

TAG_BITS = 8
"""Bits across the black square (6 data bits + a 1-bit black border on each side)."""
QUIET_BITS = 2
"""Bits of white quiet zone drawn around the black square on each side."""
NUM_TAGS = 587
"""Number of ids in tag36h11."""
PUPIL_TO_MARKER_CORNERS = (1, 0, 3, 2)
"""``detection.corners[i]`` (pupil-apriltags) is ``marker.corners_world()[PUPIL_TO_MARKER_CORNERS[i]]``."""


def outer_size(size: float) -> float:
    """Edge (metres) of the drawn quad, quiet zone included, for a black square of ``size`` metres."""
    return size * (TAG_BITS + 2 * QUIET_BITS) / TAG_BITS


def tag_image(tag_id: int, pixels_per_bit: int = 8) -> np.ndarray:
    """tag36h11 image with a white quiet zone.

    Args:
        tag_id: id in tag36h11, 0..586.
        pixels_per_bit: image pixels per tag bit.

    Returns:
        (H, W) uint8 image, H = W = (8 + 2 * QUIET_BITS) * pixels_per_bit; 0 = black, 255 =
        white; row 0 is the tag's top edge (towards the marker's +y).
    """
    return _tag_image_cached(int(tag_id), int(pixels_per_bit)).copy()


@lru_cache(maxsize=64)
def _tag_image_cached(tag_id: int, pixels_per_bit: int) -> np.ndarray:
    import cv2

    if not 0 <= tag_id < NUM_TAGS:
        raise UserError(f"tag id {tag_id} is outside tag36h11 (0..{NUM_TAGS - 1}): pick another id")
    if pixels_per_bit < 1:
        raise ValueError("pixels_per_bit must be >= 1")
    dictionary = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
    inner = cv2.aruco.generateImageMarker(dictionary, tag_id, TAG_BITS * pixels_per_bit, borderBits=1)
    pad = QUIET_BITS * pixels_per_bit
    out = np.pad(inner, pad, mode="constant", constant_values=255)
    out.setflags(write=False)
    return out
