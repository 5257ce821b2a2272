"""``markerplace plan`` as a chain of named stages, read top to bottom.

:func:`prepare` is the part every command shares (``plan``, ``evaluate``, ``check``,
``study``): discretize -> observe -> look-alikes -> score, each cached in the run folder under
the hash of its inputs (:mod:`markerplace.runtime.stages`), so a re-run with another k, method
or v reuses them. :func:`run_plan` adds the rest of a plan: the run-size check, calibration (for
calibrated methods), the user's exclusions, placement and the deliverables.

Frames: everything here is in the scene's internal frame; user inputs (``--existing``,
``--exclude``, ``--start``) are moved in and outputs moved back out
(:mod:`markerplace.scene.worldframe`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from markerplace.markers import Marker, check_markers_on_walls, check_tag_budget, load_markers
from markerplace.pipelines.size_guard import check_first_guess, measured_size_check
from markerplace.plan.config import PlanConfig, validate, warn_unused_settings
from markerplace.plan.discretize.artifact import Discretization
from markerplace.plan.discretize.exclusion import apply_exclusion, describe_changes, load_exclusion, placement_changes, previous_markers
from markerplace.plan.discretize.stage import run_discretize
from markerplace.plan.observe import run_observe
from markerplace.plan.place.greedy import check_k
from markerplace.plan.place.predicted_recall import model_methods, place_for_target, predicted_recall, score_bound, wants_success_model
from markerplace.plan.place.stage import first_pick_gain, place
from markerplace.plan.score.stage import geometric_visibility, score_poses
from markerplace.plan.similarity.stage import run_similarity
from markerplace.plan.types import PlanData
from markerplace.plan.where import Where, disc_pose_weights, load_where
from markerplace.report.output_files import output_file_patterns
from markerplace.report.plan_outputs import write_plan_outputs
from markerplace.report.plan_report import write_plan_report
from markerplace.report.tagmaps.write import tag_map_patterns
from markerplace.runtime import run_folder
from markerplace.runtime.claims import refuse_foreign
from markerplace.runtime.cluster import check_scheduler
from markerplace.runtime.executor import make_executor
from markerplace.scene.spec import SceneSpec
from markerplace.scene.worldframe import markers_to_internal, world_offset
from markerplace.simulation.map_setup import observed_map_output, testbed_imaging_config
from markerplace.simulation.success_fit import calibrate_plan

log = logging.getLogger(__name__)

__all__ = ["PlanInputs", "PlanResult", "prepare", "run_plan", "PLAN_OUTPUTS", "plan_outputs"]

PLAN_OUTPUTS = ("discretization.npz", "discretization.npz.meta.json", "observations/*.npy", "observations.meta.json",
                "similarity.npz", "similarity.npz.meta.json", "calibration/", "success_model_*.json*",
                "placement.json", "placement.csv", "tags/*_tag*.svg", "tags.pdf", "scores.npz", "config.json",
                "scores.png", "gain_first.png", "placement.png", "where.png", "report.html", *tag_map_patterns())
"""What ``plan`` writes into its folder (``fnmatch`` patterns; ``/``: a folder), checked in an
adopted folder before any work (:func:`markerplace.runtime.claims.refuse_foreign`); with the
registered parts' files: :func:`plan_outputs`."""


def plan_outputs() -> tuple[str, ...]:
    """:data:`PLAN_OUTPUTS` with the files of the tag-map formats and output files registered now
    (:mod:`markerplace.report.output_files`)."""
    return tuple(dict.fromkeys((*PLAN_OUTPUTS, *tag_map_patterns(), *output_file_patterns())))


