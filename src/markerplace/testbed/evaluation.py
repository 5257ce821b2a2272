"""Evaluation maths of the simulation testbed: test poses, pose errors and recall.

Test poses (paper, Sec. "The map and test data"; docs/design.md section 3)
--------------------------------------------------------------------
A test pose is a feasible camera pose (the map poses of the planner's discretization), drawn
either ``uniform`` or ``weighted`` towards low localizability scores with the paper's weights

    w(c) = 2 l* - mean(l) - l(c)      (l = score without markers, l* = max l)

and then perturbed: x, y += U(-0.5, 0.5) * grid_spacing, yaw += U(-0.5, 0.5) * 45 deg (height,
pitch and roll unchanged). A perturbed pose is kept only where the camera is in free space
(occupancy cell free and clearance above ``min_clearance``); rejected draws are redrawn. All
randomness comes from ``numpy.random.default_rng(seed)``: the same seed gives the same poses, so
every placement method is evaluated on identical test images.

Recall
------
``recall = #{queries with t_err <= t_max and r_err <= r_max} / #queries``. Thresholds are
INCLUSIVE (an error exactly at the threshold counts as a hit). A query that failed to localize
has errors ``inf`` (or NaN) and always counts as a miss; it stays in the denominator.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..errors import UserError
from ..geometry import world_from_cam_poses
from ..io_utils import write_npz
from ..plan.methods import PLACEMENT_METHODS

TEST_SETS = ("weighted", "uniform")

#: Recall thresholds (translation metres, rotation degrees); the paper's main one is (0.05, 5).
THRESHOLDS: tuple[tuple[float, float], ...] = ((0.01, 1.0), (0.05, 5.0), (0.10, 10.0), (1.0, 30.0))
MAIN_THRESHOLD: tuple[float, float] = (0.05, 5.0)


@dataclass(frozen=True)
class TestPoseConfig:
    """How test poses are drawn.

    Attributes:
        num: number of test poses N (paper: 200 for the room, 2000 for the office).
        mode: ``weighted`` (towards low scores, the paper's default) or ``uniform``.
        xy_jitter: x and y are perturbed by U(-0.5, 0.5) * xy_jitter * grid_spacing.
        yaw_jitter_deg: yaw is perturbed by U(-0.5, 0.5) * yaw_jitter_deg degrees (paper: 45).
        min_clearance: a perturbed camera must be at least this far (metres) from any non-free
            occupancy cell.
        seed: seed of ``numpy.random.default_rng``.
        max_rounds: give up (UserError) after this many rounds of redrawing.
    """

    __test__ = False  # not a pytest class

    num: int = 200
    mode: str = "weighted"
    xy_jitter: float = 1.0
    yaw_jitter_deg: float = 45.0
    min_clearance: float = 0.1
    seed: int = 0
    max_rounds: int = 100


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


def sampling_probabilities(scores: np.ndarray, mode: str) -> np.ndarray:
    """(N,) probabilities of drawing each feasible pose for ``mode`` in :data:`TEST_SETS`."""
    if mode not in TEST_SETS:
        raise UserError(f"test set {mode!r} is not known: use one of {', '.join(TEST_SETS)}")
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


def sample_test_poses(world_from_cam: np.ndarray, scores: np.ndarray, grid_spacing: float,
                      config: TestPoseConfig, is_free: Callable[[np.ndarray], np.ndarray]) -> TestPoses:
    """Draw ``config.num`` perturbed test poses from the feasible poses.

    Args:
        world_from_cam: (N, 4, 4) feasible (map) poses, level cameras.
        scores: (N,) localizability score of each pose without markers (used by ``weighted``).
        grid_spacing: camera grid spacing, metres (scale of the xy perturbation).
        config: number, mode, perturbation and seed.
        is_free: ``(xy (M, 2), source_index (M,)) -> (M,) bool``, e.g. from :func:`free_space_checker`.

    Returns:
        :class:`TestPoses` with exactly ``config.num`` poses, in draw order.
    """
    if config.num < 1:
        raise UserError(f"--tests {config.num} must be at least 1")
    world_from_cam = np.asarray(world_from_cam, dtype=float)
    if len(world_from_cam) == 0:
        raise UserError("no feasible camera poses to draw test poses from: check --height and --grid-spacing")
    probs = sampling_probabilities(np.asarray(scores, dtype=float), config.mode)
    rng = np.random.default_rng(config.seed)
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


def pose_errors_batch(est_world_from_cam: np.ndarray, true_world_from_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation (metres) and rotation (degrees) errors, the paper's delta_t and delta_R.

    Args:
        est_world_from_cam: (N, 4, 4) estimates; a failed query is all-NaN.
        true_world_from_cam: (N, 4, 4) ground truth.

    Returns:
        (N,) ``||t_est - t_true||`` and (N,) ``arccos((tr(R_est^T R_true) - 1) / 2)`` in degrees;
        ``inf`` for failed queries.
    """
    est = np.asarray(est_world_from_cam, dtype=float)
    true = np.asarray(true_world_from_cam, dtype=float)
    failed = ~np.isfinite(est).all(axis=(1, 2))
    t_err = np.linalg.norm(est[:, :3, 3] - true[:, :3, 3], axis=1)
    tr = np.einsum("nij,nij->n", est[:, :3, :3], true[:, :3, :3])  # trace(R_est^T R_true)
    r_err = np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))
    t_err[failed] = np.inf
    r_err[failed] = np.inf
    return t_err, r_err


