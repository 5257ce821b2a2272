"""``markerplace evaluate``: the paper's experiment as a chain of named stages over artifacts
in one run folder, read top to bottom in :func:`run_evaluation`:

1. plan (:func:`markerplace.pipelines.plan.prepare`, then calibration for calibrated methods);
   ``evaluate --plan`` starts from a finished plan folder instead, reusing its cached stages and
   its placement (:mod:`markerplace.pipelines.from_plan`);
2. marker sets: none, OMP (nested k), random and uniform runs, extra placement files
   (:func:`markerplace.simulation.marker_sets.build_placements`);
3. test poses per test set, identical for every method (:func:`markerplace.simulation.pose_sampling.cached_test_poses`);
4. marker-free map and query features and the VLAD codebook; the queries once per query
   condition (``--conditions``, :mod:`markerplace.simulation.conditions`; the map stays clean)
   (:func:`markerplace.simulation.map_setup.marker_free_images`);
5. per placement: its map (only images with one of its markers in view are re-rendered) and
   the predictions of every image set (:func:`markerplace.simulation.placement_localization.predict_placements`);
6. optionally the oracle ceiling (:func:`markerplace.testbed.ceiling.run_ceiling`);
7. metrics and reports from the predictions (:mod:`markerplace.testbed.reporting`); with
   ``--predicted`` each placement's predicted recall against its measured one
   (:mod:`markerplace.testbed.predicted_per_placement`).

Every stage is cached with the hash of its inputs (:mod:`markerplace.runtime.stages`); an
interrupted run resumes where it stopped, inside a stage too: the marker-free images, the
renders with markers and each prediction's localizations are committed in parts as they arrive. Per-image work runs on one executor for the whole
run (in process, local processes or a Dask cluster).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.imaging.engine import marker_key
from markerplace.markers import load_markers
from markerplace.pipelines.from_plan import adopt_plan_stages, plan_placement
from markerplace.pipelines.plan import prepare
from markerplace.pipelines.size_guard import check_first_guess
from markerplace.plan.config import validate
from markerplace.plan.folder import PlanFolder
from markerplace.plan.where import Where
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import atomic_path, write_json
from markerplace.runtime.claims import refuse_foreign
from markerplace.runtime.cluster import check_scheduler
from markerplace.runtime.executor import make_executor
from markerplace.scene.worldframe import markers_to_internal, world_offset
from markerplace.simulation.conditions import CLEAN, split_set
from markerplace.simulation.map_setup import map_base_key, marker_free_images, testbed_imaging_config
from markerplace.simulation.marker_sets import build_placements, find_placement_files, method_names, with_candidate_ids
from markerplace.simulation.metrics import main_threshold, threshold_label
from markerplace.simulation.placement_localization import predict_placements
from markerplace.simulation.pose_sampling import cached_test_poses
from markerplace.simulation.rendered_images import TestbedImaging
from markerplace.simulation.success_fit import MAP_SET, calibrate_plan, map_image_set, map_successes, score_outcomes
from markerplace.testbed.ceiling import SINGLE, ceiling_markdown, run_ceiling, single_placements
from markerplace.testbed.config import validate_evaluate_config
from markerplace.testbed.predicted_per_placement import predict_recalls
from markerplace.testbed.reporting.calibration import write_calibration_report
from markerplace.testbed.reporting.summary import write_outputs

log = logging.getLogger(__name__)

__all__ = ["EvaluationResult", "RunInputs", "evaluate", "open_evaluation_folder", "run_evaluation",
           "EVALUATE_OUTPUTS", "RUN_OUTPUTS", "STAGE_OUTPUTS"]

RUN_OUTPUTS = ("recall.csv", "query_errors.npz", "predicted.csv", "tables.md", "recall_vs_k.png", "config.json",
               "ceiling.md", "calibration.md", "map_outcomes.npz", "calibration.png", "timings.json",
               "test_poses_*.npz*", "report.html")
"""What :func:`run_evaluation` writes at the top of its folder (``fnmatch`` patterns, see
:data:`markerplace.pipelines.plan.PLAN_OUTPUTS`)."""
STAGE_OUTPUTS = ("discretization.npz*", "observations/*.npy", "observations.meta.json", "similarity.npz*",
                 "calibration/", "success_model_*.json*")
"""The plan stages an evaluation computes into its work folder's ``plan/``."""
EVALUATE_OUTPUTS = (*RUN_OUTPUTS, "plan/", "cache/", *(f"plan/{p}" for p in STAGE_OUTPUTS))
"""What ``evaluate`` writes into its ``--out`` folder, checked in an adopted folder before any
work (:func:`markerplace.runtime.claims.refuse_foreign`)."""


