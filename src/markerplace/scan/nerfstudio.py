"""The nerfstudio ``transforms.json`` layout (``--format nerfstudio``).

::

    DATA_DIR/
      transforms.json     {"camera_model": "OPENCV", "fl_x": ..., "fl_y": ..., "cx": ..., "cy": ...,
                           "w": ..., "h": ..., "k1": ..., "k2": ..., "p1": ..., "p2": ...,
                           "frames": [{"file_path": "images/frame_00001.png",
                                       "depth_file_path": "depth/frame_00001.png",
                                       "transform_matrix": [[...4x4...]]}, ...]}

Conventions, from nerfstudio's documentation ("Data conventions") and its dataparser
(``nerfstudio/data/dataparsers/nerfstudio_dataparser.py``, ``data/utils/data_utils.py``):

* ``transform_matrix`` is camera-to-world with OpenGL/Blender camera axes (x right, y up, z back:
  the camera looks along -z). Ours is OpenCV's: ``world_from_cam = transform_matrix @
  diag(1, -1, -1, 1)``.
* Intrinsics ``fl_x, fl_y, cx, cy, w, h`` and distortion ``k1 k2 k3 k4 p1 p2`` at the top level
  are shared; the same keys in a frame override them. ``camera_model``: ``OPENCV`` (and
  ``PINHOLE``, ``SIMPLE_PINHOLE``, ``SIMPLE_RADIAL``, ``RADIAL``, or none: a perspective camera,
  distortion k1 k2 k3 p1 p2) or ``OPENCV_FISHEYE`` (k1 k2 k3 k4). Images are undistorted when
  loaded, keeping K.
* Pixel coordinates: nerfstudio shoots the ray of pixel (i, j) through (i + 0.5, j + 0.5) (pixel
  centres, corners at integers); ours (OpenCV) has centres at integers, so cx, cy are read minus 0.5.
* ``file_path`` and ``depth_file_path`` are relative to the json's folder; nerfstudio sorts the
  frames by file name, and so do we. Depth images: 16-bit PNG, multiplied by nerfstudio's
  ``depth_unit_scale_factor`` (default 1e-3: millimetres) to get metres, resized to the colour
  image with nearest-neighbour interpolation; so depth scale 1000 per metre here.
* ``applied_transform`` (3x4, written by ``ns-process-data`` for COLMAP and other converters):
  the transform that was already applied to the poses, from the original capture's world (e.g.
  COLMAP's, or the point cloud's) to the world of ``transforms.json``. nerfstudio composes it into
  its dataparser transform only to bring the original point cloud (``ply_file_path``) into the
  poses' frame; the poses themselves are used as written. So are they here; it is logged.
* The world frame of ``transforms.json`` carries no reliable up axis (nerfstudio re-orients it
  itself, ``orientation_method="up"`` by default): up is estimated from the cameras.

Every problem raises :class:`~markerplace.errors.UserError` with one line naming the file (and frame).
"""

from __future__ import annotations

import logging
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.jsonfile import read_json
from markerplace.scan.frameset import Distortion, FrameRecord, FrameSet, check_rigid, image_size

log = logging.getLogger(__name__)

NERFSTUDIO_DEPTH_SCALE = 1000.0
"""Depth units per metre: 1 / nerfstudio's default ``depth_unit_scale_factor`` (1e-3)."""
OPENGL_TO_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
"""Right-multiplied onto an OpenGL-camera pose to give the OpenCV-camera pose (and back)."""
PERSPECTIVE_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE", "SIMPLE_RADIAL", "RADIAL")
FISHEYE_MODELS = ("OPENCV_FISHEYE",)
CAMERA_KEYS = ("fl_x", "fl_y", "cx", "cy", "w", "h")
DISTORTION_KEYS = ("k1", "k2", "k3", "k4", "p1", "p2")


def _number(value, where: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"{where}: {key} must be a number, got {value!r}")
    return float(value)


def _matrix(value, where: str, key: str) -> np.ndarray:
    try:
        M = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        M = np.zeros(0)
    if M.shape == (3, 4):
        M = np.vstack([M, [0.0, 0.0, 0.0, 1.0]])
    if M.shape != (4, 4):
        raise UserError(f"{where}: {key} must be a 4x4 (or 3x4) matrix of numbers, row-major")
    return M