def hit_mask(t_err: np.ndarray, r_err: np.ndarray, t_max: float, r_max: float) -> np.ndarray:
    """(n,) bool: queries with ``t_err <= t_max`` (metres) AND ``r_err <= r_max`` (degrees).

    Failures (``inf`` or NaN errors) are misses.
    """
    t_err = np.asarray(t_err, dtype=float)
    r_err = np.asarray(r_err, dtype=float)
    if t_err.shape != r_err.shape:
        raise ValueError("t_err and r_err must have the same shape")
    with np.errstate(invalid="ignore"):
        return (t_err <= t_max) & (r_err <= r_max)  # NaN compares False -> miss


def recall(t_err: np.ndarray, r_err: np.ndarray, t_max: float, r_max: float) -> float:
    """Fraction in [0, 1] of queries with ``t_err <= t_max`` AND ``r_err <= r_max`` (inclusive).

    Failures (``inf`` or NaN errors) count as misses. Empty input gives NaN.
    """
    hit = hit_mask(t_err, r_err, t_max, r_max)
    return float(hit.mean()) if hit.size else float("nan")


def recalls(t_err: np.ndarray, r_err: np.ndarray,
            thresholds: Sequence[tuple[float, float]] = THRESHOLDS) -> list[float]:
    """:func:`recall` at each (t_max metres, r_max degrees) threshold."""
    return [recall(t_err, r_err, t, r) for t, r in thresholds]


def threshold_label(threshold: tuple[float, float]) -> str:
    """Human label like ``5cm/5deg`` or ``1m/30deg`` for a (metres, degrees) threshold."""
    t, r = threshold
    dist = f"{t * 100:g}cm" if t < 1.0 else f"{t:g}m"
    return f"{dist}/{r:g}deg"


# --- experiments -------------------------------------------------------------------------------

#: ``--methods`` name of the marker set without markers; every other name is a placement method
#: of :data:`~markerplace.plan.methods.PLACEMENT_METHODS`.
NO_MARKERS = "none"


def method_names() -> tuple[str, ...]:
    """Every name ``--methods`` accepts: ``none``, then the registered placement methods."""
    return (NO_MARKERS, *PLACEMENT_METHODS)


def baseline_methods() -> tuple[str, ...]:
    """The randomized placement methods (``random``, ``uniform``): placed ``--runs`` times each
    and the baselines of the paired comparisons."""
    return tuple(name for name, cls in PLACEMENT_METHODS.items() if cls.randomized)