def prepare(scene_spec: SceneSpec, config: PlanConfig, run_dir: str | Path, existing: Sequence[Marker] = (),
            progress: bool = True, executor=None, k: int | None = None,
            before_observe: Callable[[Discretization], None] | None = None, where: Where | None = None,
            map_cache: str | Path | None = None, map_imaging=None) -> PlanData:
    """Discretize, observe, count look-alikes and score (each reused from ``run_dir`` when fresh).

    Args:
        scene_spec: the scene to plan in.
        config: all settings (internal frame).
        run_dir: folder of the stages' artifacts (created): ``discretization.npz``,
            ``observations/``, ``similarity.npz``, each with its ``.meta.json``.
        existing: markers already on the walls (internal frame); they count as placed.
        executor: where per-pose work runs (None: one made from ``config.runtime`` if needed).
        k: the most markers the caller will place: refused right after discretize when the
            candidates are fewer, before anything renders (None: not checked here).
        before_observe: called with the discretization when observe must run, before it
            renders (the run-size check of :func:`~markerplace.pipelines.size_guard.measured_size_check`).
        where: the ``--where`` file (:mod:`markerplace.plan.where`, user frame): the returned
            data's ``pose_weight``, computed (and a file that holds no pose refused) right after
            discretize, before anything renders. No cached stage depends on it.
        map_cache: a testbed cache folder (:mod:`markerplace.simulation.map_setup`): when observe
            runs, its renders also give the testbed's marker-free map features there, so the
            map is not rendered again (None: not).
        map_imaging: the testbed's imaging settings (None: the plan's camera, OpenCV SIFT).
    """
    run_dir = Path(run_dir)
    run_folder.make_dirs(run_dir)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    scene = scene_spec.load()
    timings["load"] = time.perf_counter() - t0
    disc, disc_key = run_discretize(scene, config.discretize, config.placement.tag_size, run_dir, timings)
    if k is not None:
        check_k(k, len(disc.candidate_world_from_marker))
    weights = None if where is None else disc_pose_weights(where, disc, world_offset(scene))
    marker_poses = np.concatenate([disc.candidate_world_from_marker,
                                   np.array([m.world_from_marker for m in existing]).reshape(-1, 4, 4)])
    sizes = [config.placement.tag_size] * len(disc.candidate_world_from_marker) + [m.size for m in existing]
    in_view = geometric_visibility(disc.world_from_cam, marker_poses, config.imaging.camera, config.noise.max_range)
    map_output = None if map_cache is None else observed_map_output(scene, disc.world_from_cam, map_cache, config,
                                                                    map_imaging)
    obs, obs_key = run_observe(scene_spec, disc.world_from_cam, disc_key, marker_poses, sizes, in_view,
                               config.imaging, run_dir, executor, config.runtime, timings, progress,
                               before=None if before_observe is None else lambda: before_observe(disc),
                               map_output=map_output)
    n_similar = run_similarity(obs.descriptors, obs.points_world, obs_key, run_dir, config.similarity,
                               config.placement.similarity, timings, progress)
    data = score_poses(disc, obs, n_similar, marker_poses, sizes, in_view, len(existing),
                       config.placement.marker_model, config.noise, config.imaging.camera.K, timings)
    return data if weights is None else replace(data, pose_weight=weights)


@dataclass(frozen=True)
class PlanInputs:
    """What a plan run reads or obeys besides its settings.

    Attributes:
        existing: ``--existing`` file of tags already on the walls (user frame), or None.
        exclude: ``--exclude`` file of spots where no tag may go, or None.
        where: ``--where`` file of the places and directions of use (:mod:`markerplace.plan.where`),
            or None (every camera pose weighs the same).
        paper: paper of ``tags.pdf`` (``--paper``).
        with_map: observe also writes the testbed's marker-free map features (``--with-map``),
            so that ``evaluate --plan`` renders no map image; always on when the plan fits the
            success model (its calibration needs the map).
        force: run even when the run-size guard says it is too large (``--force``).
        adopt: use an output folder markerplace did not make (``--adopt``).
        progress: progress bars.
    """

    existing: str | None = None
    exclude: str | None = None
    where: str | None = None
    paper: str = "a4"
    with_map: bool = False
    force: bool = False
    adopt: bool = False
    progress: bool = True


@dataclass(frozen=True)
class PlanResult:
    """What :func:`run_plan` made: the run folder, its ``report.html``, and lines saying what
    changed against the placement the folder held before (empty on a first run)."""

    out: Path
    report: Path
    changes: tuple[str, ...]


