"""The OMP planning pipeline: discretize -> observe -> similarity -> score -> place.

Each stage's artifact lives in the run directory with a hash of the inputs it came from
(:mod:`markerplace.runtime.cache`), so re-running ``plan`` with a different k, method or v reuses the
expensive stages (rendering, SIFT, similarity) and only re-runs placement. A stage's key holds
the digest of the artifact it was computed from (observe: ``discretization.npz``; similarity:
``observations/``), so a recomputed or repaired upstream artifact invalidates what follows.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import FeatureSet
from markerplace.runtime.atomic_io import write_npz
from markerplace.markers import DEFAULT_TAG_SIZE, FAMILY, Marker
from markerplace.runtime import cache, run_folder
from markerplace.runtime.executor import RuntimeConfig, make_executor
from markerplace.runtime.stages import cached
from markerplace.tagfamily import DRAWING_VERSION
from markerplace.scene.spec import SceneSpec
from markerplace.settings import SEED_MAX, setting
from markerplace.plan.discretize.artifact import Discretization
from markerplace.plan.discretize.artifact import load as load_discretization
from markerplace.plan.discretize.artifact import save as save_discretization
from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
from markerplace.plan.score.localizability import (
    NoiseConfig,
    entropy,
    information_gain,
    marker_visibility,
    pose_information,
)
from markerplace.plan.observe import observe
from markerplace.plan.score.marker_models import MARKER_MODELS, get_marker_model
from markerplace.plan.place.methods import CALIBRATION_POSES, PLACEMENT_METHODS, method_from_config
from markerplace.plan.place.greedy import MarkerCoverage, apply_coverages, check_k
from markerplace.plan.similarity.stage import SimilarityConfig, count_similar

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlacementConfig:
    """How markers are chosen.

    Attributes:
        k: number of markers to place.
        method: a name in :data:`~markerplace.plan.place.methods.PLACEMENT_METHODS`: ``omp`` (the
            paper's greedy), ``random`` (seeded uniform sample of candidates) or ``uniform``
            (evenly spaced along the free-space perimeter).
        v: OMP hyper-parameter in [0, 100]: the most visible v percent of candidates compete.
        marker_model: a name in :data:`~markerplace.plan.score.marker_models.MARKER_MODELS`:
            ``paper`` (relative-pose factor, as published) or ``corners`` (projected tag
            corners; depends on distance, viewing angle and tag size).
        tag_size: black-square edge of the printed tags, metres: the one home of the tag size
            (the discretization's fit check, the scoring and the placed markers use it).
        similarity: down-weight look-alike points (the paper's similarity analysis).
        lazy: lazy greedy (exactly the same picks as plain greedy, far fewer evaluations).
        seed: seed of the randomized methods (random and uniform).
        first_tag_id: tag id of the first placed marker; ids count up in placement order,
            skipping ids of existing markers.
        calibration_poses: images ``expected-recall`` fits its success model on (map images
            only, never test images): ``map`` (the map images, each localized against the map
            without its own location) or ``offgrid`` (renders at test-like poses, map poses
            perturbed within a grid cell and +-22.5 deg of yaw, localized against the whole
            map; :mod:`markerplace.testbed.calibration`).
    """

    k: int = setting(20, flag="-k", bounds=(1, 10_000), commands=("plan",), help="number of markers to place",
                     doc="number of markers", hint="the number of markers to place, e.g. 20")
    method: str = setting("omp", flag="--method", choices=lambda: PLACEMENT_METHODS.names(), commands=("plan",),
                          help=lambda: f"placement method: {PLACEMENT_METHODS.help()}",
                          doc=lambda: "a registered placement method: " + ", ".join(
                              f"`{n}`" + (f" ({c.summary})" if getattr(c, "summary", "") else "")
                              for n, c in PLACEMENT_METHODS.items()))
    v: float = setting(90.0, flag="-v", bounds=(0.0, 100.0), units="%", hint="a percentage such as 90",
                       help="OMP percentile parameter v in [0, 100]: the most visible v % of candidates compete "
                            "(q is derived from v as in the paper)")
    marker_model: str = setting("paper", flag="--marker-model", choices=lambda: MARKER_MODELS.names(),
                                help=lambda: f"marker information model: {MARKER_MODELS.help()}")
    tag_size: float = setting(DEFAULT_TAG_SIZE, flag="--tag-size", bounds=(0.02, 3.0), units="m",
                              hint="the black-square edge in metres, e.g. 0.4",
                              help="black-square edge of the printed tags, metres; the one tag size (the "
                                   "discretization's fit check uses it too)")
    similarity: bool = setting(True, flag="--no-similarity", const=False,
                               help="turn the look-alike (similarity) analysis off (no down-weighting of repeated "
                                    "features)")
    lazy: bool = True
    seed: int = setting(0, flag="--placement-seed", bounds=(0, SEED_MAX), hint=f"a seed in 0..{SEED_MAX}, e.g. 0",
                        help=lambda: "seed of the " + "/".join(n for n, c in PLACEMENT_METHODS.items() if c.randomized)
                        + " placements")
    first_tag_id: int = 0
    calibration_poses: str = setting("map", flag="--calibration-poses", choices=lambda: CALIBRATION_POSES,
                                     help="images expected-recall fits its success model on: map (the map images, "
                                          "each without its own location) or offgrid (1000 test-like renders "
                                          "between the map poses, never test images)")


@dataclass(frozen=True)
class PlanConfig:
    """Every setting of a plan run, saved resolved as ``config.json`` in the run directory
    (``plan --config`` reads it back, or a TOML file with the same tables:
    :mod:`markerplace.config_file`).

    ``runtime`` (where the per-image work runs) changes speed, never results: it is left out of
    every cache key. The tag size lives in ``placement`` alone; the discretization gets it as
    an argument.
    """

    discretize: DiscretizeConfig = field(default_factory=DiscretizeConfig)
    imaging: ImagingConfig = field(default_factory=ImagingConfig)
    similarity: SimilarityConfig = field(default_factory=SimilarityConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    runtime: RuntimeConfig = field(default_factory=RuntimeConfig)


@dataclass(frozen=True, eq=False)
class PlanData:
    """Everything placement needs, computed once per scene and discretization.

    Attributes:
        disc: the discretization (poses, candidates, occupancy).
        base_info: (N, 6, 6) information per pose from scene features only.
        base_score: (N,) localizability score -entropy without markers.
        coverages: one :class:`MarkerCoverage` per candidate (poses that see it and the
            information it adds there), then one per existing marker.
        num_candidates: C (coverages[C:] belong to existing markers).
        timings: seconds per stage.
        points_world: (K, 3) float32 world metres of the map images' SIFT keypoints (NaN: no 3D
            point), or None; for methods that look at the scene's texture (``human``).
        pose_index: (K,) int32 camera pose of each keypoint, or None.
        visible: (N, C + E) bool: the pose sees the marker (geometry and occlusion), candidates
            then existing markers, or None; with ``marker_poses`` (C + E, 4, 4) and
            ``marker_sizes`` (C + E,) metres it rebuilds the coverages under another marker
            model (:func:`coverages_with_model`).
        calibration: what a calibrated method needs, filled by
            :func:`markerplace.testbed.calibration.calibrate_plan` (e.g. the fitted
            :class:`~markerplace.plan.score.success_model.SuccessModel` of ``expected-recall``).
    """

    disc: Discretization
    base_info: np.ndarray
    base_score: np.ndarray
    coverages: list
    num_candidates: int
    timings: dict
    points_world: np.ndarray | None = None
    pose_index: np.ndarray | None = None
    visible: np.ndarray | None = None
    marker_poses: np.ndarray | None = None
    marker_sizes: np.ndarray | None = None
    calibration: dict = field(default_factory=dict)


def validate(config: PlanConfig) -> None:
    """Raise :class:`UserError` for settings that cannot work."""
    p = config.placement
    PLACEMENT_METHODS.lookup(p.method)  # UserError naming the known ones
    MARKER_MODELS.lookup(p.marker_model)
    if p.calibration_poses not in CALIBRATION_POSES:
        raise UserError(f"--calibration-poses {p.calibration_poses!r} is not one of {', '.join(CALIBRATION_POSES)}")
    from markerplace.validation import check_plan_config

    check_plan_config(config)  # every numeric setting: finite and in range (markerplace.validation)


def geometric_visibility(world_from_cam: np.ndarray, world_from_markers: np.ndarray, config: PlanConfig) -> np.ndarray:
    """(N, C) bool: range, field of view and viewing angle (no occlusion) for each marker pose."""
    intr = config.imaging.camera
    out = np.zeros((len(world_from_cam), len(world_from_markers)), dtype=bool)
    for c, T in enumerate(world_from_markers):
        out[:, c] = marker_visibility(world_from_cam, T, intr.K, (intr.width, intr.height), max_range=config.noise.max_range)
    return out


def build_coverages(world_from_cam: np.ndarray, world_from_markers: np.ndarray, sizes: Sequence[float],
                    visible: np.ndarray, config: PlanConfig) -> list:
    """One :class:`MarkerCoverage` per marker pose from the (N, C) visibility mask, with the
    information of ``config.placement.marker_model`` (:mod:`markerplace.plan.score.marker_models`)."""
    model = get_marker_model(config.placement.marker_model, noise=config.noise)
    K = config.imaging.camera.K
    covs = []
    for c, T in enumerate(world_from_markers):
        idx = np.flatnonzero(visible[:, c])
        info = model.information(world_from_cam[idx], T, sizes[c], K) if len(idx) else np.zeros((0, 6, 6))
        covs.append(MarkerCoverage(pose_idx=idx.astype(np.int64), info=info))
    return covs


def prepare(scene_spec: SceneSpec, config: PlanConfig, run_dir: str | Path,
            existing: Sequence[Marker] = (), progress: bool = True, executor=None, k: int | None = None,
            before_observe: Callable[[Discretization], None] | None = None) -> PlanData:
    """Run (or reuse) discretize, observe, similarity and scoring for a scene.

    Args:
        scene_spec: the scene to plan in.
        config: all settings.
        run_dir: directory for artifacts (created): ``discretization.npz``, ``observations/``
            (a feature folder), ``similarity.npz``, each with its ``.meta.json``.
        existing: markers already on the walls; they count as placed.
        progress: progress bars on long stages.
        executor: where per-pose work runs (default: one made from ``config.runtime`` for
            this call).
        k: the most markers the caller will place: refused (:func:`check_k`) right after
            discretize when the candidates are fewer, before rendering and the look-alike
            search (None: not checked here).
        before_observe: called with the discretization when the observe stage must run (not
            when its artifact is reused), before anything renders: the run-size check of
            :func:`markerplace.pipelines.size_guard.measured_size_check`.
    """
    run_dir = Path(run_dir)
    run_folder.make_dirs(run_dir)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    scene = scene_spec.load()
    timings["load"] = time.perf_counter() - t0

    # the parts' names and glass decide which wall spots may carry a tag (plan.wall_candidates)
    labels = [(p.name, tuple(p.names), bool(p.transparent)) for p in scene.parts]
    disc_key = cache.hash_of("discretize-v4", cache.scene_hash(scene), labels,
                             config.discretize.cache_view(config.placement.tag_size))
    disc = cached("discretize", run_dir / "discretization.npz", disc_key,
                  lambda: discretize(scene, config.discretize, config.placement.tag_size),
                  save_discretization, load_discretization, timings)
    N, C = len(disc.world_from_cam), len(disc.candidate_world_from_marker)
    log.info("discretize: %d camera locations x %d yaws = %d poses, %d candidate marker poses",
             len(disc.locations), config.discretize.num_yaws, N, C)
    if k is not None:
        check_k(k, C)  # now, not after rendering and the look-alike search

    existing_T = np.array([m.world_from_marker for m in existing]).reshape(-1, 4, 4)
    all_T = np.concatenate([disc.candidate_world_from_marker, existing_T])
    sizes = [config.placement.tag_size] * C + [m.size for m in existing]
    in_view = geometric_visibility(disc.world_from_cam, all_T, config)

    obs_key = cache.hash_of("observe-v3", DRAWING_VERSION, disc_key, cache.content_digest(run_dir / "discretization.npz"),
                            config.imaging, all_T, sizes)

    def run_observe() -> FeatureSet:
        log.info("observe: rendering and extracting SIFT at %d poses", N)
        own = executor is None
        ex = make_executor(config.runtime) if own else executor
        try:
            return observe(scene_spec, disc.world_from_cam, in_view, all_T, np.asarray(sizes, float), config.imaging,
                           ex, run_dir / "observations", obs_key, progress=progress)
        finally:
            if own:
                ex.close()

    if before_observe is not None and not cache.is_fresh(run_dir / "observations", obs_key):
        before_observe(disc)
    obs = cached("observe", run_dir / "observations", obs_key, run_observe, None, FeatureSet.load, timings)
    points, descriptors, pose_index = obs.points_world, obs.descriptors, obs.image_index
    log.info("observe: %d features with 3D points (%.0f per pose)", len(pose_index), len(pose_index) / max(N, 1))

    if config.placement.similarity:
        sim_key = cache.hash_of("similarity-v3", obs_key, cache.content_digest(run_dir / "observations"),
                                config.similarity)
        n_similar = cached("similarity", run_dir / "similarity.npz", sim_key,
                           lambda: count_similar(descriptors, points, config.similarity, progress=progress),
                           lambda n, path: write_npz(path, n_similar=n),
                           lambda path: np.load(path, allow_pickle=False)["n_similar"], timings)
    else:
        n_similar = np.zeros(len(pose_index), dtype=np.int32)
        timings["similarity"] = 0.0

    t0 = time.perf_counter()
    base_info = pose_information(disc.world_from_cam, config.imaging.camera.K, np.asarray(points, float), pose_index,
                                 n_similar, config.noise)
    base_score = -entropy(base_info)
    visible = in_view & np.asarray(obs.extras["candidate_unoccluded"])
    # a tag that no camera pose sees helps nobody: never offer it to any method
    seen = visible[:, :C].any(axis=0)
    if not seen.all():
        log.info("plan: %d of %d candidates are seen by no camera pose (hidden behind furniture, beyond every "
                 "view or on walls no camera faces); removed", int((~seen).sum()), C)
        keep = np.r_[seen, np.ones(len(existing_T), bool)]
        disc = disc.with_candidates(seen)
        all_T, sizes, visible = all_T[keep], [v for v, k in zip(sizes, keep) if k], visible[:, keep]
        C = int(seen.sum())
    removed = {**disc.summary.get("candidates_removed", {}), "not seen": int((~seen).sum())}
    disc = replace(disc, summary={**disc.summary, "candidates_removed": removed})
    coverages = build_coverages(disc.world_from_cam, all_T, sizes, visible, config)
    timings["score"] = time.perf_counter() - t0
    return PlanData(disc, base_info, base_score, coverages, C, timings, np.asarray(points), pose_index,
                    visible, all_T, np.asarray(sizes, float))


def coverages_with_model(data: PlanData, config: PlanConfig, marker_model: str) -> list:
    """``data.coverages`` (candidates, then existing markers) with the information of another
    registered marker model (the same poses see each marker)."""
    if marker_model == config.placement.marker_model:
        return data.coverages
    cfg = replace(config, placement=replace(config.placement, marker_model=marker_model))
    return build_coverages(data.disc.world_from_cam, data.marker_poses, list(data.marker_sizes), data.visible, cfg)


@dataclass(frozen=True, eq=False)
class Placement:
    """A chosen set of markers.

    Attributes:
        candidates: (k,) candidate indices in placement order.
        gains: (k,) localizability gain of each pick when it was chosen (OMP; NaN otherwise).
        markers: the markers, with tag ids.
        info_after: (N, 6, 6) information per pose with existing + placed markers.
        q: OMP percentile used (NaN for baselines).
    """

    candidates: np.ndarray
    gains: np.ndarray
    markers: list
    info_after: np.ndarray
    q: float


def place(data: PlanData, config: PlacementConfig, existing: Sequence[Marker] = (), progress: bool = True) -> Placement:
    """Choose ``config.k`` markers among the candidates with the method ``config.method``
    (:func:`~markerplace.plan.place.methods.method_from_config`), seeded with ``config.seed``.

    With ``progress``, each OMP pick is logged (candidate, gain) as it is made.
    """
    check_k(config.k, data.num_candidates)
    choice = method_from_config(config).place(data, config.k, seed=config.seed, progress=progress)
    order = np.asarray(choice.order, dtype=np.int64)
    used = {m.tag_id for m in existing}
    markers, tag_id = [], config.first_tag_id
    for c in order:
        while tag_id in used:
            tag_id += 1
        markers.append(Marker(tag_id, config.tag_size, data.disc.candidate_world_from_marker[c].copy(), FAMILY))
        used.add(tag_id)
    return Placement(order, np.asarray(choice.gains, dtype=float), markers, choice.info_after, float(choice.q))


def first_pick_gain(data: PlanData, placement: Placement) -> np.ndarray:
    """(N,) information gain of the first placed marker at every pose (0 where not seen),
    given the existing markers (the paper's Fig. 5(c))."""
    existing_info = apply_coverages(data.base_info, data.coverages[data.num_candidates:])
    gain = np.zeros(len(data.base_info))
    if len(placement.candidates):
        cov = data.coverages[int(placement.candidates[0])]
        if len(cov.pose_idx):
            gain[cov.pose_idx] = information_gain(existing_info[cov.pose_idx], cov.info)
    return gain
