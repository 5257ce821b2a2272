"""Test poses of the simulation testbed (paper, "The map and test data"; docs/design.md section 3).

A test pose is a feasible camera pose (the map poses of the planner's discretization), drawn
either ``uniform`` or ``weighted`` towards low localizability scores with the paper's weights

    w(c) = 2 l* - mean(l) - l(c)      (l = score without markers, l* = max l)

or ``where`` proportionally to the ``--where`` pose weights (:mod:`markerplace.plan.where`: the
places and directions of use the plan was weighted by), and then perturbed: x, y += U(-0.5, 0.5) * grid_spacing, yaw += U(-0.5, 0.5) * 45 deg (height,
pitch and roll unchanged). A perturbed pose is kept only where the camera is in free space of
its own storey (occupancy cell free and clearance above ``min_clearance``); rejected draws are
redrawn. All randomness comes from ``numpy.random.default_rng(seed)``: the same seed gives the
same poses, so every placement method is evaluated on identical test images.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import world_from_cam_poses
from markerplace.runtime import cache
from markerplace.runtime.atomic_io import write_npz
from markerplace.runtime.stages import cached

TEST_SETS = ("weighted", "uniform")
"""The test sets of every evaluation (the default of ``--test-sets``)."""

WHERE_SET = "where"
"""The test set drawn from the ``--where`` pose weights; valid only with a where file."""

ALL_TEST_SETS = TEST_SETS + (WHERE_SET,)
"""Every test set name, in the order that seeds them (``seed + 1000 * index``)."""



@dataclass(frozen=True)
class TestPoseConfig:
    """How test poses are drawn.

    Attributes:
        num: number of test poses N (paper: 200 for the room, 2000 for the office).
        mode: ``weighted`` (towards low scores, the paper's default), ``uniform`` or ``where``
            (proportional to the pose weights of ``plan --where``).
        xy_jitter: x and y are perturbed by U(-0.5, 0.5) * xy_jitter * grid_spacing.
        yaw_jitter_deg: yaw is perturbed by U(-0.5, 0.5) * yaw_jitter_deg degrees (paper: 45).
        min_clearance: a perturbed camera must be at least this far (metres) from any non-free
            occupancy cell.
        seed: seed of ``numpy.random.default_rng``.
        max_rounds: give up (UserError) after this many rounds of redrawing.
        stream: independent random stream of the same seed: 0 (test poses) draws from
            ``default_rng(seed)``, any other value from ``default_rng([seed, stream])``, a stream
            no integer seed reaches (``expected-recall``'s off-grid calibration images use 1, so
            they are never test images, whatever ``--test-seed`` is).
    """

    __test__ = False  # not a pytest class

    num: int = 200
    mode: str = "weighted"
    xy_jitter: float = 1.0
    yaw_jitter_deg: float = 45.0
    min_clearance: float = 0.1
    seed: int = 0
    max_rounds: int = 100
    stream: int = 0


@dataclass(frozen=True, eq=False)
class TestPoses:
    """Perturbed test camera poses.

    Attributes:
        world_from_cam: (N, 4, 4) camera poses (OpenCV camera frame, world z up, metres).
        source_index: (N,) index of the feasible pose each one was drawn from.
        offset_xy: (N, 2) applied translation perturbation, metres.
        offset_yaw: (N,) applied yaw perturbation, radians.
    """

    __test__ = False

    world_from_cam: np.ndarray
    source_index: np.ndarray
    offset_xy: np.ndarray
    offset_yaw: np.ndarray

    def __len__(self) -> int:
        return len(self.world_from_cam)

    def save(self, path: str | Path) -> None:
        """Write as ``.npz`` atomically."""
        write_npz(path, world_from_cam=self.world_from_cam, source_index=self.source_index,
                  offset_xy=self.offset_xy, offset_yaw=self.offset_yaw)

    @classmethod
    def load(cls, path: str | Path) -> "TestPoses":
        with np.load(path, allow_pickle=False) as f:
            return cls(f["world_from_cam"], f["source_index"], f["offset_xy"], f["offset_yaw"])


def test_pose_weights(scores: np.ndarray) -> np.ndarray:
    """The paper's sampling weights ``w = 2 l* - mean(l) - l`` for (N,) scores l -> (N,) >= 0.

    The weight of the best pose is ``l* - mean(l) >= 0``; lower scores get larger weights. When
    every score is equal all weights are 0; :func:`sampling_probabilities` then falls back to
    uniform.
    """
    scores = np.asarray(scores, dtype=float)
    if scores.ndim != 1 or len(scores) == 0:
        raise ValueError("scores must be a non-empty 1-D array")
    w = 2.0 * scores.max() - scores.mean() - scores
    return np.maximum(w, 0.0)  # clip -1e-15 rounding noise


test_pose_weights.__test__ = False  # type: ignore[attr-defined]


def sampling_probabilities(scores: np.ndarray, mode: str, weights: np.ndarray | None = None) -> np.ndarray:
    """(N,) probabilities of drawing each feasible pose for ``mode`` in :data:`ALL_TEST_SETS`
    (``where``: proportional to the (N,) pose ``weights``, which it needs)."""
    if mode not in ALL_TEST_SETS:
        raise UserError(f"test set {mode!r} is not known: use one of {', '.join(ALL_TEST_SETS)}")
    if mode == WHERE_SET:
        if weights is None or not np.sum(weights) > 0:
            raise UserError("test set 'where' needs --where FILE (the places and directions of use)")
        w = np.asarray(weights, dtype=float)
        return w / w.sum()
    n = len(scores)
    if mode == "uniform":
        return np.full(n, 1.0 / n)
    w = test_pose_weights(scores)
    total = w.sum()
    return w / total if total > 0 else np.full(n, 1.0 / n)


def free_space_checker(occupancy: np.ndarray, origin: Sequence[float], resolution: float,
                       min_clearance: float, layer_of_pose: np.ndarray | None = None
                       ) -> Callable[..., np.ndarray]:
    """A function ``check(xy (M, 2), source_index (M,) = None) -> (M,) bool``: "free with enough
    clearance" at world xy (metres), on the storey of the feasible pose each point was drawn from.

    Args:
        occupancy: (H, W) grid, or (S, H, W) one per storey; 0 free, 1 occupied, -1 unknown;
            row 0 at ``origin`` y, column 0 at ``origin`` x (the discretization's grids).
        origin: (x0, y0) world metres of the grid's lower-left corner.
        resolution: cell size, metres.
        min_clearance: required distance (metres) from the cell centre to the nearest
            non-free (occupied or unknown) cell centre.
        layer_of_pose: (N,) occupancy layer of each feasible pose (needed when S > 1).
    """
    from scipy.ndimage import distance_transform_edt

    occ = np.asarray(occupancy)
    if occ.ndim == 2:
        occ = occ[None]
    free = occ == 0
    clearance = np.stack([distance_transform_edt(f) * float(resolution) for f in free])  # 0 on non-free cells
    x0, y0 = float(origin[0]), float(origin[1])
    S, H, W = free.shape
    layers = None if layer_of_pose is None else np.asarray(layer_of_pose, dtype=np.int64)

    def check(xy: np.ndarray, source_index: np.ndarray | None = None) -> np.ndarray:
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if S == 1:
            layer = np.zeros(len(xy), np.int64)
        elif layers is None or source_index is None:
            raise ValueError("several storeys: give layer_of_pose and the source pose of each point")
        else:
            layer = layers[np.asarray(source_index, dtype=np.int64)]
        col = np.floor((xy[:, 0] - x0) / resolution).astype(int)
        row = np.floor((xy[:, 1] - y0) / resolution).astype(int)
        inside = (col >= 0) & (col < W) & (row >= 0) & (row < H)
        ok = np.zeros(len(xy), dtype=bool)
        li, ri, ci = layer[inside], row[inside], col[inside]
        ok[inside] = free[li, ri, ci] & (clearance[li, ri, ci] > min_clearance)
        return ok

    return check


def free_space_of(disc, min_clearance: float) -> Callable[..., np.ndarray]:
    """:func:`free_space_checker` of a discretization (``markerplace.plan.discretize.artifact``): its
    occupancy grids, one layer per planned storey, each feasible pose checked on its own storey."""
    layer = {int(st): k for k, st in enumerate(disc.planned_storeys)}
    return free_space_checker(disc.occupancy, disc.grid_origin, disc.grid_resolution, min_clearance,
                              np.array([layer[int(st)] for st in disc.pose_storey], dtype=np.int64))


def sample_test_poses(world_from_cam: np.ndarray, scores: np.ndarray, grid_spacing: float,
                      config: TestPoseConfig, is_free: Callable[[np.ndarray], np.ndarray],
                      weights: np.ndarray | None = None) -> TestPoses:
    """Draw ``config.num`` perturbed test poses from the feasible poses.

    Args:
        world_from_cam: (N, 4, 4) feasible (map) poses, level cameras.
        scores: (N,) localizability score of each pose without markers (used by ``weighted``).
        grid_spacing: camera grid spacing, metres (scale of the xy perturbation).
        config: number, mode, perturbation and seed.
        is_free: ``(xy (M, 2), source_index (M,)) -> (M,) bool``, e.g. from :func:`free_space_checker`.
        weights: (N,) pose weights of ``--where`` (used by ``where``), or None.

    Returns:
        :class:`TestPoses` with exactly ``config.num`` poses, in draw order.
    """
    if config.num < 1:
        raise UserError(f"--tests {config.num} must be at least 1")
    world_from_cam = np.asarray(world_from_cam, dtype=float)
    if len(world_from_cam) == 0:
        raise UserError("no feasible camera poses to draw test poses from: check --height and --grid-spacing")
    probs = sampling_probabilities(np.asarray(scores, dtype=float), config.mode, weights)
    rng = np.random.default_rng(config.seed if config.stream == 0 else [config.seed, config.stream])
    yaws = np.arctan2(world_from_cam[:, 1, 2], world_from_cam[:, 0, 2])
    kept_idx, kept_dxy, kept_dyaw = [], [], []
    need = config.num
    for _ in range(config.max_rounds):
        batch = max(2 * need, 16)
        idx = rng.choice(len(world_from_cam), size=batch, p=probs)
        dxy = rng.uniform(-0.5, 0.5, size=(batch, 2)) * config.xy_jitter * grid_spacing
        dyaw = np.radians(rng.uniform(-0.5, 0.5, size=batch) * config.yaw_jitter_deg)
        ok = is_free(world_from_cam[idx, :2, 3] + dxy, idx)
        take = np.flatnonzero(ok)[:need]
        kept_idx.append(idx[take])
        kept_dxy.append(dxy[take])
        kept_dyaw.append(dyaw[take])
        need -= len(take)
        if need == 0:
            break
    else:
        raise UserError(f"could only place {config.num - need} of {config.num} test poses in free space: "
                        "lower --tests or check the scene's free space")
    idx = np.concatenate(kept_idx)
    dxy = np.concatenate(kept_dxy)
    dyaw = np.concatenate(kept_dyaw)
    positions = world_from_cam[idx, :3, 3].copy()
    positions[:, :2] += dxy
    poses = world_from_cam_poses(positions, yaws[idx] + dyaw)
    return TestPoses(poses, idx.astype(np.int64), dxy, dyaw)


def cached_test_poses(out: Path, config, plan_config, data, base_key: str, timings: dict) -> dict:
    """The test poses of every test set of an evaluation, ``out/test_poses_<set>.npz``, reused
    while the map, the scores and the settings are unchanged. A set's seed does not depend on
    which other sets run. The ``where`` set's key holds the pose weights (``data.pose_weight``, from
    the ``--where`` file), so another file draws other poses. Returns test set name -> :class:`TestPoses`."""
    map_poses = np.asarray(data.disc.world_from_cam, float)
    is_free = free_space_of(data.disc, config.test.min_clearance)
    poses = {}
    for ts in config.test.sets:
        tcfg = TestPoseConfig(num=config.test.tests, mode=ts, seed=config.pose_seed + 1000 * ALL_TEST_SETS.index(ts),
                              min_clearance=config.test.min_clearance)
        weights = data.pose_weight if ts == WHERE_SET else None
        key = cache.hash_of("test-poses-v1", base_key, data.base_score, tcfg, plan_config.discretize.grid_spacing,
                            *(() if weights is None else (np.asarray(weights, float),)))
        poses[ts] = cached("test_poses", out / f"test_poses_{ts}.npz", key,
                           lambda: sample_test_poses(map_poses, data.base_score, plan_config.discretize.grid_spacing,
                                                     tcfg, is_free, weights),
                           lambda tp, path: tp.save(path), TestPoses.load, timings)
    return poses
