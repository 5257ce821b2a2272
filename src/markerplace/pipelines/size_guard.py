"""The run-size guard: estimate a ``plan``/``evaluate`` run before it starts and refuse one too
large for this machine unless ``--force``.

:func:`estimate_run` estimates the camera poses (an upper bound from the model's footprint,
or the exact count of a discretization), the peak memory (bytes) and the wall-clock time
(seconds) of a run from the costs measured on the reference machine (README, Benchmarks; the
module constants); :func:`check_run_size` refuses, with the numbers and the ``--force`` flag, a
run over :class:`SizeLimits` (:class:`~markerplace.errors.UserError`, one line, exit code 2).
The bound is loose for multi-level models whose storeys cover little of the bounding box (a
game level with a deep pit), so a run over the limits by the bound is checked again
with the discretization's exact count (:func:`over_limits` tells when; discretizing takes
seconds) before it is refused, unless it is over by more than :data:`RECOUNT_FACTOR`.

The constants are a first guess only: the cost of a pose varies tenfold between scenes (a
procedural room, 35 ms on one core; a vertex-coloured scan of a million faces, 0.4 s on
llvmpipe). So once the discretization is known, :func:`time_sample` renders and extracts SIFT at
a few of its own poses in this process, and :func:`estimate_plan` turns the measured seconds per
pose, the start-up of a renderer and the features per pose into the time of each stage; that
estimate is what ``plan`` logs and checks (README: within 2x of the measured time on room, house
and a scan-like house, ``benchmarks/run_estimate.py``).
"""

from __future__ import annotations

import logging
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.imaging.engine import EngineSpec, ImagingEngine
from markerplace.imaging.location_views import crop, face_layout, location_groups
from markerplace.plan.discretize.stage import discretize
from markerplace.progress import format_duration
from markerplace.render.renderer import RenderResult
from markerplace.runtime.workers import default_workers
from markerplace.scene.worldframe import points_to_internal, world_offset
from markerplace.settings import OCCUPANCY_CELL
from markerplace.simulation.marker_sets import NO_MARKERS, marker_set_count

log = logging.getLogger(__name__)


SECONDS_PER_POSE_CORE = 0.035
"""Render + SIFT of one 600x450 pose on one core (README, Benchmarks: office, llvmpipe)."""
BYTES_PER_POSE = 0.8e6
"""Peak memory per camera pose of the main process (office: 1.55 GB for 1848 poses)."""
BASE_BYTES = 0.4e9
"""Main process without poses (libraries, scene)."""
BYTES_PER_WORKER = 0.35e9
"""One rendering worker (GL context, scene copy)."""
BYTES_PER_GRID_CELL = 40.0
"""Occupancy grid and its distance transforms per 5 cm cell of the model's bounding box."""
SECONDS_PER_QUERY_CORE = 0.1
"""Localizing one test image on one core (README, Results: room and office evaluations)."""


STOREY_HEIGHT_M = 3.5
"""Height per storey when guessing how many storeys ``--level all`` plans."""
RECOUNT_FACTOR = 10.0
"""A bound over the limits by less than this is checked again with the exact pose count; one
further over is refused at once (wrong units, an absurd grid: discretizing it would be slow)."""
LARGE_FOOTPRINT_M2 = 10_000.0
"""A refused run over this footprint also suggests ``--unit-scale`` (a model in cm looks 10^4 x larger)."""


@dataclass(frozen=True)
class SizeLimits:
    """Largest run started without ``--force``.

    Attributes:
        max_poses: camera poses (estimated upper bound).
        max_hours: estimated wall-clock hours.
        memory_fraction: estimated peak memory as a fraction of the machine's memory.
    """

    max_poses: int = 200_000
    max_hours: float = 12.0
    memory_fraction: float = 0.8


