"""RGB-D frame sets in memory, and the parsing both on-disk layouts share.

* :class:`FrameRecord` (one frame: colour and depth paths, (4, 4) float64 ``world_from_cam``,
  OpenCV camera x right, y down, z forward; world metres) and :class:`FrameSet` (frames, one
  pinhole :class:`~markerplace.geometry.Intrinsics` in pixels, depth PNG units per metre);
* :func:`check_rigid`: a pose's rotation must be orthonormal with determinant +1 within
  :data:`ROTATION_TOLERANCE` (then re-orthonormalized) and its last row ``0 0 0 1``;
* ``intrinsics.json`` reading and writing (``width, height, fx, fy, cx, cy`` pixels, optional
  ``depth_scale`` units per metre);
* text-file helpers (comment-stripped lines, numbers) whose errors name the file and line.

The layouts themselves: :mod:`markerplace.scan.frames` (markerplace layout, reading and writing,
and :func:`~markerplace.scan.frames.open_frameset` for either layout) and
:mod:`markerplace.scan.tum` (TUM RGB-D). Every problem raises
:class:`~markerplace.errors.UserError` with one line that names the file (and line) at fault.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.jsonfile import read_json

ROTATION_TOLERANCE = 2e-3
"""Largest accepted entry of |R^T R - I| of a pose rotation."""

FRAME_NAME_RE = re.compile(r"^[^\s/\\]+$")
"""A frame name: no whitespace, no ``/`` or ``\\``."""


@dataclass(frozen=True)
class FrameRecord:
    """One RGB-D frame of a frame set.

    Attributes:
        name: frame name (markerplace layout) or colour timestamp as written (TUM).
        color_path: 8-bit colour PNG.
        depth_path: 16-bit depth PNG.
        world_from_cam: (4, 4) float64 pose, OpenCV camera frame, metres.
    """

    name: str
    color_path: Path
    depth_path: Path
    world_from_cam: np.ndarray


@dataclass(frozen=True)
class FrameSet:
    """Frames with poses and one camera model.

    Attributes:
        root: the frame folder.
        format: ``"markerplace"`` or ``"tum"``.
        intrinsics: pinhole model of both images (pixels).
        depth_scale: depth PNG units per metre.
        frames: the frames, in order.
    """

    root: Path
    format: str
    intrinsics: Intrinsics
    depth_scale: float
    frames: tuple[FrameRecord, ...]


def check_rigid(T: np.ndarray, where: str) -> np.ndarray:
    """Validate a (4, 4) ``world_from_cam`` and return it with an exactly orthonormal rotation.

    Raises:
        UserError: non-finite entries, a last row other than ``0 0 0 1``, a rotation that is not
            orthonormal within :data:`ROTATION_TOLERANCE` or has determinant -1 (a mirror).
    """
    T = np.asarray(T, dtype=np.float64).reshape(4, 4)
    if not np.all(np.isfinite(T)):
        raise UserError(f"{where}: the pose has non-finite values")
    if np.max(np.abs(T[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-6:
        raise UserError(f"{where}: the pose's last row must be 0 0 0 1, got {' '.join(f'{v:g}' for v in T[3])}")
    R = T[:3, :3]
    err = float(np.max(np.abs(R.T @ R - np.eye(3))))
    if err > ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        raise UserError(
            f"{where}: the pose is not rigid (rotation part not orthonormal with determinant +1; "
            f"max |R^T R - I| = {err:.3g}, det = {np.linalg.det(R):.3g})"
        )
    out = T.copy()
    if err > 1e-12:  # leave exact rotations bit-identical (poses written with %.17g round-trip)
        U, _, Vt = np.linalg.svd(R)
        out[:3, :3] = U @ Vt
    return out


def parse_numbers(values: Sequence[str], where: str) -> list[float]:
    """Floats of ``values``; :class:`UserError` naming ``where`` when one is not a number."""
    try:
        out = [float(v) for v in values]
    except ValueError:
        raise UserError(f"{where}: expected numbers, got {' '.join(values)!r}") from None
    return out


def data_lines(path: Path) -> list[tuple[int, list[str]]]:
    """(line number, whitespace-split fields) of the non-empty, non-comment lines of a text file."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as err:
        raise UserError(f"cannot read {path}: {err.strerror or err}") from None
    out = []
    for i, line in enumerate(text.splitlines(), start=1):
        line = line.split("#", 1)[0].strip()
        if line:
            out.append((i, line.replace(",", " ").split()))
    return out


def read_intrinsics(path: Path, default_depth_scale: float) -> tuple[Intrinsics, float]:
    """Read an intrinsics JSON file: ``width, height, fx, fy, cx, cy`` and optional ``depth_scale``.

    Returns:
        (intrinsics, depth units per metre).
    """
    path = Path(path)
    if not path.is_file():
        raise UserError(f"intrinsics file {path} not found")
    data = read_json(path, f"intrinsics file {path}")
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected a JSON object with width, height, fx, fy, cx, cy")
    missing = [k for k in ("width", "height", "fx", "fy", "cx", "cy") if k not in data]
    if missing:
        raise UserError(f"{path}: missing {', '.join(missing)} (needs width, height, fx, fy, cx, cy; optional depth_scale)")
    try:
        w, h = int(data["width"]), int(data["height"])
        fx, fy, cx, cy = (float(data[k]) for k in ("fx", "fy", "cx", "cy"))
        scale = float(data.get("depth_scale", default_depth_scale))
    except (TypeError, ValueError):
        raise UserError(f"{path}: width/height must be integers and fx, fy, cx, cy, depth_scale numbers") from None
    if w <= 0 or h <= 0 or w != data["width"] or h != data["height"]:
        raise UserError(f"{path}: width and height must be positive integers, got {data['width']!r} x {data['height']!r}")
    if not all(math.isfinite(v) for v in (fx, fy, cx, cy, scale)) or fx <= 0 or fy <= 0 or scale <= 0:
        raise UserError(f"{path}: fx, fy and depth_scale must be positive and cx, cy finite")
    return Intrinsics(w, h, fx, fy, cx, cy), scale


def intrinsics_dict(intrinsics: Intrinsics, depth_scale: float) -> dict:
    """The JSON object of ``intrinsics.json``."""
    return {"width": int(intrinsics.width), "height": int(intrinsics.height), "fx": float(intrinsics.fx),
            "fy": float(intrinsics.fy), "cx": float(intrinsics.cx), "cy": float(intrinsics.cy),
            "depth_scale": float(depth_scale)}


__all__ = ["FrameRecord", "FrameSet", "ROTATION_TOLERANCE", "FRAME_NAME_RE", "check_rigid", "parse_numbers", "data_lines",
           "read_intrinsics", "intrinsics_dict"]
