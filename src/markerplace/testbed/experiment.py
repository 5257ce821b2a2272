"""The paper's experiment as a short chain of stages over artifacts in one run folder:

1. plan (:func:`markerplace.plan.planner.prepare`): feasible poses, scores, candidates;
2. placements: none, OMP (nested k), random and uniform runs, extra placement files;
3. test poses per test set (identical for every method);
4. marker-free map and query features, and which markers each image may show;
5. the VLAD codebook of the marker-free map;
6. per placement: its map (only images with one of its markers in view are re-rendered) and
   the predictions of every test set (query images with its markers in view re-rendered);
7. metrics from the predictions (:mod:`markerplace.testbed.reporting.summary`).

Every stage is cached with the hash of its inputs (:mod:`markerplace.runtime.stages`); an
interrupted run resumes where it stopped. Per-image work runs on one executor for the whole
run (in process, local processes or a Dask cluster).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplace.imaging.engine import marker_key
from markerplace.runtime import cache, run_folder
from markerplace.runtime.executor import make_executor
from markerplace.runtime.stages import cached
from markerplace.runtime.atomic_io import atomic_path
from markerplace.testbed.calibration import MAP_SET, calibrate_plan, map_image_set, map_successes, score_outcomes
from markerplace.testbed.ceiling import (SINGLE, ceiling_markdown, ceiling_placements, held_out_estimate, single_placements,
                      single_tag_outcomes)
from markerplace.testbed.images import BaseImages, TestbedImaging
from markerplace.testbed.map_setup import localizer_spec, map_base_key, map_images, testbed_imaging_config, vlad_codebook
from markerplace.testbed.metrics import main_threshold, threshold_label
from markerplace.testbed.predict import ImageSet, predict_placements

log = logging.getLogger(__name__)

__all__ = ["EvaluationResult", "run_evaluation"]


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


def _test_poses(out: Path, config, plan_config, data, base_key: str, timings: dict) -> dict:
    from markerplace.testbed import poses as tp

    map_poses = np.asarray(data.disc.world_from_cam, float)
    is_free = tp.free_space_of(data.disc, config.test.min_clearance)
    poses = {}
    for ts in config.test.sets:  # a test set's seed does not depend on which other sets run
        tcfg = tp.TestPoseConfig(num=config.test.tests, mode=ts, seed=config.pose_seed + 1000 * tp.TEST_SETS.index(ts),
                                 min_clearance=config.test.min_clearance)
        key = cache.hash_of("test-poses-v1", base_key, data.base_score, tcfg, plan_config.discretize.grid_spacing)
        poses[ts] = cached("test_poses", out / f"test_poses_{ts}.npz", key,
                           lambda: tp.sample_test_poses(map_poses, data.base_score, plan_config.discretize.grid_spacing,
                                                        tcfg, is_free),
                           lambda t, path: t.save(path), tp.TestPoses.load, timings)
    return poses


def run_evaluation(scene_spec, plan_config, config, out_dir: str | Path, placements_dir: str | Path | None = None,
                   imaging_config=None, progress: bool = True, reuse_unchanged: bool = True,
                   work_dir: str | Path | None = None, extra_placements: dict | None = None) -> EvaluationResult:
    """Run the paper's experiments and write every output into ``out_dir``.

    Args:
        scene_spec: :class:`~markerplace.scene.spec.SceneSpec` of the scene.
        plan_config: :class:`~markerplace.plan.planner.PlanConfig` (discretization, scoring,
            v, runtime: where the per-image work runs).
        config: :class:`~markerplace.testbed.config.EvaluateConfig`.
        out_dir: run directory: planner artifacts (``plan/``), caches (``cache/``: marker-free
            features, codebook, ``predictions/``) and the outputs ``recall.csv``,
            ``query_errors.npz``, ``tables.md``, ``recall_vs_k.png``, ``timings.json``,
            ``config.json``, ``test_poses_<set>.npz``.
        placements_dir: folder of ``placement.json`` files evaluated as extra methods.
        imaging_config: the testbed's imaging (default: the plan's camera with the
            localization SIFT preset, OpenCV defaults).
        progress: progress bars.
        reuse_unchanged: give queries no placement's marker can change the no-marker result
            instead of localizing them again (exact; see :mod:`markerplace.testbed.predict`).
        work_dir: folder of the planner's artifacts and the caches (default ``out_dir``); runs
            that share it share every stage their inputs have in common (``markerplace study``).
        extra_placements: more marker sets evaluated as methods: name -> markers in the
            internal (scene) frame.
    """
    from markerplace.runtime.atomic_io import write_json
    from markerplace.markers import load_markers
    from markerplace.plan.planner import prepare, validate
    from markerplace.testbed.config import validate_evaluate_config
    from markerplace.testbed.marker_sets import build_placements, find_placement_files, with_candidate_ids
    from markerplace.testbed.reporting.summary import write_outputs

    t_all = time.perf_counter()
    validate_evaluate_config(config)
    validate(plan_config)
    out = Path(out_dir)
    run_folder.make_dirs(out)
    work = Path(work_dir) if work_dir is not None else out
    cache_dir = work / "cache"
    timings: dict[str, float] = {}
    imaging = testbed_imaging_config(plan_config, imaging_config)
    lcfg = localizer_spec(config.localization, config.seed)

    with make_executor(plan_config.runtime) as executor:
        t0 = time.perf_counter()
        data = prepare(scene_spec, plan_config, work / "plan", progress=progress, executor=executor,
                       k=max(config.study.ks))
        calibrate_plan(scene_spec, data, plan_config, work / "plan", executor, config.study.methods, progress,
                       cache_dir=cache_dir, imaging_config=imaging_config)
        timings["plan_prepare"] = time.perf_counter() - t0
        scene = scene_spec.load()
        map_poses = np.asarray(data.disc.world_from_cam, float)
        base_key = map_base_key(scene, map_poses)

        t0 = time.perf_counter()
        extra = dict(extra_placements or {})
        if placements_dir is not None:
            from markerplace.scene.worldframe import markers_to_internal, world_offset

            # placement files are in the user's (file) frame; the scene may be recentred
            extra.update({name: markers_to_internal(load_markers(p), world_offset(scene))
                          for name, p in find_placement_files(placements_dir).items()})
        placements = build_placements(data, plan_config.placement, config, extra)
        timings["placements"] = time.perf_counter() - t0
        log.info("evaluating %d marker sets: %s", len(placements), ", ".join(sorted({p.method for p in placements})))

        diag = config.diagnostics
        singles = single_placements(data.disc.candidate_world_from_marker, plan_config.placement.tag_size) \
            if diag.ceiling else []
        by_spot = config.study.tag_ids == "candidate"
        if by_spot:  # one code per spot in every run, so that runs share renders
            placements = with_candidate_ids(placements, data.disc.candidate_world_from_marker)
            singles = with_candidate_ids(singles, data.disc.candidate_world_from_marker)
        test_poses = _test_poses(out, config, plan_config, data, base_key, timings)
        union = list({marker_key(m): m for p in placements + singles for m in p.markers}.values())
        tb = TestbedImaging(scene_spec, imaging, union, executor, progress)
        t0 = time.perf_counter()
        map_base = map_images(tb, map_poses, cache_dir, base_key)
        timings["map_no_markers"] = time.perf_counter() - t0
        codebook, cb_key = vlad_codebook(cache_dir, base_key, imaging, map_base, config.localization.vlad_clusters,
                                         config.seed, timings)
        t0 = time.perf_counter()
        query_base = {ts: BaseImages(tb, test_poses[ts].world_from_cam, cache_dir / f"query_base_{ts}",
                                     cache.hash_of(base_key, test_poses[ts].world_from_cam), False, f"queries {ts}")
                      for ts in config.test.sets}
        timings["queries_no_markers"] = time.perf_counter() - t0

        sets = {ts: ImageSet(ts, test_poses[ts].world_from_cam, query_base[ts]) for ts in config.test.sets}
        if diag.calibration:
            sets[MAP_SET] = map_image_set(map_base, data.disc.location_index)
        predictions = predict_placements(tb, placements, map_base, sets, codebook, cb_key, lcfg, imaging, cache_dir,
                                         timings, reuse_unchanged)
        estimate = held_out = None
        threshold = main_threshold(config.thresholds)  # the ceiling's picks and ceiling.md's table
        if diag.ceiling:  # every candidate alone, the oracle's picks from those outcomes, then the picks
            test_sets = {ts: s for ts, s in sets.items() if ts != MAP_SET}
            predictions.update(predict_placements(tb, placements[:1] + singles, map_base, test_sets, codebook, cb_key,
                                                  lcfg, imaging, cache_dir, timings, reuse_unchanged))
            outcomes = single_tag_outcomes(predictions, test_poses, len(data.disc.candidate_world_from_marker),
                                           threshold)
            ceiling_runs, estimate = ceiling_placements(data.disc.candidate_world_from_marker,
                                                        plan_config.placement.tag_size, outcomes, config.study.ks)
            held_out = held_out_estimate(outcomes, config.study.ks, config.seed)
            if by_spot:
                ceiling_runs = with_candidate_ids(ceiling_runs, data.disc.candidate_world_from_marker)
            predictions.update(predict_placements(tb, placements[:1] + ceiling_runs, map_base, test_sets, codebook,
                                                  cb_key, lcfg, imaging, cache_dir, timings, reuse_unchanged))
            placements = placements + ceiling_runs

    t0 = time.perf_counter()
    test_predictions = {key: est for key, est in predictions.items() if key[0] != SINGLE and key[3] in test_poses}
    rows, summary = write_outputs(out, scene.name, placements, test_predictions, test_poses, data.base_score, config,
                                  plan_config, scene=scene)
    if estimate is not None:
        with atomic_path(out / "ceiling.md") as tmp:
            tmp.write_text(ceiling_markdown(rows, estimate, sorted(set(config.study.ks)),
                                            threshold_label(threshold), held_out))
    if diag.calibration:
        from markerplace.testbed.reporting.calibration import write_calibration_report

        write_calibration_report(out, scene.name, score_outcomes(data, plan_config, placements,
                                                                  map_successes(predictions, map_poses)))
    timings["report"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    write_json(out / "timings.json", {k: round(v, 3) for k, v in timings.items()})
    log.info("stage seconds: %s", ", ".join(f"{k} {v:.1f}" for k, v in timings.items()))
    return EvaluationResult(rows, summary, timings)