@dataclass(frozen=True)
class RunEstimate:
    """Estimated size of a run (see :func:`estimate_run`).

    Attributes:
        footprint_m2: area where cameras may stand on one storey (bounding box less the
            clearance), m^2.
        poses: camera poses, an upper bound (footprint / grid_spacing^2 x yaws x storeys).
        memory_bytes: peak memory, bytes.
        seconds: wall-clock time on ``workers`` processes.
        workers: rendering processes.
        queries: localized test images (``evaluate``; 0 for ``plan``).
        storeys: storeys the bound assumes.
        exact: ``poses`` is a discretization's count, not the bound.
    """

    footprint_m2: float
    poses: int
    memory_bytes: float
    seconds: float
    workers: int
    queries: int = 0
    storeys: int = 1
    exact: bool = False

    def describe(self) -> str:
        where = f"{self.footprint_m2:.0f} m^2 footprint" + (f" x {self.storeys} storeys" if self.storeys > 1 else "")
        poses = f"{self.poses:,} camera poses (discretized)" if self.exact else f"up to about {self.poses:,} camera poses ({where})"
        text = (f"{poses}, "
                f"{_gib(self.memory_bytes)} of memory and {format_duration(self.seconds)} on {self.workers} worker(s)")
        if self.queries:
            text += f" including {self.queries:,} test-image localizations"
        return text


def _gib(b: float) -> str:
    return f"{b / 2**30:.1f} GiB"


