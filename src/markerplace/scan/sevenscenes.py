"""The Microsoft 7-Scenes layout (``--format 7scenes``): one folder of frames, three files each.

::

    SEQ_DIR/
      frame-000000.color.png     8-bit RGB 640x480 (PNG; a .jpg is read too)
      frame-000000.depth.png     16-bit depth, millimetres, 65535 = no reading (read as 0)
      frame-000000.pose.txt      4 lines of 4 numbers: the 4x4 camera-to-world matrix, row-major
      camera-intrinsics.txt      optional: 3 lines of 3 numbers, the 3x3 K (pixels)
      gravity-direction.txt      optional: 3 numbers, the direction of gravity (pointing down)
                                 in the poses' world frame

* Poses map camera points (OpenCV axes: x right, y down, z forward; metres) to the world of the
  sequence (the KinectFusion reconstruction's, not gravity-aligned).
* Two cameras: 7-Scenes' colour and depth cameras are not calibrated against each other (the
  dataset's own note); its published parameters, focal length 585 and principal point (320, 240),
  are the depth camera's, and ``camera-intrinsics.txt`` (not part of the dataset; the copy in
  andyzeng/tsdf-fusion-python holds the same 585) is read as the depth camera's. The colour
  camera is :data:`SEVENSCENES_COLOUR_INTRINSICS` (fx = fy = 525, cx 320, cy 240), the value the
  relocalization literature uses for 7-Scenes' RGB images; measured on the kitchen frames
  (``benchmarks/sevenscenes_colour_focal.py``: SIFT matches between frames 6 apart, lifted by the
  depth and reprojected with the poses) the median reprojection error is 1.5-1.6 px for colour
  focal lengths 510-525 against 2.6 px at 585. The depth is resampled into the colour camera
  with a zero baseline (:func:`markerplace.scan.frame_images.register_depth`; the cameras' real offset,
  a few centimetres, is unknown): the poses are the depth camera's.
* Frames are the ``frame-*.pose.txt`` files in name order.

Every problem raises :class:`~markerplace.errors.UserError` with one line naming the file (and line).
"""

from __future__ import annotations

import logging
import re
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.scan.frameset import FrameRecord, FrameSet, check_rigid, data_lines, image_size, parse_numbers

log = logging.getLogger(__name__)

SEVENSCENES_DEPTH_SCALE = 1000.0
"""Depth PNG units per metre of 7-Scenes (millimetres)."""
SEVENSCENES_INVALID_DEPTH = 65535
"""7-Scenes' depth value for no reading."""
SEVENSCENES_INTRINSICS = Intrinsics(640, 480, 585.0, 585.0, 320.0, 240.0)
"""The dataset's published depth-camera calibration."""
SEVENSCENES_COLOUR_INTRINSICS = Intrinsics(640, 480, 525.0, 525.0, 320.0, 240.0)
"""The colour camera (module docstring: the literature's value, checked on real frames)."""
GRAVITY_FILE = "gravity-direction.txt"
POSE_RE = re.compile(r"^(frame-\d+)\.pose\.txt$")


def _matrix(path: Path, rows: int, what: str) -> np.ndarray:
    """``rows`` lines of ``rows`` numbers (whitespace or comma separated) of a small text file."""
    if not path.is_file():
        raise UserError(f"{path} not found")
    lines = data_lines(path)
    if len(lines) != rows:
        raise UserError(f"{path}: expected {rows} lines of {rows} numbers ({what}), got {len(lines)} lines")
    out = []
    for lineno, fields in lines:
        if len(fields) != rows:
            raise UserError(f"{path}:{lineno}: expected {rows} numbers ({what}), got {len(fields)}")
        out.append(parse_numbers(fields, f"{path}:{lineno}"))
    return np.array(out, dtype=np.float64)


def read_pose_file(path: Path) -> np.ndarray:
    """(4, 4) ``world_from_cam`` of a 7-Scenes ``.pose.txt`` (checked rigid)."""
    return check_rigid(_matrix(path, 4, "the 4x4 camera-to-world matrix, row-major"), str(path))