def marker_set_count(config: EvaluateConfig) -> int:
    """Marker sets with markers that :func:`build_placements` evaluates without ``--placements``
    files: per method, one per k, times ``runs`` for randomized methods (every entry of
    ``config.ks`` counts: an upper bound when ks repeat)."""
    ks = len(config.ks)
    return sum(ks * (config.runs if PLACEMENT_METHODS[m].randomized else 1)
               for m in config.methods if m in PLACEMENT_METHODS)


@dataclass(frozen=True)
class EvaluateConfig:
    """Settings of an ``evaluate`` run (the paper's experiments; defaults as published).

    Attributes:
        tests: test images per test set (paper: 200 room ... 10000 apartment).
        test_sets: ``weighted`` (towards low scores) and/or ``uniform``.
        methods: ``none`` (no markers) and placement methods by name (default: ``none`` and
            every registered method: ``omp``, ``random``, ``uniform``, the paper's comparison).
        runs: placements per randomized method (random, uniform), seeds ``placement_seed + run``.
        ks: marker budgets (OMP is computed once with max k; prefixes are the smaller budgets).
        thresholds: recall thresholds (metres, degrees).
        use_tags: tag detection in the localizer (paper's "marker detection"; off = --no-tags).
        tag_corners: also use the tag corners as 2D-3D correspondences.
        tag_scale: printed tag size = planned size * tag_scale (sensitivity study; the planner's
            marker model still uses the nominal size).
        shift: markers are moved along their wall by +-shift metres, alternating sign with a
            seeded first sign (sensitivity study).
        seed: seed of the localizer's RANSAC, of the VLAD codebook's k-means and, unless
            ``test_seed`` is set, of the test poses and the shift signs.
        test_seed: seed of the test poses and the shift signs alone; None (default) = ``seed``.
        min_clearance: test cameras need this clearance (metres) from non-free cells.
        vlad_clusters: k-means clusters of the VLAD codebook (trained on the no-marker map).
    """

    tests: int = 200
    test_sets: tuple[str, ...] = TEST_SETS
    methods: tuple[str, ...] = field(default_factory=method_names)
    runs: int = 5
    ks: tuple[int, ...] = (5, 10, 15, 20)
    thresholds: tuple[tuple[float, float], ...] = THRESHOLDS
    use_tags: bool = True
    tag_corners: bool = False
    tag_scale: float = 1.0
    shift: float = 0.0
    seed: int = 0
    test_seed: int | None = None
    min_clearance: float = 0.1
    vlad_clusters: int = 64

    @property
    def pose_seed(self) -> int:
        """Seed of the test poses and shift signs: ``test_seed``, else ``seed``."""
        return self.seed if self.test_seed is None else self.test_seed


def validate_evaluate_config(config: EvaluateConfig) -> None:
    """Raise :class:`UserError` (one line) for settings that cannot work."""
    from ..validation import check_evaluate_config

    if not config.test_sets or any(t not in TEST_SETS for t in config.test_sets):
        raise UserError(f"--test-sets {','.join(config.test_sets)!r} is not valid: use a comma list of {', '.join(TEST_SETS)}")
    if any(m not in method_names() for m in config.methods):
        raise UserError(f"--methods {','.join(config.methods)!r} is not valid: use a comma list of {', '.join(method_names())}")
    check_evaluate_config(config)  # numbers: finite and in range (markerplace.validation)


@dataclass(frozen=True, eq=False)
class PlacementRun:
    """One evaluated marker set.

    Attributes:
        method: ``none``, a placement method's name or an extra (``--placements``) name.
        run: run index (0 for deterministic methods).
        k: number of markers (0 for ``none``).
        markers: the markers as drawn in the scene (after tag scale and shift).
    """

    method: str
    run: int
    k: int
    markers: tuple


