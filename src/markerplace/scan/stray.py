"""The Stray Scanner layout (``--format stray``): the folder the Stray Scanner iOS app exports.

::

    SCAN_DIR/
      rgb.mp4              colour video (or rgb/000000.jpg|png, one image per frame)
      depth/000000.png     16-bit depth, millimetres, lower resolution than the colour (256x192)
      confidence/000000.png  optional: 8-bit, 0 / 1 / 2 per depth pixel (higher = surer);
                           readings below 1 are dropped
      camera_matrix.csv    3x3 K of the colour image, comma separated (pixels)
      odometry.csv         header 'timestamp, frame, x, y, z, qx, qy, qz, qw', then one row per
                           frame (an older 7-column form 'x, y, z, qx, qy, qz, qw' has frame =
                           row number)

Conventions, from the app's source (github.com/strayrobots/scanner) rather than assumed:

* ``OdometryEncoder.swift`` writes the position of ARKit's ``camera.transform`` and the quaternion
  ``q_WA * q_AC`` with ``q_AC = (x 1, y 0, z 0, w 0)``, 180 deg about the camera x axis: ARKit's
  camera (x right, y up, z back) turned into OpenCV's (x right, y down, z forward). So the row is
  ``world_from_cam`` in OpenCV camera axes already; the quaternion is Hamilton, scalar last.
  The app's companion StrayVisualizer (``stray_visualize.py --integrate``) agrees: it passes
  ``inv(T_WC)`` of these rows straight to Open3D's TSDF, whose camera is OpenCV's.
* The world is ARKit's default (``worldAlignment = .gravity``, the app sets no other): y up,
  parallel to gravity, origin where the recording started. So up is +y (``up_source`` "layout
  (ARKit world, y up)").
* Depth (``DepthEncoder.swift``, ``docs/format.md``): 16-bit PNG, millimetres, registered to the
  colour image at a lower resolution; :func:`~markerplace.scan.frame_images.load_frame` upsamples it
  (nearest neighbour, pixel centres aligned) to the colour size and K.
* Frame numbers: ``frame`` is the depth/confidence file number and the video frame index.

Every problem raises :class:`~markerplace.errors.UserError` with one line naming the file (and line).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.scan.frameset import FrameRecord, FrameSet, data_lines, image_size, parse_numbers, pose_from_quaternion

log = logging.getLogger(__name__)

STRAY_DEPTH_SCALE = 1000.0
"""Depth PNG units per metre of Stray Scanner (millimetres)."""
STRAY_UP = (0.0, 1.0, 0.0)
"""ARKit's gravity-aligned world: +y up."""
STRAY_UP_SOURCE = "layout (ARKit world, y up)"
ODOMETRY_COLUMNS = ("timestamp", "frame", "x", "y", "z", "qx", "qy", "qz", "qw")


def read_camera_matrix(path: Path) -> np.ndarray:
    """(3, 3) K of ``camera_matrix.csv``."""
    if not path.is_file():
        raise UserError(f"{path} not found (Stray Scanner layout: camera_matrix.csv, odometry.csv, depth/, rgb.mp4)")
    lines = data_lines(path)
    if len(lines) != 3 or any(len(f) != 3 for _, f in lines):
        raise UserError(f"{path}: expected 3 lines of 3 comma-separated numbers (the colour camera's 3x3 K)")
    K = np.array([parse_numbers(f, f"{path}:{n}") for n, f in lines])
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or np.max(np.abs(K[2] - [0, 0, 1])) > 1e-6:
        raise UserError(f"{path}: not a pinhole camera matrix (expected fx 0 cx / 0 fy cy / 0 0 1 with fx, fy > 0)")
    return K


def read_odometry(path: Path) -> list[tuple[int, np.ndarray]]:
    """(frame number, (4, 4) ``world_from_cam``) of each row of ``odometry.csv``."""
    if not path.is_file():
        raise UserError(f"{path} not found (Stray Scanner layout)")
    lines = data_lines(path)
    if lines and lines[0][1][0].lower() in ("timestamp", "x"):
        header = [c.lower() for c in lines[0][1]]
        if header not in (list(ODOMETRY_COLUMNS), list(ODOMETRY_COLUMNS[2:])):
            raise UserError(f"{path}:{lines[0][0]}: unexpected header {', '.join(lines[0][1])!r} "
                            f"(expected {', '.join(ODOMETRY_COLUMNS)})")
        lines = lines[1:]
    out, seen = [], set()
    for row, (lineno, fields) in enumerate(lines):
        where = f"{path}:{lineno}"
        if len(fields) not in (7, 9):
            raise UserError(f"{where}: expected 9 values ({', '.join(ODOMETRY_COLUMNS)}), got {len(fields)}")
        v = parse_numbers(fields, where)
        if len(v) == 9:
            if v[1] != int(v[1]) or v[1] < 0:
                raise UserError(f"{where}: frame {fields[1]!r} is not a frame number")
            frame, v = int(v[1]), v[2:]
        else:
            frame = row
        if frame in seen:
            raise UserError(f"{where}: frame {frame} is listed twice")
        seen.add(frame)
        T = pose_from_quaternion(v[0:3], v[3:7], where)
        out.append((frame, T))
    return out


def _colour_size(root: Path, first: Path | None) -> tuple[int, int]:
    """(width, height) of the colour video or the first colour image."""
    import cv2

    video = root / "rgb.mp4"
    if first is None:
        cap = cv2.VideoCapture(str(video))
        try:
            if not cap.isOpened():
                raise UserError(f"cannot decode {video} (not a video OpenCV can read?)")
            w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        finally:
            cap.release()
        if w <= 0 or h <= 0:
            raise UserError(f"cannot decode {video}: OpenCV reports no frame size")
        return w, h
    return image_size(first, "Stray layout: one colour image per odometry row")


def read_stray(root: Path) -> FrameSet:
    """Read a Stray Scanner export (module docstring); poses in ARKit's world (y up)."""
    root = Path(root)
    K = read_camera_matrix(root / "camera_matrix.csv")
    rows = read_odometry(root / "odometry.csv")
    if not rows:
        raise UserError(f"{root / 'odometry.csv'}: no frames")
    video = root / "rgb.mp4"
    folder = root / "rgb"
    if not video.exists() and not folder.is_dir():
        raise UserError(f"{root}: neither rgb.mp4 nor an rgb/ folder of frames (Stray Scanner layout)")
    use_video = video.exists()
    conf_dir = root / "confidence"
    frames = []
    for frame, T in rows:
        name = f"{frame:06d}"
        if use_video:
            color, index = video, frame
        else:
            color, index = folder / f"{name}.jpg", None
            if not color.exists():
                color = folder / f"{name}.png"
        conf = conf_dir / f"{name}.png" if conf_dir.is_dir() else None
        frames.append(FrameRecord(name, color, root / "depth" / f"{name}.png", T, color_index=index, confidence_path=conf))
    w, h = _colour_size(root, None if use_video else frames[0].color_path)
    intrinsics = Intrinsics(w, h, float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))
    log.info("Stray Scanner: %d frames, colour %dx%d from %s%s", len(frames), w, h, "rgb.mp4" if use_video else "rgb/",
             ", confidence >= 1 kept" if conf_dir.is_dir() else ", no confidence maps")
    return FrameSet(root, "stray", intrinsics, STRAY_DEPTH_SCALE, tuple(frames))


__all__ = ["STRAY_DEPTH_SCALE", "STRAY_UP", "STRAY_UP_SOURCE", "ODOMETRY_COLUMNS", "read_camera_matrix", "read_odometry",
           "read_stray"]