@dataclass(frozen=True, eq=False)
class EvaluationResult:
    """What :func:`run_evaluation` returns.

    Attributes:
        rows: the recall rows (see :mod:`markerplace.testbed.reporting.tables`).
        summary: markdown of the main tables (recall at the main threshold per test set).
        timings: seconds per stage.
    """

    rows: list
    summary: str
    timings: dict


def run_evaluation(scene_spec, plan_config, config, out_dir: str | Path, placements_dir: str | Path | None = None,
                   imaging_config=None, progress: bool = True, reuse_unchanged: bool = True,
                   work_dir: str | Path | None = None, extra_placements: dict | None = None,
                   plan: PlanFolder | None = None, where: Where | None = None) -> EvaluationResult:
    """Run the paper's experiments and write every output into ``out_dir``.

    Args:
        scene_spec: :class:`~markerplace.scene.spec.SceneSpec` of the scene.
        plan_config: :class:`~markerplace.plan.config.PlanConfig` (internal frame; ``runtime``:
            where the per-image work runs).
        config: :class:`~markerplace.testbed.config.EvaluateConfig`.
        out_dir: run folder: the outputs ``recall.csv``, ``query_errors.npz``, ``tables.md``,
            ``recall_vs_k.png``, ``timings.json``, ``config.json``, ``test_poses_<set>.npz``.
        placements_dir: folder of ``placement.json`` files (user frame) evaluated as extra methods.
        imaging_config: the testbed's imaging (default: the plan's camera, OpenCV's SIFT defaults).
        reuse_unchanged: give images no placement's marker can change the marker-free result
            instead of localizing them again (exact; :mod:`markerplace.simulation.placement_localization`).
        work_dir: folder of the plan's artifacts (``plan/``) and the caches (``cache/``) (default
            ``out_dir``); runs that share it share every stage with the same inputs (``study``).
        extra_placements: more marker sets evaluated as methods: name -> markers (internal frame).
        plan: the plan folder of ``evaluate --plan`` (:mod:`markerplace.pipelines.from_plan`):
            its cached stages are reused and its placement is its method's marker set;
            ``scene_spec`` and ``plan_config`` must be its own (:func:`~markerplace.pipelines.from_plan.start_from_plan`).
        where: the ``--where`` file (:mod:`markerplace.plan.where`): the placement methods weigh
            the poses by it (as ``plan --where``) and the ``where`` test set is drawn from it.
    """
    t_all, timings = time.perf_counter(), {}
    validate_evaluate_config(config, where is not None)
    validate(plan_config)
    out = Path(out_dir)
    run_folder.make_dirs(out)
    work = Path(work_dir) if work_dir is not None else out
    cache_dir, diag, by_spot = work / "cache", config.diagnostics, config.study.tag_ids == "candidate"
    imaging = testbed_imaging_config(plan_config, imaging_config)
    if plan is not None:
        adopt_plan_stages(plan, work / "plan", cache_dir)
    with make_executor(plan_config.runtime) as executor:
        t0 = time.perf_counter()
        data = prepare(scene_spec, plan_config, work / "plan", progress=progress, executor=executor,
                       k=max(config.study.ks), where=where, map_cache=cache_dir, map_imaging=imaging_config)
        models = config.study.methods + ((plan_config.placement.recall_model,) if diag.predicted else ())  # --predicted: the plans' model
        calibrate_plan(scene_spec, data, plan_config, work / "plan", executor, models, progress,
                       cache_dir=cache_dir, imaging_config=imaging_config)
        timings["plan_prepare"] = time.perf_counter() - t0
        scene = scene_spec.load()
        candidates, map_poses = data.disc.candidate_world_from_marker, np.asarray(data.disc.world_from_cam, float)
        base_key = map_base_key(scene, map_poses)
        t0 = time.perf_counter()
        extra = dict(extra_placements or {})
        if placements_dir is not None:  # placement files are in the user's frame; the scene may be recentred
            extra.update({name: markers_to_internal(load_markers(path), world_offset(scene))
                          for name, path in find_placement_files(placements_dir).items()})
        given = plan_placement(plan, data, scene) if plan is not None else None
        placements = build_placements(data, plan_config.placement, config, extra, given)
        singles = single_placements(candidates, plan_config.placement.tag_size) if diag.ceiling else []
        if by_spot:  # one code per spot in every run, so that runs share renders
            placements, singles = with_candidate_ids(placements, candidates), with_candidate_ids(singles, candidates)
        timings["placements"] = time.perf_counter() - t0
        log.info("evaluating %d marker sets: %s", len(placements), ", ".join(sorted({p.method for p in placements})))
        test_poses = cached_test_poses(out, config, plan_config, data, base_key, timings)
        union = list({marker_key(m): m for p in placements + singles for m in p.markers}.values())
        tb = TestbedImaging(scene_spec, imaging, union, executor, progress)
        ctx, sets = marker_free_images(tb, map_poses, test_poses, cache_dir, base_key, imaging, config.localization,
                                       config.seed, timings, reuse_unchanged, config.test.conditions, config.pose_seed)
        if diag.calibration:
            sets[MAP_SET] = map_image_set(ctx.map_base, data.disc.location_index)
        predictions = predict_placements(ctx, placements, sets)
        threshold = main_threshold(config.thresholds)  # the ceiling's picks and ceiling.md's table
        clean = {name: s for name, s in sets.items() if s.condition is None}  # the ceiling is measured clean
        ceiling = run_ceiling(ctx, placements, singles, clean, test_poses, candidates, plan_config.placement.tag_size,
                              config.study.ks, config.seed, threshold, by_spot) if diag.ceiling else None
    if ceiling is not None:
        placements = placements + ceiling[0]
        predictions.update(ceiling[1])
    t0 = time.perf_counter()
    test_predictions = {key: est for key, est in predictions.items()
                        if key.method != SINGLE and split_set(key.test_set)[0] in test_poses}
    predicted = predict_recalls(data, placements, test_poses, plan_config.placement.tag_size,
                                plan_config.placement.recall_model) \
        if diag.predicted else None
    rows, summary = write_outputs(out, scene.name, placements, test_predictions, test_poses, data.base_score, config,
                                  plan_config, scene=scene, where=None if where is None else where.doc,
                                  predicted=predicted)
    if ceiling is not None:
        with atomic_path(out / "ceiling.md") as tmp:
            clean_rows = [r for r in rows if r["condition"] == CLEAN]  # the ceiling is measured clean
            tmp.write_text(ceiling_markdown(clean_rows, ceiling[2], sorted(set(config.study.ks)),
                                            threshold_label(threshold), ceiling[3]))
    if diag.calibration:
        write_calibration_report(out, scene.name, score_outcomes(data, plan_config, placements,
                                                                  map_successes(predictions, map_poses)))
    timings["report"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    write_json(out / "timings.json", {name: round(s, 3) for name, s in timings.items()})
    log.info("stage seconds: %s", ", ".join(f"{name} {s:.1f}" for name, s in timings.items()))
    return EvaluationResult(rows, summary, timings)


@dataclass(frozen=True)
class RunInputs:
    """Run options of ``evaluate`` and ``study``: ``force`` (past the run-size guard), ``adopt``
    (an output folder markerplace did not make), ``progress`` (progress bars)."""

    force: bool = False
    adopt: bool = False
    progress: bool = True


def open_evaluation_folder(command: str, out: str | Path, scene_spec, plan_config, config, inputs: RunInputs,
                           extra_runs: int = 0, outputs: tuple[str, ...] = EVALUATE_OUTPUTS):
    """Open ``out`` as the run folder of ``command`` (marked, locked), refuse a foreign file named
    like one of its ``outputs`` (patterns, in an adopted folder), check that a ``--cluster``
    answers and the run-size guard's first guess (``extra_runs`` more placements); returns
    ``plan_config`` with ``--start`` in the scene's internal frame."""
    run_folder.open_run_folder(out, command, adopt=inputs.adopt)
    refuse_foreign(out, outputs)  # before any work, not when the output is written at the end
    if plan_config.runtime.cluster:
        check_scheduler(plan_config.runtime.cluster)
    return check_first_guess(plan_config, scene_spec.load(), inputs.force, config, extra_runs)


def evaluate(scene_spec, plan_config, config, out: str | Path, placements_dir: str | Path | None = None,
             inputs: RunInputs = RunInputs(), plan: PlanFolder | None = None,
             where: Where | None = None) -> EvaluationResult:
    """``markerplace evaluate``: every input checked (placement files read) before any work,
    the run folder opened, then :func:`run_evaluation` (``plan``: ``evaluate --plan``, see
    :mod:`markerplace.pipelines.from_plan`; ``where``: ``--where`` or the plan's)."""
    validate_evaluate_config(config, where is not None)
    validate(plan_config)
    if not config.study.methods and not placements_dir:
        raise UserError(f"--methods is empty: give a comma list such as {','.join(method_names())} (or --placements DIR)")
    placement_files = find_placement_files(placements_dir) if placements_dir else {}
    for path in placement_files.values():
        load_markers(path, "--placements")
    if plan is not None and Path(out).resolve() == plan.path.resolve():
        raise UserError(f"--out {out} is the --plan folder: give the evaluation its own folder (the plan's is only read)")
    if plan is not None:
        plan.check_scene(scene_spec.load())  # its placement on its scene's candidates, before anything is written
    run_config = open_evaluation_folder("evaluate", out, scene_spec, plan_config, config, inputs, len(placement_files))
    return run_evaluation(scene_spec, run_config, config, out, placements_dir=placements_dir, progress=inputs.progress,
                          plan=plan, where=where)