def read_camera_intrinsics(path: Path, width: int, height: int) -> Intrinsics:
    """Intrinsics of ``camera-intrinsics.txt`` (3x3 K) for images of ``width`` x ``height``."""
    K = _matrix(path, 3, "the 3x3 camera matrix K")
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or np.max(np.abs(K[2] - [0, 0, 1])) > 1e-9 \
            or abs(K[0, 1]) > 1e-9 or abs(K[1, 0]) > 1e-9:
        raise UserError(f"{path}: not a pinhole camera matrix (expected fx 0 cx / 0 fy cy / 0 0 1 with fx, fy > 0)")
    return Intrinsics(width, height, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))


def read_gravity(root: Path) -> np.ndarray | None:
    """Unit up vector (minus gravity) of ``gravity-direction.txt``, or None when there is none."""
    path = Path(root) / GRAVITY_FILE
    if not path.exists():
        return None
    fields = [(n, f) for n, line in data_lines(path) for f in line]
    if len(fields) != 3:
        raise UserError(f"{path}: expected 3 numbers (the direction of gravity, pointing down, in the poses' world), "
                        f"got {len(fields)}")
    g = np.array([parse_numbers([f], f"{path}:{n}")[0] for n, f in fields])
    if not np.all(np.isfinite(g)) or np.linalg.norm(g) < 1e-9:
        raise UserError(f"{path}: the gravity direction must be a non-zero vector")
    return -g / np.linalg.norm(g)


def read_7scenes(root: Path) -> FrameSet:
    """Read a 7-Scenes sequence folder (module docstring); poses in the sequence's world."""
    root = Path(root)
    names = sorted(m.group(1) for p in root.iterdir() if (m := POSE_RE.match(p.name)))
    if not names:
        raise UserError(f"{root}: no frame-NNNNNN.pose.txt files (7-Scenes layout)")
    frames = []
    for name in names:
        color = root / f"{name}.color.png"
        if not color.exists() and (root / f"{name}.color.jpg").exists():
            color = root / f"{name}.color.jpg"
        frames.append(FrameRecord(name, color, root / f"{name}.depth.png", read_pose_file(root / f"{name}.pose.txt")))
    try:
        size = image_size(frames[0].depth_path)
    except UserError:  # unreadable: load_frame names the problem when the frame is read
        size = (SEVENSCENES_INTRINSICS.width, SEVENSCENES_INTRINSICS.height)
    kfile = root / "camera-intrinsics.txt"
    if kfile.exists():
        depth_intrinsics = read_camera_intrinsics(kfile, *size)
    else:
        d = SEVENSCENES_INTRINSICS
        depth_intrinsics = Intrinsics(size[0], size[1], d.fx, d.fy, d.cx, d.cy)
        log.info("7-Scenes: no camera-intrinsics.txt, using the dataset's depth camera (fx = fy = 585, cx 320, cy 240)")
    c = SEVENSCENES_COLOUR_INTRINSICS
    sx, sy = size[0] / c.width, size[1] / c.height
    colour = Intrinsics(size[0], size[1], c.fx * sx, c.fy * sy, (c.cx + 0.5) * sx - 0.5, (c.cy + 0.5) * sy - 0.5)
    log.info("7-Scenes: %d frames; colour camera fx %.0f (the literature's 7-Scenes RGB focal length), depth camera "
             "fx %.0f, depth resampled into the colour camera (the dataset calibrates neither against the other)",
             len(frames), colour.fx, depth_intrinsics.fx)
    return FrameSet(root, "7scenes", colour, SEVENSCENES_DEPTH_SCALE, tuple(frames), depth_intrinsics=depth_intrinsics)


__all__ = ["SEVENSCENES_DEPTH_SCALE", "SEVENSCENES_INVALID_DEPTH", "SEVENSCENES_INTRINSICS", "SEVENSCENES_COLOUR_INTRINSICS",
           "GRAVITY_FILE",
           "read_pose_file", "read_camera_intrinsics", "read_gravity", "read_7scenes"]