def run_plan(config: PlanConfig, scene_spec: SceneSpec, out: str | Path, inputs: PlanInputs = PlanInputs()) -> PlanResult:
    """Plan ``config.placement.k`` tags in the scene (with ``target_recall``: as many as reach
    it, k at most: :func:`~markerplace.plan.place.predicted_recall.place_for_target`) and write every
    deliverable into ``out``; placement.json and report.html carry the predicted recall against
    k where the success model was fitted (:func:`~markerplace.plan.place.predicted_recall.wants_success_model`).

    Every input is read and checked before any work; the folder is then opened as this run's
    (marked, locked, only markerplace's own files rewritten: :mod:`markerplace.runtime.run_folder`).
    """
    out, k = Path(out), config.placement.k
    validate(config)
    warn_unused_settings(config)
    existing = load_markers(inputs.existing, "--existing") if inputs.existing else []
    target = config.placement.target_recall  # then k is the most tags (place_for_target)
    check_tag_budget(k if target is None else 1, existing, config.placement.first_tag_id)
    exclusion = load_exclusion(inputs.exclude) if inputs.exclude else None
    where = load_where(inputs.where) if inputs.where else None
    previous = previous_markers(out, scene_spec.spec)  # to say what this run changes
    run_folder.open_run_folder(out, "plan", adopt=inputs.adopt)
    refuse_foreign(out, plan_outputs())  # a file of the user's named like an output: refused now, not at the end
    if config.runtime.cluster:
        check_scheduler(config.runtime.cluster)  # something answers there, before any work
    scene = scene_spec.load()
    offset = world_offset(scene)
    existing = markers_to_internal(existing, offset)
    check_markers_on_walls(scene, existing, f"--existing {inputs.existing}")
    run_config = check_first_guess(config, scene, inputs.force)  # also moves --start into the scene frame
    with_map = inputs.with_map or wants_success_model(config.placement)
    with make_executor(run_config.runtime) as executor:
        size_check = measured_size_check(scene, scene_spec, run_config, k, force=inputs.force,
                                         map_sift=testbed_imaging_config(run_config).sift if with_map else None)
        data = prepare(scene_spec, run_config, out, existing, inputs.progress, executor,
                       None if target is not None else k, size_check, where,
                       map_cache=out / "calibration" if with_map else None)
        if target is None:
            check_k(k, data.num_candidates)  # before calibrating for nothing
        calibrate_plan(scene_spec, data, run_config, out, executor, model_methods(config.placement),
                       progress=inputs.progress)
    if exclusion is not None:
        data = apply_exclusion(data, exclusion, offset, 1 if target is not None else k)
    if target is None:
        placement, target_info = place(data, config.placement, existing=existing, progress=inputs.progress), None
    else:
        placement, target_info = place_for_target(data, config.placement, existing, inputs.progress)
    t0 = time.perf_counter()
    predicted = {"predicted_recall": predicted_recall(data, placement, config.placement, target_info),
                 "score_bound": score_bound(data, placement)}
    data.timings["predicted recall and bounds"] = time.perf_counter() - t0
    summary = write_plan_outputs(out, data=data, placement=placement, first_gain=first_pick_gain(data, placement),
                                 config=config, method=config.placement.method, scene_source=scene_spec.spec,
                                 scene=scene, existing=existing, world_offset=offset, paper=inputs.paper,
                                 scene_options={"up": scene_spec.up, "unit_scale": scene_spec.unit_scale,
                                                "seed": scene_spec.seed}, exclusion=exclusion,
                                 predicted=predicted, where=where)
    log.info("placed %d markers with %s; mean score %.2f -> %.2f; 10th percentile %.2f -> %.2f",
             len(placement.markers), config.placement.method, summary["mean_score_before"],
             summary["mean_score_after"], summary["p10_score_before"], summary["p10_score_after"])
    log.info("stage seconds: %s", ", ".join(f"{name} {s:.1f}" for name, s in data.timings.items()))
    report = write_plan_report(out, scene, data.disc, config.discretize.height, world_offset=offset)
    changes = () if previous is None else tuple(
        describe_changes(placement_changes(previous, previous_markers(out, scene_spec.spec) or [])))
    return PlanResult(out, Path(report), changes)
