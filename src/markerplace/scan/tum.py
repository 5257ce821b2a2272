"""The TUM RGB-D benchmark layout (``--format tum``): reading a sequence folder and associating
its timestamps.

``rgb.txt`` and ``depth.txt`` (``timestamp filename`` per line), ``groundtruth.txt``
(``timestamp tx ty tz qx qy qz qw``: the colour camera's optical centre in the motion-capture
world, same OpenCV camera axes), depth PNGs scaled by 5000 per metre. Colour and depth are
associated one-to-one by nearest timestamp, greedily from the closest pair, as TUM's
``associate.py`` does, at most ``max_dt`` (0.02 s) apart; each pair takes the ground-truth pose
nearest to its colour timestamp, also within ``max_dt``. Intrinsics come from a JSON file as
above (``depth_scale`` defaults to 5000) or the freiburg1 defaults (fx 517.3, fy 516.5,
cx 318.6, cy 255.3, 640x480). The fused mesh is then in the motion-capture frame.

Poses are (4, 4) float64 ``world_from_cam`` (OpenCV camera axes, metres); timestamps are seconds.
:func:`~markerplace.scan.frames.open_frameset` reads either layout.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.scan.frameset import FrameRecord, FrameSet, data_lines, parse_numbers, pose_from_quaternion, read_intrinsics

log = logging.getLogger(__name__)

TUM_DEPTH_SCALE = 5000.0
"""Depth PNG units per metre of the TUM RGB-D benchmark."""
TUM_FR1_INTRINSICS = Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3)
"""TUM freiburg1 colour camera (the benchmark's published calibration)."""
TUM_MAX_DT = 0.02
"""Maximum timestamp difference (s) of associated colour, depth and pose (TUM associate.py)."""


def _read_stamped_files(path: Path) -> tuple[np.ndarray, list[str], list[Path]]:
    """TUM ``timestamp filename`` list -> (stamps (N,), stamps as written, paths)."""
    if not path.is_file():
        raise UserError(f"{path} not found (TUM layout needs rgb.txt, depth.txt and groundtruth.txt)")
    stamps, raw, files = [], [], []
    for lineno, fields in data_lines(path):
        if len(fields) != 2:
            raise UserError(f"{path}:{lineno}: expected 'timestamp filename', got {len(fields)} fields")
        stamps.append(parse_numbers(fields[:1], f"{path}:{lineno}")[0])
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
    for lineno, fields in data_lines(gt):
        where = f"{gt}:{lineno}"
        if len(fields) != 8:
            raise UserError(f"{where}: expected 'timestamp tx ty tz qx qy qz qw' (8 values), got {len(fields)}")
        v = parse_numbers(fields, where)
        T = pose_from_quaternion(v[1:4], v[4:8], where)
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


__all__ = ["TUM_DEPTH_SCALE", "TUM_FR1_INTRINSICS", "TUM_MAX_DT", "associate", "nearest",
           "read_tum"]
