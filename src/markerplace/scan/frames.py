"""RGB-D frame sets on disk: the project's own layout and the TUM RGB-D benchmark layout.

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

The TUM RGB-D layout (``--format tum``) is read by :mod:`markerplace.scan.tum`; the frame
types, pose checks and ``intrinsics.json`` parsing both layouts share are in
:mod:`markerplace.scan.frameset`. This module reads and writes the markerplace layout, detects
the layout of a folder (:func:`open_frameset`) and loads a frame's images (:func:`load_frame`).

Every problem with a frame set raises :class:`~markerplace.errors.UserError` with one line that
names the file (and line) at fault.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.runtime.atomic_io import atomic_path
from markerplace.scan.frameset import (FRAME_NAME_RE, FrameRecord, FrameSet, check_rigid, data_lines, intrinsics_dict, parse_numbers,
                       read_intrinsics)
from markerplace.scan.tum import TUM_MAX_DT, read_tum
from markerplace.runtime.atomic_io import write_image, write_json

log = logging.getLogger(__name__)

FORMATS = ("markerplace", "tum")
MARKERPLACE_DEPTH_SCALE = 1000.0
"""Depth PNG units per metre of the markerplace layout (millimetres)."""


def detect_format(root: Path) -> str:
    """``"markerplace"`` when ``poses.txt`` or ``intrinsics.json`` exists, ``"tum"`` when ``rgb.txt``
    or ``depth.txt`` does; :class:`UserError` otherwise."""
    root = Path(root)
    if (root / "poses.txt").exists() or (root / "intrinsics.json").exists():
        return "markerplace"
    if (root / "rgb.txt").exists() or (root / "depth.txt").exists():
        return "tum"
    raise UserError(
        f"{root} is not an RGB-D frame folder: expected intrinsics.json + poses.txt + color/ + depth/ "
        "(markerplace layout, see docs/rgbd_layout.md) or rgb.txt + depth.txt + groundtruth.txt (TUM)"
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


def open_frameset(root: str | Path, fmt: str = "auto", intrinsics_path: str | Path | None = None,
                  max_dt: float = TUM_MAX_DT) -> FrameSet:
    """Read a frame folder in either layout.

    Args:
        root: the folder.
        fmt: ``"auto"`` (detect), ``"markerplace"`` or ``"tum"``.
        intrinsics_path: JSON intrinsics for the TUM layout (ignored, with a warning, otherwise).
        max_dt: TUM association window, seconds.

    Raises:
        UserError: missing folder or files, malformed lines, non-rigid poses, no frames.
    """
    root = Path(root)
    if not root.exists():
        raise UserError(f"frame folder {root} not found")
    if not root.is_dir():
        raise UserError(f"{root} is not a folder (give the folder that holds the frames)")
    if fmt not in ("auto", *FORMATS):
        raise UserError(f"--format {fmt!r}: choose auto, {' or '.join(FORMATS)}")
    if fmt == "auto":
        fmt = detect_format(root)
    if fmt == "tum":
        fs = read_tum(root, intrinsics_path, max_dt)
    else:
        if intrinsics_path is not None:
            log.warning("--intrinsics is for the TUM layout; %s uses its own intrinsics.json", root)
        fs = read_markerplace(root)
    if not fs.frames:
        hint = " (no colour/depth/pose triple within the time window)" if fmt == "tum" else ""
        raise UserError(f"{root}: no frames{hint}")
    return fs


def load_frame(fs: FrameSet, rec: FrameRecord) -> tuple[np.ndarray, np.ndarray]:
    """Read one frame's images and check them against the frame set's intrinsics.

    Returns:
        rgb (H, W, 3) uint8 and depth (H, W) uint16 in ``fs.depth_scale`` units per metre.

    Raises:
        UserError: missing or unreadable file, wrong size, colour not 8-bit, depth not 16-bit
            single-channel.
    """
    import cv2
    from PIL import Image

    W, H = fs.intrinsics.width, fs.intrinsics.height
    for p, what in ((rec.color_path, "colour"), (rec.depth_path, "depth")):
        if not p.is_file():
            raise UserError(f"frame {rec.name}: {what} image {p} not found")
    depth = cv2.imread(str(rec.depth_path), cv2.IMREAD_UNCHANGED)
    if depth is None:
        raise UserError(f"frame {rec.name}: cannot read depth image {rec.depth_path} (not an image?)")
    if depth.dtype != np.uint16 or depth.ndim != 2:
        kind = f"{depth.dtype} with {1 if depth.ndim == 2 else depth.shape[2]} channel(s)"
        raise UserError(f"frame {rec.name}: depth image {rec.depth_path} is {kind}; it must be a 16-bit single-channel PNG")
    if depth.shape != (H, W):
        raise UserError(f"frame {rec.name}: depth image {rec.depth_path} is {depth.shape[1]}x{depth.shape[0]}, the intrinsics say {W}x{H}")
    try:
        with Image.open(rec.color_path) as img:
            mode = img.mode
            if mode not in ("RGB", "RGBA", "L", "LA", "P"):
                raise UserError(f"frame {rec.name}: colour image {rec.color_path} has mode {mode}; it must be 8-bit RGB")
            rgb = np.asarray(img.convert("RGB"))
    except UserError:
        raise
    except Exception as err:  # PIL raises many kinds on corrupt files
        raise UserError(f"frame {rec.name}: cannot read colour image {rec.color_path} ({err.__class__.__name__})") from None
    if rgb.shape[:2] != (H, W):
        raise UserError(f"frame {rec.name}: colour image {rec.color_path} is {rgb.shape[1]}x{rgb.shape[0]}, the intrinsics say {W}x{H}")
    return np.ascontiguousarray(rgb), depth


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


__all__ = ["FORMATS", "MARKERPLACE_DEPTH_SCALE", "detect_format", "read_markerplace", "open_frameset", "load_frame",
           "FrameWriter"]
