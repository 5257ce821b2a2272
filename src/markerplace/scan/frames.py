"""RGB-D frame sets on disk: the project's own layout, and opening a folder in any layout.

markerplace layout (``--format markerplace``)
---------------------------------------------
::

    FRAMES_DIR/
      intrinsics.json      {"width": 320, "height": 240, "fx": 262.5, "fy": 262.5,
                            "cx": 159.5, "cy": 119.5, "depth_scale": 1000}
      poses.txt            one frame per line: NAME then the 16 numbers of the 4x4
                           world_from_cam, row-major; '#' starts a comment
      color/NAME.png       8-bit RGB (grey and RGBA are accepted and converted)
      depth/NAME.png       16-bit single channel, depth_scale units per metre
                           (default 1000 = millimetres), 0 = no reading

* ``world_from_cam`` maps camera-frame points to the world (world z up, metres). The camera
  frame is OpenCV's: x right, y down, z forward. The rotation must be orthonormal with
  determinant +1 (max |R^T R - I| <= 2e-3; it is re-orthonormalized) and the last row
  ``0 0 0 1``.
* Depth is *planar* (the camera z of the surface, not the distance along the ray), registered to
  the colour image: both images are ``height`` x ``width`` and share the intrinsics (pixel
  centres at integer coordinates, OpenCV convention).
* ``poses.txt`` defines the frames and their order; images it does not name are ignored. Frame
  names contain no whitespace and no ``/``.

The other layouts: TUM RGB-D (``--format tum``, :mod:`markerplace.scan.tum`), 7-Scenes
(``7scenes``, :mod:`markerplace.scan.sevenscenes`), nerfstudio ``transforms.json``
(``nerfstudio``, :mod:`markerplace.scan.nerfstudio`) and Stray Scanner (``stray``,
:mod:`markerplace.scan.stray`); the frame types and shared parsing are in
:mod:`markerplace.scan.frameset`. This module reads and writes the markerplace layout, detects
the layout of a folder and opens it with its up axis turned to +z (:func:`open_frameset`, rule
in :mod:`markerplace.scan.up`); :func:`load_frame` (from :mod:`markerplace.scan.frame_images`) loads
a frame's images.

Every problem with a frame set raises :class:`~markerplace.errors.UserError` with one line that
names the file (and line) at fault.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.runtime.atomic_io import atomic_path, write_image, write_json
from markerplace.scan.frameset import FRAME_NAME_RE, FrameRecord, FrameSet, check_rigid, data_lines, intrinsics_dict, parse_numbers, read_intrinsics
from markerplace.scan.nerfstudio import read_nerfstudio
from markerplace.scan.sevenscenes import GRAVITY_FILE, read_7scenes, read_gravity
from markerplace.scan.stray import STRAY_UP, STRAY_UP_SOURCE, read_stray
from markerplace.scan.tum import TUM_MAX_DT, read_tum
from markerplace.scan.up import SPREAD_WARN_DEG, UP_SOURCE_CAMERAS, angle_deg, estimate_up_from_cameras, parse_up, world_from_input

log = logging.getLogger(__name__)

FORMATS = ("markerplace", "tum", "7scenes", "nerfstudio", "stray")
MARKERPLACE_DEPTH_SCALE = 1000.0
"""Depth PNG units per metre of the markerplace layout (millimetres)."""


def detect_format(root: Path) -> str:
    """The layout of a folder, by the files it has: ``"markerplace"`` (``poses.txt`` or
    ``intrinsics.json``), ``"tum"`` (``rgb.txt`` or ``depth.txt``), ``"7scenes"``
    (``frame-*.pose.txt``), ``"nerfstudio"`` (``transforms.json``), ``"stray"``
    (``odometry.csv``); :class:`UserError` otherwise."""
    root = Path(root)
    if (root / "poses.txt").exists() or (root / "intrinsics.json").exists():
        return "markerplace"
    if (root / "rgb.txt").exists() or (root / "depth.txt").exists():
        return "tum"
    if any(root.glob("frame-*.pose.txt")):
        return "7scenes"
    if (root / "transforms.json").exists():
        return "nerfstudio"
    if (root / "odometry.csv").exists():
        return "stray"
    raise UserError(
        f"{root} is not an RGB-D frame folder: expected intrinsics.json + poses.txt + color/ + depth/ "
        "(markerplace layout, see docs/rgbd_layout.md), rgb.txt + depth.txt + groundtruth.txt (TUM), "
        "frame-NNNNNN.pose.txt (7-Scenes), transforms.json (nerfstudio) or odometry.csv (Stray Scanner)"
    )


def read_markerplace(root: Path) -> FrameSet:
    """Read a frame folder in the markerplace layout (module docstring). Images are checked when loaded."""
    root = Path(root)
    intrinsics, scale = read_intrinsics(root / "intrinsics.json", MARKERPLACE_DEPTH_SCALE)
    poses = root / "poses.txt"
    if not poses.is_file():
        raise UserError(f"{poses} not found (one line per frame: NAME and 16 numbers of world_from_cam)")
    frames, seen = [], set()
    for lineno, fields in data_lines(poses):
        where = f"{poses}:{lineno}"
        name = fields[0]
        if len(fields) != 17:
            raise UserError(f"{where}: expected a frame name and 16 numbers (4x4 world_from_cam, row-major), got {len(fields) - 1} values")
        if not FRAME_NAME_RE.match(name):
            raise UserError(f"{where}: frame name {name!r} must not contain '/' or '\\'")
        if name in seen:
            raise UserError(f"{where}: frame {name!r} is listed twice")
        seen.add(name)
        T = check_rigid(np.array(parse_numbers(fields[1:], where)).reshape(4, 4), where)
        frames.append(FrameRecord(name, root / "color" / f"{name}.png", root / "depth" / f"{name}.png", T))
    return FrameSet(root, "markerplace", intrinsics, scale, tuple(frames))


READERS = {"markerplace": read_markerplace, "7scenes": read_7scenes, "nerfstudio": read_nerfstudio, "stray": read_stray}


def layout_up(fs: FrameSet) -> tuple[np.ndarray, str] | None:
    """(unit up in the input's world, source) when the layout says where up is, else None:
    the markerplace layout is z up, Stray Scanner's ARKit world y up, a 7-Scenes sequence with
    ``gravity-direction.txt`` minus gravity."""
    if fs.format == "markerplace":
        return np.array([0.0, 0.0, 1.0]), "layout (z up)"
    if fs.format == "stray":
        return np.array(STRAY_UP), STRAY_UP_SOURCE
    if fs.format == "7scenes":
        g = read_gravity(fs.root)
        if g is not None:
            return g, GRAVITY_FILE
    return None


def orient(fs: FrameSet, up=None) -> FrameSet:
    """``fs`` (poses as written) turned so that its up axis is +z: ``up`` (``--up``) if given,
    else the layout's (:func:`layout_up`), else the cameras' estimate; logged."""
    if up is not None:
        vec, source = parse_up(up), "--up"
    elif (lu := layout_up(fs)) is not None:
        vec, source = lu
    else:
        vec, spread = estimate_up_from_cameras([r.world_from_cam for r in fs.frames])
        source = UP_SOURCE_CAMERAS
        (log.warning if spread > SPREAD_WARN_DEG else log.info)(
            "%s: up axis estimated from %d cameras' down axes: (%.3f, %.3f, %.3f), spread %.1f deg%s", fs.root,
            len(fs.frames), *vec, spread, "; the cameras' up axes spread widely: check the result or give --up"
            if spread > SPREAD_WARN_DEG else "")
    T = world_from_input(vec)
    log.info("%s: up axis (%s): (%.3f, %.3f, %.3f) in the input world, turned %.1f deg to +z", fs.root, source, *vec,
             angle_deg(vec, [0.0, 0.0, 1.0]))
    if np.array_equal(T, np.eye(4)):
        return replace(fs, up_source=source, world_from_input=T)
    frames = tuple(replace(r, world_from_cam=T @ r.world_from_cam) for r in fs.frames)
    return replace(fs, frames=frames, up_source=source, world_from_input=T)


def open_frameset(root: str | Path, fmt: str = "auto", intrinsics_path: str | Path | None = None,
                  max_dt: float = TUM_MAX_DT, up=None) -> FrameSet:
    """Read a frame folder in any layout, its world turned so that +z is up.

    Args:
        root: the folder.
        fmt: ``"auto"`` (detect) or one of :data:`FORMATS`.
        intrinsics_path: JSON intrinsics for the TUM layout (ignored, with a warning, otherwise).
        max_dt: TUM association window, seconds.
        up: the up direction in the input's world (``"z"``, ``"-y"``, ``"0,0.9,0.4"`` or three
            numbers); None = the layout's, else estimated from the cameras (:func:`orient`).

    Raises:
        UserError: missing folder or files, malformed lines, non-rigid poses, no frames, bad ``up``.
    """
    root = Path(root)
    if not root.exists():
        raise UserError(f"frame folder {root} not found")
    if not root.is_dir():
        raise UserError(f"{root} is not a folder (give the folder that holds the frames)")
    if fmt not in ("auto", *FORMATS):
        raise UserError(f"--format {fmt!r}: choose auto, {', '.join(FORMATS)}")
    if up is not None:
        parse_up(up)  # a bad --up fails before any file is read
    if fmt == "auto":
        fmt = detect_format(root)
    if fmt == "tum":
        fs = read_tum(root, intrinsics_path, max_dt)
    else:
        if intrinsics_path is not None:
            log.warning("--intrinsics is for the TUM layout; %s uses its own camera files", root)
        fs = READERS[fmt](root)
    if not fs.frames:
        hint = " (no colour/depth/pose triple within the time window)" if fmt == "tum" else ""
        raise UserError(f"{root}: no frames{hint}")
    return orient(fs, up)


class FrameWriter:
    """Writes frames in the markerplace layout; every file is written atomically.

    ``poses.txt`` is rewritten by :meth:`close` (also used as a context manager), so a folder
    with a complete ``poses.txt`` has all of its images.

    Args:
        root: output folder (created).
        intrinsics: camera model of the images.
        depth_scale: depth PNG units per metre (default millimetres).
    """

    def __init__(self, root: str | Path, intrinsics: Intrinsics, depth_scale: float = MARKERPLACE_DEPTH_SCALE):
        self.root = Path(root)
        self.intrinsics = intrinsics
        self.depth_scale = float(depth_scale)
        (self.root / "color").mkdir(parents=True, exist_ok=True)
        (self.root / "depth").mkdir(parents=True, exist_ok=True)
        write_json(self.root / "intrinsics.json", intrinsics_dict(intrinsics, depth_scale))
        self._lines: list[str] = []

    def write(self, name: str, rgb: np.ndarray, depth: np.ndarray, world_from_cam: np.ndarray) -> None:
        """Write one frame: rgb (H, W, 3) uint8, depth (H, W) uint16 in ``depth_scale`` units, (4, 4) pose."""
        import cv2


        if not FRAME_NAME_RE.match(name):
            raise ValueError(f"bad frame name {name!r}")
        if depth.dtype != np.uint16:
            raise ValueError("depth must be uint16")
        write_image(self.root / "color" / f"{name}.png", rgb)
        with atomic_path(self.root / "depth" / f"{name}.png") as tmp:
            if not cv2.imwrite(str(tmp), depth):
                raise UserError(f"cannot write {self.root / 'depth' / (name + '.png')}")
        T = np.asarray(world_from_cam, dtype=np.float64).reshape(-1)
        self._lines.append(name + " " + " ".join(f"{v:.17g}" for v in T))

    def close(self) -> None:
        """Write ``poses.txt`` (atomically)."""
        header = ("# markerplace RGB-D frames: NAME then the 4x4 world_from_cam, row-major "
                  "(OpenCV camera: x right, y down, z forward; world z up, metres)\n")
        with atomic_path(self.root / "poses.txt") as tmp:
            tmp.write_text(header + "".join(line + "\n" for line in self._lines))

    def __enter__(self) -> "FrameWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


__all__ = ["FORMATS", "MARKERPLACE_DEPTH_SCALE", "READERS", "detect_format", "read_markerplace", "layout_up", "orient",
           "open_frameset",
           "FrameWriter"]
