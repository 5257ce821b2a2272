"""AprilTag (tag36h11) detection with pupil-apriltags, and the camera pose a tag implies.

Corner convention: the detector's own. pupil-apriltags (the AprilTag C library) returns the
corners counter-clockwise in the image from the tag's bottom-left (BL, BR, TR, TL as a facing
viewer sees the tag as printed; ``apriltag_detection.p`` in ``apriltag.h``, the object points of
``apriltag_pose.c``), which is the order of :func:`markerplace.geometry.marker_corners_local`:
corners pair by index, no permutation. Its pixel convention puts pixel centres at +0.5;
:func:`detect_tags` shifts by -0.5 px to OpenCV's (pixel centres at integers).

Detector settings: ``quad_decimate=1.0`` (full resolution). At 600x450 a 0.4 m tag 8-10 m away
spans only ~12-15 px; decimation by 2 loses those far tags, and full resolution costs only a few
milliseconds per image. ``nthreads=1`` (parallelism is across images, by processes).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass

import cv2
import numpy as np

from markerplace.geometry import invert
from markerplace.localization.sift import to_gray
from markerplace.markers import FAMILY, Marker

log = logging.getLogger(__name__)

QUAD_DECIMATE = 1.0
_PUPIL_PIXEL_OFFSET = 0.5

_DETECTORS: dict[int, object] = {}
MARKER_FROM_APRILTAG = np.diag([1.0, -1.0, -1.0, 1.0])
"""(4, 4) pose of the AprilTag library's tag frame (x right, y down, z into the tag, as a facing
viewer sees it; the frame of its pose estimates) in markerplace's marker frame (x right, y up,
z out of the wall): a half-turn about x."""


@dataclass(frozen=True, eq=False)
class TagDetection:
    """One detected tag.

    Attributes:
        tag_id: tag36h11 id.
        corners: (4, 2) float64 pixel ``(x, y)`` (pixel centres at integers), the detector's order:
            BL, BR, TR, TL as a facing viewer sees the tag (:func:`~markerplace.geometry.marker_corners_local`).
        center: (2,) pixel ``(x, y)`` of the tag centre.
        decision_margin: detector's decoding margin (higher is more reliable).
        hamming: number of corrected bits.
    """

    tag_id: int
    corners: np.ndarray
    center: np.ndarray
    decision_margin: float = 0.0
    hamming: int = 0


def make_detector(**settings):
    """A pupil-apriltags ``Detector`` for tag36h11 (keyword ``settings`` as pupil-apriltags)
    that releases its C objects in the right order.

    pupil-apriltags 1.0.4 frees the tag families before the detector, whose destructor then
    reads them again (use after free: pupil-labs/apriltags PR #65, not released): deleting a
    detector corrupts the heap and crashes the process later, somewhere else. Every detector
    of the package and its tests comes from here.
    """
    import pupil_apriltags

    class _Detector(pupil_apriltags.Detector):
        def __del__(self):
            ptr = getattr(self, "tag_detector_ptr", None)
            if ptr is None:
                return
            self.libc.apriltag_detector_destroy.restype = None
            self.libc.apriltag_detector_destroy(ptr)  # detaches and uninitializes the families
            self.tag_detector_ptr = None
            for family, tf in self.tag_families.items():
                destroy = getattr(self.libc, f"{family}_destroy")
                destroy.restype = None
                destroy(tf)

    return _Detector(**{"families": FAMILY, **settings})


def _detector():
    """One detector per process, with the settings of the module docstring."""
    pid = os.getpid()
    det = _DETECTORS.get(pid)
    if det is None:
        det = make_detector(nthreads=1, quad_decimate=QUAD_DECIMATE, quad_sigma=0.0, refine_edges=1,
                            decode_sharpening=0.25)
        _DETECTORS[pid] = det
    return det


def detect_tags(image: np.ndarray, max_hamming: int = 1) -> list[TagDetection]:
    """Detect tag36h11 tags in an (H, W, 3) RGB or (H, W) gray uint8 image.

    Detections with more than ``max_hamming`` corrected bits are dropped. If an id is detected
    more than once, only the detection with the largest decision margin is kept.
    Returns detections sorted by tag id.
    """
    gray = to_gray(image)
    best: dict[int, TagDetection] = {}
    for r in _detector().detect(gray):
        if r.hamming > max_hamming:
            continue
        det = TagDetection(
            tag_id=int(r.tag_id),
            corners=np.asarray(r.corners, dtype=np.float64) - _PUPIL_PIXEL_OFFSET,
            center=np.asarray(r.center, dtype=np.float64) - _PUPIL_PIXEL_OFFSET,
            decision_margin=float(r.decision_margin),
            hamming=int(r.hamming),
        )
        prev = best.get(det.tag_id)
        if prev is None or det.decision_margin > prev.decision_margin:
            best[det.tag_id] = det
    return [best[k] for k in sorted(best)]


def pose_from_tag(detection: TagDetection, marker: Marker, K: np.ndarray) -> np.ndarray:
    """(4, 4) ``world_from_cam`` implied by one tag detection (IPPE square on its 4 corners).

    Args:
        detection: corners in the detector's order (BL, BR, TR, TL), pixels.
        marker: the tag's known pose and size.
        K: (3, 3) camera matrix.
    """
    # IPPE_SQUARE's object points are (-h, h), (h, h), (h, -h), (-h, -h): the AprilTag library's
    # tag frame (y down, z into the tag) in the detector's corner order, so it solves for
    # cam_from_apriltag directly (near the identity for facing views, where IPPE is stable).
    h = marker.size / 2.0
    obj = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]]).reshape(4, 1, 3)
    img = np.asarray(detection.corners, dtype=np.float64).reshape(4, 1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, img, np.asarray(K, float), None, flags=cv2.SOLVEPNP_IPPE_SQUARE)
    if not ok or not np.all(np.isfinite(rvec)) or not np.all(np.isfinite(tvec)):
        raise RuntimeError("solvePnP(IPPE_SQUARE) failed on a tag detection")
    cam_from_apriltag = np.eye(4)
    cam_from_apriltag[:3, :3] = cv2.Rodrigues(rvec)[0]
    cam_from_apriltag[:3, 3] = tvec.reshape(3)
    return np.asarray(marker.world_from_marker, float) @ MARKER_FROM_APRILTAG @ invert(cam_from_apriltag)