def shift_markers(markers: Sequence, shift: float, seed: int) -> list:
    """Move marker i along its wall (marker x axis) by ``s_i * shift`` metres, ``s_i = s0 (-1)^i``
    with a seeded random first sign ``s0``; orientation unchanged."""
    from ..markers import Marker

    if shift == 0.0 or not markers:
        return list(markers)
    s0 = 1.0 if np.random.default_rng(seed).random() < 0.5 else -1.0
    out = []
    for i, m in enumerate(markers):
        T = np.array(m.world_from_marker, dtype=float)
        T[:3, 3] += s0 * (-1.0) ** i * shift * T[:3, 0]
        out.append(Marker(m.tag_id, m.size, T, m.family))
    return out


def scale_markers(markers: Sequence, scale: float) -> list:
    """Markers printed ``scale`` times their planned size (same centre and orientation)."""
    from ..markers import Marker

    if scale == 1.0:
        return list(markers)
    return [Marker(m.tag_id, m.size * scale, np.array(m.world_from_marker, float), m.family) for m in markers]


def build_placements(data, placement_config, config: EvaluateConfig,
                     extra: dict[str, Sequence] | None = None) -> list[PlacementRun]:
    """Every marker set to evaluate, in processing order.

    Args:
        data: the planner's :class:`~markerplace.plan.planner.PlanData` (one ``prepare``).
        placement_config: the planner's :class:`~markerplace.plan.planner.PlacementConfig` (v,
            marker model, tag size, similarity, placement seed).
        config: evaluation settings (methods, runs, ks, tag scale, shift).
        extra: method name -> ordered markers (e.g. from ``--placements``); evaluated at each k
            up to their length (prefixes), or at their full length when shorter than every k.

    Methods come in registry order. A ``nested`` method (OMP) is placed once with max k and
    evaluated on prefixes; a ``randomized`` one (random, uniform) draws its own placement for
    every (run, k) with seed ``placement_seed + run``; any other is placed once per k.
    """
    from dataclasses import replace

    from ..plan.planner import place

    ks = sorted(set(config.ks))
    runs: list[PlacementRun] = []

    def add(method, run, k, markers):
        markers = shift_markers(scale_markers(markers, config.tag_scale), config.shift, config.pose_seed)
        runs.append(PlacementRun(method, run, k, tuple(markers)))

    if NO_MARKERS in config.methods:
        runs.append(PlacementRun(NO_MARKERS, 0, 0, ()))
    for method, cls in PLACEMENT_METHODS.items():
        if method not in config.methods:
            continue
        if cls.randomized:
            for run in range(config.runs):
                for k in ks:
                    pl = place(data, replace(placement_config, k=k, method=method, seed=placement_config.seed + run),
                               progress=False)
                    add(method, run, k, pl.markers)
        elif cls.nested:
            pl = place(data, replace(placement_config, k=max(ks), method=method), progress=False)
            for k in ks:
                add(method, 0, k, pl.markers[:k])
        else:
            for k in ks:
                add(method, 0, k, place(data, replace(placement_config, k=k, method=method), progress=False).markers)
    for name, markers in (extra or {}).items():
        fits = [k for k in ks if k <= len(markers)] or [len(markers)]
        for k in fits:
            add(name, 0, k, list(markers)[:k])
    return runs


def find_placement_files(folder: str | Path) -> dict[str, Path]:
    """``placement.json`` (or any ``*.json``) files under ``folder`` -> method name.

    The name is the parent folder for files called ``placement.json`` and the file stem
    otherwise. Raises :class:`UserError` when nothing is found or names clash.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"--placements {folder} is not a directory")
    found: dict[str, Path] = {}
    for path in sorted(folder.rglob("*.json")):
        # evaluate's own outputs and caches are not placements
        if path.name.endswith(".meta.json") or path.name in ("config.json", "timings.json") or "cache" in path.relative_to(folder).parts:
            continue
        name = path.parent.name if path.name == "placement.json" else path.stem
        if name in method_names():
            name = f"{name}-file"
        if name in found:
            raise UserError(f"--placements: two files give the method name {name!r} ({found[name]}, {path}): rename one")
        found[name] = path
    if not found:
        raise UserError(f"--placements {folder} holds no placement.json files: run `markerplace plan` first")
    return found