def machine_memory_bytes() -> float:
    """Physical memory of this machine, or the cgroup limit when lower (bytes)."""
    try:
        total = float(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        total = 8 * 2**30
    for limit_file in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(limit_file).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and 0 < int(text) < total:
            total = float(int(text))
    return total


def estimate_run(scene, plan_config, evaluate_config=None, extra_placements: int = 0,
                 poses: int | None = None, seconds_per_pose: float | None = None,
                 candidates: int | None = None) -> RunEstimate:
    """Estimate camera poses, peak memory and wall-clock time of planning (and evaluating) ``scene``.

    Poses: the model's bounding box in x and y, shrunk by the clearance on each side, divided
    by ``grid_spacing^2``, times the yaws, times the storeys planned (``--level N``: one;
    ``--level all``: one per started 3.5 m of height above the first 0.5 m). An upper bound:
    walls and furniture take space.
    Memory and time use the per-pose costs measured on the reference machine (module
    constants). ``evaluate`` adds a map re-render per placement with markers, and one render
    per test image, test set and query condition (``--conditions``) and one localization per
    such image and placement. ``--ceiling`` adds its k picks as placements and, once
    ``candidates`` (the discretization's count) is known, one localization per clean test
    image per candidate (an upper bound: a single tag's run localizes only the images that
    see it; its few map re-renders are not counted). ``poses``: the exact count (from a
    discretization) instead of the bound; ``seconds_per_pose``: a measured cost of one pose on
    one core (:func:`time_sample`) instead of :data:`SECONDS_PER_POSE_CORE`.
    """
    d = plan_config.discretize
    lo, hi = scene.bounds
    w = max(float(hi[0] - lo[0]) - 2 * d.clearance, 0.0)
    h = max(float(hi[1] - lo[1]) - 2 * d.clearance, 0.0)
    footprint = w * h
    locations = (math.floor(w / d.grid_spacing) + 1) * (math.floor(h / d.grid_spacing) + 1) if footprint > 0 else 1
    storeys = 1 if d.level is not None else max(1, math.ceil((float(hi[2] - lo[2]) - 0.5) / STOREY_HEIGHT_M))
    exact = poses is not None
    poses = int(poses) if exact else int(locations * d.num_yaws * storeys)
    workers = default_workers(plan_config.runtime.workers)
    cells = (float(hi[0] - lo[0]) / OCCUPANCY_CELL + 20) * (float(hi[1] - lo[1]) / OCCUPANCY_CELL + 20)
    memory = BASE_BYTES + workers * BYTES_PER_WORKER + poses * BYTES_PER_POSE + cells * BYTES_PER_GRID_CELL
    per_pose = SECONDS_PER_POSE_CORE if seconds_per_pose is None else float(seconds_per_pose)
    core_seconds = poses * per_pose
    queries = 0
    if evaluate_config is not None:
        ceiling = evaluate_config.diagnostics.ceiling
        with_markers = marker_set_count(evaluate_config) + extra_placements \
            + (len(evaluate_config.study.ks) if ceiling else 0)
        placements = with_markers + (1 if NO_MARKERS in evaluate_config.study.methods else 0)
        clean_images = evaluate_config.test.tests * len(evaluate_config.test.sets)
        images = clean_images * len(evaluate_config.test.conditions)
        queries = images * placements + (clean_images * candidates if ceiling and candidates else 0)
        core_seconds += with_markers * poses * per_pose + queries * SECONDS_PER_QUERY_CORE + images * per_pose
    return RunEstimate(footprint, poses, memory, core_seconds / workers, workers, queries, storeys, exact)


SAMPLE_POSES = 16
"""Poses :func:`time_sample` renders (the first one, which warms up SIFT and the GL driver, is not
timed)."""
PARALLEL_EFFICIENCY = 0.85
"""Speed-up of W feature-extracting processes over one, per process."""
SIMILARITY_EXACT_S_PER_PAIR = 5e-9
"""Exact look-alike search, seconds per pair of points (2 cores; room: 23k points in 2.3 s)."""
SIMILARITY_IVF_S_PER_POINT = 1.5e-4
"""Inverted-file look-alike search, seconds per point (2 cores: 0.7e-4 on house's 166k points,
1.9e-4 on the scan-like house's 86k real-texture points)."""
OUTPUT_SECONDS = 3.0
"""Writing the plan's files and report, besides the installer views."""
VIEWS_PER_TAG = 3
"""Renders per placed tag for the report's installer views."""


@dataclass(frozen=True)
class PoseSample:
    """What a few real poses of the scene cost here (see :func:`time_sample`).

    Attributes:
        render_seconds: rendering one pose (llvmpipe spreads it over the cores itself, so
            rendering workers share that throughput rather than add to it), seconds.
        feature_seconds: SIFT and the 3D lift of one pose on one core (this scales with the
            workers), seconds.
        setup_seconds: loading the scene and starting a renderer (each worker pays it once).
        features_per_pose: SIFT features with a 3D point per pose (the look-alike search's input).
        poses: poses timed.
    """

    render_seconds: float
    feature_seconds: float
    setup_seconds: float
    features_per_pose: float
    poses: int

    @property
    def seconds_per_pose(self) -> float:
        """Render + features of one pose, seconds."""
        return self.render_seconds + self.feature_seconds


def time_sample(scene_spec, world_from_cam, imaging_config, n: int = SAMPLE_POSES, map_sift=None) -> PoseSample:
    """Render and extract features at ``n`` poses spread over ``world_from_cam`` ((N, 4, 4)) in
    this process, as a worker of the observe stage does (OpenCV on one thread), and time it;
    with ``map_sift`` (a SIFT preset), the testbed's map features (that preset and the tags)
    too, as observe extracts them for ``plan --with-map``. With ``observe_views`` other than
    ``pose``, the sampled poses are rendered as faces (:mod:`markerplace.imaging.location_views`)
    and a pose is charged half a face render and SIFT of its crop (``location-renders``; the
    resampling is not timed) or of half a face (``location-features``)."""
    import cv2


    poses = np.asarray(world_from_cam, float).reshape(-1, 4, 4)
    pick = np.unique(np.linspace(0, len(poses) - 1, max(2, n)).round().astype(int)) if len(poses) else []
    layout = None
    if imaging_config.observe_views != "pose" and map_sift is None and len(poses):
        layout = face_layout(poses, location_groups(poses), imaging_config.camera)
    # with faces, a pose costs half a face render, and SIFT of half a face or of its own image
    share = layout is not None and imaging_config.observe_views == "location-features"
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    t0 = time.perf_counter()
    engine = ImagingEngine(EngineSpec(scene_spec, imaging_config if layout is None else layout.face_config(imaging_config), {}))
    try:
        setup = time.perf_counter() - t0
        render, feature, feats = [], [], []
        for i in pick:
            t1 = time.perf_counter()
            res = engine.render(poses[i])
            if layout is not None and not share:
                res = RenderResult(crop(layout, res.rgb), crop(layout, res.depth), None, res.world_from_cam)
            t2 = time.perf_counter()
            f = engine.features(res, K=None if layout is None or share else layout.camera.K).with_3d_only()
            if map_sift is not None:
                engine.features(res, tags=True, sift=map_sift)
            render.append((t2 - t1) / (1 if layout is None else 2))
            feature.append((time.perf_counter() - t2) / (2 if share else 1))
            feats.append(len(f.keypoints) * (layout.camera.width * layout.camera.height
                                             / (layout.face.width * layout.face.height) if share else 1))
    finally:
        engine.close()
        cv2.setNumThreads(threads)
    if len(render) > 1:  # the first pose warms up SIFT and the GL driver
        render, feature = render[1:], feature[1:]
    if not render:
        return PoseSample(SECONDS_PER_POSE_CORE / 2, SECONDS_PER_POSE_CORE / 2, setup, 0.0, 0)
    return PoseSample(float(np.mean(render)), float(np.mean(feature)), setup, float(np.mean(feats)), len(render))


def estimate_plan(sample: PoseSample, poses: int, workers: int, similarity_config, k: int,
                  similarity: bool = True) -> dict[str, float]:
    """Seconds of the remaining stages of a plan from a :class:`PoseSample`: ``observe`` (every
    worker starts a renderer; renders share the machine's llvmpipe throughput, features run on
    ``workers`` processes), ``similarity`` (exact or inverted-file search on the expected
    points, as :func:`markerplace.plan.similarity.stage.count_similar` picks), ``outputs`` (files,
    report, installer views) and ``total``."""
    eff = max(1.0, workers * PARALLEL_EFFICIENCY) if workers > 1 else 1.0
    observe = sample.setup_seconds + poses * (sample.render_seconds + sample.feature_seconds / eff)
    points = poses * sample.features_per_pose
    if not similarity:
        sim = 0.0
    elif points <= similarity_config.exact_max_points and similarity_config.method != "ivf":
        sim = SIMILARITY_EXACT_S_PER_PAIR * points ** 2
    else:
        sim = SIMILARITY_IVF_S_PER_POINT * points
    outputs = OUTPUT_SECONDS + k * VIEWS_PER_TAG * sample.seconds_per_pose
    return {"observe": observe, "similarity": sim, "outputs": outputs, "total": observe + sim + outputs}


def measured_size_check(scene, scene_spec, plan_config, k: int, force: bool = False, evaluate_config=None,
                        extra_placements: int = 0, map_sift=None):
    """The check ``prepare`` runs once the discretization is known and before it renders: a
    :func:`time_sample` of the scene's own poses (``map_sift``: with the map features observe
    also extracts), the stage times of :func:`estimate_plan` (plus the evaluation's, for
    ``evaluate``) logged, and :func:`check_run_size` on them. Returns the callable ``check(disc)``."""
    def check(disc) -> None:
        N = len(disc.world_from_cam)
        sample = time_sample(scene_spec, disc.world_from_cam, plan_config.imaging, map_sift=map_sift)
        workers = default_workers(plan_config.runtime.workers)
        tags = min(k, len(disc.candidate_world_from_marker))  # a --target-recall plan's k is only a bound
        stages = estimate_plan(sample, N, workers, plan_config.similarity, tags, plan_config.placement.similarity)
        estimate = estimate_run(scene, plan_config, evaluate_config, extra_placements, poses=N,
                                seconds_per_pose=sample.seconds_per_pose,
                                candidates=len(disc.candidate_world_from_marker))
        evaluation = 0.0
        if evaluate_config is not None:
            evaluation = estimate.seconds - estimate_run(scene, plan_config, None, 0, poses=N,
                                                         seconds_per_pose=sample.seconds_per_pose).seconds
        elapsed = _seconds_since_start()
        estimate = replace(estimate, seconds=elapsed + stages["total"] + evaluation)
        log.info("run size: %d poses; %d of them here took %.0f ms each to render and extract features (%.1f s to "
                 "start a renderer), so about "
                 "%s to render and extract features, %s for the look-alikes (%d points), %s for the outputs%s; "
                 "with the %s so far, about %s in all on %d worker(s) and %s of memory", N, sample.poses,
                 1000 * sample.seconds_per_pose, sample.setup_seconds, format_duration(stages["observe"]),
                 format_duration(stages["similarity"]), int(N * sample.features_per_pose),
                 format_duration(stages["outputs"]), f", {format_duration(evaluation)} to evaluate" if evaluation else "",
                 format_duration(elapsed), format_duration(estimate.seconds), workers, _gib(estimate.memory_bytes))
        check_run_size(estimate, force=force, log_ok=False)

    return check


def over_limits(estimate: RunEstimate, limits: SizeLimits = SizeLimits(),
                memory_bytes: float | None = None, factor: float = 1.0) -> list[str]:
    """Why ``estimate`` is over ``factor`` times ``limits`` (empty when it is not), e.g. "longer
    than 12 h"."""
    total = machine_memory_bytes() if memory_bytes is None else memory_bytes
    limits = SizeLimits(int(limits.max_poses * factor), limits.max_hours * factor, limits.memory_fraction * factor)
    reasons = []
    if estimate.poses > limits.max_poses:
        reasons.append(f"more than {limits.max_poses:,} poses")
    if estimate.memory_bytes > limits.memory_fraction * total:
        reasons.append(f"more memory than this machine has ({_gib(total)})")
    if estimate.seconds > limits.max_hours * 3600:
        reasons.append(f"longer than {limits.max_hours:g} h")
    return reasons


def _seconds_since_start() -> float:
    """Wall seconds since this process started (imports included)."""
    import psutil

    try:
        return max(0.0, time.time() - psutil.Process().create_time())
    except psutil.Error:
        return 0.0


def check_run_size(estimate: RunEstimate, force: bool = False, limits: SizeLimits = SizeLimits(),
                   memory_bytes: float | None = None, log_ok: bool = True, what: str = "run size") -> None:
    """Refuse a run over ``limits`` (unless ``force``), naming the numbers and the flag; a run
    within them is logged as ``what: ...`` unless ``log_ok`` is False.

    Raises:
        UserError: estimated poses over ``max_poses``, time over ``max_hours`` or memory over
            ``memory_fraction`` of ``memory_bytes`` (default: :func:`machine_memory_bytes`).
    """
    reasons = over_limits(estimate, limits, memory_bytes)
    if not reasons:
        if log_ok:
            log.info("%s: %s", what, estimate.describe())
        return
    if force:
        log.warning("run size: %s (%s); going on because of --force", estimate.describe(), " and ".join(reasons))
        return
    units = ("; if the model is not in metres, pass --unit-scale (e.g. 0.01 for cm)"
             if estimate.footprint_m2 > LARGE_FOOTPRINT_M2 else "")
    raise UserError(f"this run needs {estimate.describe()}: {' and '.join(reasons)}; increase --grid-spacing or "
                    f"reduce --yaws (or --tests/--runs/--k), or pass --force to run it anyway{units}")


def check_first_guess(config, scene, force: bool, evaluate_config=None, extra_placements: int = 0):
    """The run-size guard's first guess, before discretizing (:func:`check_run_size`; ``force``
    = ``--force``); returns ``config`` with ``--start`` moved into the scene's internal frame
    (:mod:`markerplace.scene.worldframe`)."""
    offset = world_offset(scene)
    if config.discretize.start is not None and offset.any():
        start = tuple(float(v) for v in points_to_internal(config.discretize.start, offset))
        config = replace(config, discretize=replace(config.discretize, start=start))
    estimate = estimate_run(scene, config, evaluate_config, extra_placements)
    if over_limits(estimate) and not over_limits(estimate, factor=RECOUNT_FACTOR) and not force:
        # the bound is loose (multi-level models): count the poses (seconds)
        log.info("run size: %s by the bounding box; counting the camera poses", estimate.describe())
        poses = len(discretize(scene, config.discretize, config.placement.tag_size).world_from_cam)
        estimate = estimate_run(scene, config, evaluate_config, extra_placements, poses=poses)
    check_run_size(estimate, force=force, what="run size, a first guess before discretizing")
    return config
