"""RGB-D frame sets in memory, and the parsing the on-disk layouts share.

* :class:`FrameRecord` (one frame: colour and depth paths, (4, 4) float64 ``world_from_cam``,
  OpenCV camera x right, y down, z forward; world metres, +z up once opened; optionally its own
  pinhole :class:`~markerplace.geometry.Intrinsics` and lens :class:`Distortion`) and
  :class:`FrameSet` (frames, the set's pinhole intrinsics in pixels, depth PNG units per metre,
  where its up axis came from and the (4, 4) rotation applied to the input's world);
* :func:`frame_intrinsics`: the pinhole camera of a frame's (undistorted) images;
* :func:`check_rigid`: a pose's rotation must be orthonormal with determinant +1 within
  :data:`ROTATION_TOLERANCE` (then re-orthonormalized) and its last row ``0 0 0 1``;
* ``intrinsics.json`` reading and writing (``width, height, fx, fy, cx, cy`` pixels, optional
  ``depth_scale`` units per metre);
* text-file helpers (comment-stripped lines, numbers) whose errors name the file and line.

The layouts themselves: :mod:`markerplace.scan.frames` (markerplace layout, reading and writing,
and :func:`~markerplace.scan.frames.open_frameset` for every layout), :mod:`markerplace.scan.tum`
(TUM RGB-D), :mod:`markerplace.scan.sevenscenes` (7-Scenes), :mod:`markerplace.scan.nerfstudio`
(``transforms.json``) and :mod:`markerplace.scan.stray` (Stray Scanner). Every problem raises
:class:`~markerplace.errors.UserError` with one line that names the file (and line) at fault.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
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
class Distortion:
    """Lens distortion of a frame's colour (and depth) image, removed when the frame is loaded.

    Attributes:
        model: ``"opencv"`` (coefficients k1, k2, p1, p2, k3 as ``cv2.undistort`` takes them) or
            ``"fisheye"`` (k1, k2, k3, k4 as ``cv2.fisheye.undistortImage`` takes them).
        coeffs: the coefficients.
    """

    model: str
    coeffs: tuple[float, ...]

    @property
    def is_zero(self) -> bool:
        """All coefficients are 0 (a pinhole camera)."""
        return not any(self.coeffs)


@dataclass(frozen=True)
class FrameRecord:
    """One RGB-D frame of a frame set.

    Attributes:
        name: frame name (markerplace layout, 7-Scenes ``frame-NNNNNN``, Stray ``NNNNNN``),
            colour timestamp as written (TUM) or ``file_path`` (nerfstudio).
        color_path: 8-bit colour image (PNG or JPEG), or the video holding it (``color_index``).
        depth_path: 16-bit depth PNG; None when the frame has no depth (nerfstudio).
        world_from_cam: (4, 4) float64 pose, OpenCV camera frame, metres.
        intrinsics: this frame's pinhole camera (pixels, of the undistorted colour image); None
            = the set's (:func:`frame_intrinsics`).
        distortion: lens distortion of the stored images; None = none.
        color_index: frame number in the video ``color_path``; None = an image file.
        confidence_path: 8-bit confidence PNG at the depth image's size (Stray: 0, 1, 2); depth
            readings below :data:`CONFIDENCE_MIN` are dropped. None = no confidence map.
    """

    name: str
    color_path: Path
    depth_path: Path | None
    world_from_cam: np.ndarray
    intrinsics: Intrinsics | None = None
    distortion: Distortion | None = None
    color_index: int | None = None
    confidence_path: Path | None = None


@dataclass(frozen=True)
class FrameSet:
    """Frames with poses and a camera model.

    Attributes:
        root: the frame folder.
        format: ``"markerplace"``, ``"tum"``, ``"7scenes"``, ``"nerfstudio"`` or ``"stray"``.
        intrinsics: pinhole model of the (undistorted) colour image and of the depth delivered
            by :func:`~markerplace.scan.frame_images.load_frame` (pixels), for frames without their own.
        depth_scale: depth PNG units per metre.
        frames: the frames, in order.
        up_source: where the up axis came from (``"--up"``, ``"gravity-direction.txt"``,
            ``"layout (z up)"``, ``"estimated from the cameras' down axes"``, ...).
        world_from_input: (4, 4) rotation applied to the input's world to make +z up:
            ``frames[i].world_from_cam = world_from_input @ (pose as written)``.
        depth_intrinsics: pinhole model of the depth images as stored when their camera is not
            the colour camera (7-Scenes), or None: the depth is registered to the colour (or a
            scaled copy of it). :func:`~markerplace.scan.frame_images.load_frame` resamples such depth
            into the colour camera (zero-baseline model: colour pixel ``x`` reads the depth pixel
            ``K_depth K_colour^-1 x``; the poses are the depth camera's).
    """

    root: Path
    format: str
    intrinsics: Intrinsics
    depth_scale: float
    frames: tuple[FrameRecord, ...]
    up_source: str = "input world as written"
    world_from_input: np.ndarray = field(default_factory=lambda: np.eye(4))
    depth_intrinsics: Intrinsics | None = None


CONFIDENCE_MIN = 1
"""Depth readings whose confidence is below this are dropped (Stray: 0 low, 1 medium, 2 high)."""


def frame_intrinsics(fs: FrameSet, rec: FrameRecord) -> Intrinsics:
    """The pinhole camera of ``rec``'s images as :func:`~markerplace.scan.frame_images.load_frame`
    returns them: the frame's own, else the set's."""
    return rec.intrinsics if rec.intrinsics is not None else fs.intrinsics


def image_size(path: Path, hint: str = "") -> tuple[int, int]:
    """(width, height) of an image file; :class:`UserError` naming it when it is missing or
    unreadable (``hint``: what the layout expects there, appended to the not-found message)."""
    from PIL import Image

    try:
        with Image.open(path) as img:
            return img.size
    except FileNotFoundError:
        raise UserError(f"colour image {path} not found{f' ({hint})' if hint else ''}") from None
    except Exception as err:  # PIL raises many kinds on corrupt files
        raise UserError(f"cannot read colour image {path} ({err.__class__.__name__})") from None


def rotation_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    """(3, 3) rotation of a unit quaternion (Hamilton convention, scalar last as in TUM files)."""
    x, y, z, w = qx, qy, qz, qw
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def pose_from_quaternion(t, q_xyzw, where: str) -> np.ndarray:
    """(4, 4) pose of a translation (3,) and a unit quaternion (x, y, z, w), scalar last (TUM,
    Stray); :class:`UserError` naming ``where`` when a value is not finite or the norm is off
    by more than 1 %."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))) or abs(norm - 1.0) > 0.01:
        raise UserError(f"{where}: the pose is not rigid (quaternion norm {norm:.4g}, must be 1)")
    T = np.eye(4)
    T[:3, :3] = rotation_from_quaternion(*(q / norm))
    T[:3, 3] = t
    return T


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


__all__ = ["image_size", "rotation_from_quaternion", "pose_from_quaternion", "Distortion", "FrameRecord", "FrameSet", "CONFIDENCE_MIN", "frame_intrinsics", "ROTATION_TOLERANCE", "FRAME_NAME_RE", "check_rigid", "parse_numbers", "data_lines",
           "read_intrinsics", "intrinsics_dict"]