def _camera(meta: dict, frame: dict, where: str, image: Path) -> tuple[Intrinsics, Distortion | None]:
    """Pinhole intrinsics (OpenCV pixel centres) and distortion of one frame: its keys over the shared ones."""
    def get(key):
        return frame[key] if key in frame else meta.get(key)

    model = get("camera_model") or "OPENCV"
    if model not in PERSPECTIVE_MODELS + FISHEYE_MODELS:
        raise UserError(f"{where}: camera_model {model!r} is not supported (use OPENCV, OPENCV_FISHEYE or PINHOLE)")
    missing = [k for k in ("fl_x", "fl_y", "cx", "cy") if get(k) is None]
    if missing:
        raise UserError(f"{where}: missing {', '.join(missing)} (at the top level or in the frame)")
    fx, fy, cx, cy = (_number(get(k), where, k) for k in ("fl_x", "fl_y", "cx", "cy"))
    if fx <= 0 or fy <= 0:
        raise UserError(f"{where}: fl_x and fl_y must be positive")
    if get("w") is None or get("h") is None:
        w, h = image_size(image)
    else:
        w, h = (_number(get(k), where, k) for k in ("w", "h"))
        if w != int(w) or h != int(h) or w <= 0 or h <= 0:
            raise UserError(f"{where}: w and h must be positive integers")
    k = {key: _number(get(key), where, key) if get(key) is not None else 0.0 for key in DISTORTION_KEYS}
    if model in FISHEYE_MODELS:
        dist = Distortion("fisheye", (k["k1"], k["k2"], k["k3"], k["k4"]))
    else:
        if k["k4"] != 0.0:
            raise UserError(f"{where}: k4 is only read for camera_model OPENCV_FISHEYE (got {model})")
        dist = Distortion("opencv", (k["k1"], k["k2"], k["p1"], k["p2"], k["k3"]))
    return Intrinsics(int(w), int(h), fx, fy, cx - 0.5, cy - 0.5), (None if dist.is_zero else dist)


def read_applied_transform(meta: dict, path: Path) -> np.ndarray | None:
    """(4, 4) ``applied_transform`` (original world -> transforms.json world), or None."""
    if "applied_transform" not in meta:
        return None
    return _matrix(meta["applied_transform"], str(path), "applied_transform")


def read_nerfstudio(root: Path) -> FrameSet:
    """Read a nerfstudio data folder (module docstring); poses in the transforms.json world."""
    root = Path(root)
    path = root / "transforms.json"
    if not path.is_file():
        raise UserError(f"{path} not found (nerfstudio layout)")
    meta = read_json(path, f"nerfstudio file {path}")
    if not isinstance(meta, dict) or not isinstance(meta.get("frames"), list):
        raise UserError(f"{path}: expected a JSON object with a \"frames\" list")
    applied = read_applied_transform(meta, path)
    frames = []
    for i, frame in enumerate(meta["frames"]):
        where = f"{path}: frame {i}"
        if not isinstance(frame, dict) or not isinstance(frame.get("file_path"), str):
            raise UserError(f"{where}: expected an object with file_path and transform_matrix")
        where = f"{path}: frame {i} ({frame['file_path']})"
        if "transform_matrix" not in frame:
            raise UserError(f"{where}: no transform_matrix")
        T_gl = check_rigid(_matrix(frame["transform_matrix"], where, "transform_matrix"), where)
        color = root / frame["file_path"]
        intr, dist = _camera(meta, frame, where, color)
        depth = frame.get("depth_file_path")
        if depth is not None and not isinstance(depth, str):
            raise UserError(f"{where}: depth_file_path must be a string")
        frames.append(FrameRecord(frame["file_path"], color, root / depth if depth else None, T_gl @ OPENGL_TO_OPENCV,
                                  intrinsics=intr, distortion=dist))
    if not frames:
        raise UserError(f"{path}: no frames")
    frames.sort(key=lambda r: r.name)
    shared = frames[0].intrinsics
    if all(r.intrinsics == shared for r in frames):
        frames = [replace(r, intrinsics=None) for r in frames]
    with_depth = sum(r.depth_path is not None for r in frames)
    log.info("nerfstudio: %d frames, %d with depth (depth_unit_scale_factor 1e-3: millimetres)%s", len(frames), with_depth,
             "; applied_transform present (poses used as written, in the transforms.json world)" if applied is not None else "")
    return FrameSet(root, "nerfstudio", shared, NERFSTUDIO_DEPTH_SCALE, tuple(frames))


__all__ = ["NERFSTUDIO_DEPTH_SCALE", "OPENGL_TO_OPENCV", "PERSPECTIVE_MODELS", "FISHEYE_MODELS", "read_applied_transform",
           "read_nerfstudio"]
