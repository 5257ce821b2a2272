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

TUM RGB-D layout (``--format tum``)
-----------------------------------
``rgb.txt`` and ``depth.txt`` (``timestamp filename`` per line), ``groundtruth.txt``
(``timestamp tx ty tz qx qy qz qw``: the colour camera's optical centre in the motion-capture
world, same OpenCV camera axes), depth PNGs scaled by 5000 per metre. Colour and depth are
associated one-to-one by nearest timestamp, greedily from the closest pair, as TUM's
``associate.py`` does, at most ``max_dt`` (0.02 s) apart; each pair takes the ground-truth pose
nearest to its colour timestamp, also within ``max_dt``. Intrinsics come from a JSON file as
above (``depth_scale`` defaults to 5000) or the freiburg1 defaults (fx 517.3, fy 516.5,
cx 318.6, cy 255.3, 640x480). The fused mesh is then in the motion-capture frame.

Every problem with a frame set raises :class:`~markerplace.errors.UserError` with one line that
names the file (and line) at fault.
"""

from __future__ import annotations

import json
import logging
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import UserError
from ..geometry import Intrinsics
from ..io_utils import atomic_path

log = logging.getLogger(__name__)

FORMATS = ("markerplace", "tum")
MARKERPLACE_DEPTH_SCALE = 1000.0
"""Depth PNG units per metre of the markerplace layout (millimetres)."""
TUM_DEPTH_SCALE = 5000.0
"""Depth PNG units per metre of the TUM RGB-D benchmark."""
TUM_FR1_INTRINSICS = Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3)
"""TUM freiburg1 colour camera (the benchmark's published calibration)."""
TUM_MAX_DT = 0.02
"""Maximum timestamp difference (s) of associated colour, depth and pose (TUM associate.py)."""
ROTATION_TOLERANCE = 2e-3
"""Largest accepted entry of |R^T R - I| of a pose rotation."""

_NAME_RE = re.compile(r"^[^\s/\\]+$")


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


# ------------------------------------------------------------------------------------- poses
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


def rotation_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    """(3, 3) rotation of a unit quaternion (Hamilton convention, scalar last as in TUM files)."""
    x, y, z, w = qx, qy, qz, qw
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _numbers(values: Sequence[str], where: str) -> list[float]:
    try:
        out = [float(v) for v in values]
    except ValueError:
        raise UserError(f"{where}: expected numbers, got {' '.join(values)!r}") from None
    return out


def _data_lines(path: Path) -> list[tuple[int, list[str]]]:
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


# -------------------------------------------------------------------------------- intrinsics
def read_intrinsics(path: Path, default_depth_scale: float) -> tuple[Intrinsics, float]:
    """Read an intrinsics JSON file: ``width, height, fx, fy, cx, cy`` and optional ``depth_scale``.

    Returns:
        (intrinsics, depth units per metre).
    """
    path = Path(path)
    if not path.is_file():
        raise UserError(f"intrinsics file {path} not found")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise UserError(f"{path}: not valid JSON ({err})") from None
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


# ---------------------------------------------------------------------------- format readers
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
    for lineno, fields in _data_lines(poses):
        where = f"{poses}:{lineno}"
        name = fields[0]
        if len(fields) != 17:
            raise UserError(f"{where}: expected a frame name and 16 numbers (4x4 world_from_cam, row-major), got {len(fields) - 1} values")
        if not _NAME_RE.match(name):
            raise UserError(f"{where}: frame name {name!r} must not contain '/' or '\\'")
        if name in seen:
            raise UserError(f"{where}: frame {name!r} is listed twice")
        seen.add(name)
        T = check_rigid(np.array(_numbers(fields[1:], where)).reshape(4, 4), where)
        frames.append(FrameRecord(name, root / "color" / f"{name}.png", root / "depth" / f"{name}.png", T))
    return FrameSet(root, "markerplace", intrinsics, scale, tuple(frames))


def _read_stamped_files(path: Path) -> tuple[np.ndarray, list[str], list[Path]]:
    """TUM ``timestamp filename`` list -> (stamps (N,), stamps as written, paths)."""
    if not path.is_file():
        raise UserError(f"{path} not found (TUM layout needs rgb.txt, depth.txt and groundtruth.txt)")
    stamps, raw, files = [], [], []
    for lineno, fields in _data_lines(path):
        if len(fields) != 2:
            raise UserError(f"{path}:{lineno}: expected 'timestamp filename', got {len(fields)} fields")
        stamps.append(_numbers(fields[:1], f"{path}:{lineno}")[0])
        raw.append(fields[0])
        files.append(path.parent / fields[1])
    return np.array(stamps, dtype=np.float64), raw, files


def associate(a: np.ndarray, b: np.ndarray, max_dt: float) -> list[tuple[int, int]]:
    """One-to-one association of two timestamp lists, as TUM's ``associate.py``.

    Every pair with ``|a_i - b_j| < max_dt`` is a candidate; candidates are taken closest first,
    skipping any that reuses an index. Returns (i, j) index pairs sorted by ``i``.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    order = np.argsort(b, kind="stable")
    bs = b[order]
    cands = []
    for i, t in enumerate(a):
        lo = np.searchsorted(bs, t - max_dt, side="left")
        hi = np.searchsorted(bs, t + max_dt, side="right")
        for k in range(lo, hi):
            d = abs(t - bs[k])
            if d < max_dt:
                cands.append((d, i, int(order[k])))
    cands.sort()
    used_a, used_b, out = set(), set(), []
    for _, i, j in cands:
        if i not in used_a and j not in used_b:
            used_a.add(i)
            used_b.add(j)
            out.append((i, j))
    return sorted(out)


def nearest(a: np.ndarray, b: np.ndarray, max_dt: float) -> np.ndarray:
    """(len(a),) index of the nearest entry of ``b`` for each of ``a``; -1 where it is ``max_dt`` or more away."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    out = np.full(len(a), -1, dtype=np.int64)
    if len(b) == 0:
        return out
    order = np.argsort(b, kind="stable")
    bs = b[order]
    k = np.clip(np.searchsorted(bs, a), 1, len(bs) - 1) if len(bs) > 1 else np.zeros(len(a), np.int64)
    left = bs[np.maximum(k - 1, 0)]
    right = bs[k]
    pick = np.where(np.abs(a - left) <= np.abs(a - right), np.maximum(k - 1, 0), k)
    ok = np.abs(a - bs[pick]) < max_dt
    out[ok] = order[pick[ok]]
    return out


def read_tum(root: Path, intrinsics_path: str | Path | None = None, max_dt: float = TUM_MAX_DT) -> FrameSet:
    """Read a TUM RGB-D benchmark sequence folder (module docstring)."""
    root = Path(root)
    if intrinsics_path is not None:
        intrinsics, scale = read_intrinsics(Path(intrinsics_path), TUM_DEPTH_SCALE)
    else:
        intrinsics, scale = TUM_FR1_INTRINSICS, TUM_DEPTH_SCALE
        log.info("TUM layout without --intrinsics: using the freiburg1 calibration (fx 517.3, fy 516.5, "
                 "cx 318.6, cy 255.3, 640x480, depth scale 5000); pass --intrinsics FILE.json for fr2/fr3 or other cameras")
    rgb_t, rgb_raw, rgb_files = _read_stamped_files(root / "rgb.txt")
    dep_t, _, dep_files = _read_stamped_files(root / "depth.txt")
    gt = root / "groundtruth.txt"
    if not gt.is_file():
        raise UserError(f"{gt} not found (TUM layout needs rgb.txt, depth.txt and groundtruth.txt)")
    gt_t, gt_T = [], []
    for lineno, fields in _data_lines(gt):
        where = f"{gt}:{lineno}"
        if len(fields) != 8:
            raise UserError(f"{where}: expected 'timestamp tx ty tz qx qy qz qw' (8 values), got {len(fields)}")
        v = _numbers(fields, where)
        q = np.array(v[4:8])
        norm = float(np.linalg.norm(q))
        if not np.all(np.isfinite(v)) or abs(norm - 1.0) > 0.01:
            raise UserError(f"{where}: the pose is not rigid (quaternion norm {norm:.4g}, must be 1)")
        T = np.eye(4)
        T[:3, :3] = rotation_from_quaternion(*(q / norm))
        T[:3, 3] = v[1:4]
        gt_t.append(v[0])
        gt_T.append(T)
    pairs = associate(rgb_t, dep_t, max_dt)
    pose_idx = nearest(rgb_t[[i for i, _ in pairs]], np.array(gt_t), max_dt) if pairs else np.zeros(0, np.int64)
    frames = []
    for (i, j), g in zip(pairs, pose_idx):
        if g >= 0:
            frames.append(FrameRecord(rgb_raw[i], rgb_files[i], dep_files[j], gt_T[g]))
    log.info("TUM: %d colour, %d depth, %d pose entries -> %d associated frames (max %.3f s apart)",
             len(rgb_t), len(dep_t), len(gt_t), len(frames), max_dt)
    return FrameSet(root, "tum", intrinsics, scale, tuple(frames))


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


# ------------------------------------------------------------------------------------ images
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


# ------------------------------------------------------------------------------------ writer
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
        from ..io_utils import write_json

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

        from ..io_utils import write_image

        if not _NAME_RE.match(name):
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
