"""The paper's experiment as a short chain of stages over artifacts in one run folder:

1. plan (:func:`markerplace.plan.planner.prepare`): feasible poses, scores, candidates;
2. placements: none, OMP (nested k), random and uniform runs, extra placement files;
3. test poses per test set (identical for every method);
4. marker-free map and query features, and which markers each image may show;
5. the VLAD codebook of the marker-free map;
6. per placement: its map (only images with one of its markers in view are re-rendered) and
   the predictions of every test set (query images with its markers in view re-rendered);
7. metrics from the predictions (:mod:`markerplace.testbed.report`).

Every stage is cached with the hash of its inputs (:mod:`markerplace.runtime.stages`); an
interrupted run resumes where it stopped. Per-image work runs on one executor for the whole
run (in process, local processes or a Dask cluster).
"""

from __future__ import annotations

import logging
import shutil
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..imaging.engine import marker_key
from ..imaging.features import ImageFeatures
from ..runtime import cache
from ..runtime.executor import make_executor
from ..runtime.stages import cached
from .images import BaseImages, TestbedImaging
from .maps import localize_task, save_map
from .predictions import load_prediction, save_prediction

log = logging.getLogger(__name__)

__all__ = ["EvaluationResult", "run_evaluation"]


@dataclass(frozen=True, eq=False)
class EvaluationResult:
    """What :func:`run_evaluation` returns.

    Attributes:
        rows: the recall rows (see :mod:`markerplace.report.tables`).
        summary: markdown of the main tables (recall at the main threshold per test set).
        timings: seconds per stage.
    """

    rows: list
    summary: str
    timings: dict


def _localizer_spec(config) -> tuple:
    """(registered localizer name, its settings) of the run (hashable: part of cache keys)."""
    loc = config.localization
    return loc.localizer, (("use_tags", loc.use_tags), ("tag_corners", loc.tag_corners), ("seed", config.seed))


def _test_poses(out: Path, config, plan_config, data, base_key: str, timings: dict) -> dict:
    from . import poses as tp

    disc = data.disc
    map_poses = np.asarray(disc.world_from_cam, float)
    layer = {int(st): k for k, st in enumerate(disc.planned_storeys)}
    is_free = tp.free_space_checker(disc.occupancy, disc.grid_origin, disc.grid_resolution, config.test.min_clearance,
                                    np.array([layer[int(st)] for st in disc.pose_storey], dtype=np.int64))
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


def _codebook(path: Path, key: str, map_base: BaseImages, config, timings: dict):
    from ..localization.vlad import VladCodebook

    return cached("vlad_codebook", path, key,
                  lambda: VladCodebook.train(np.asarray(map_base.features.descriptors, np.float32),
                                             num_clusters=config.localization.vlad_clusters, seed=config.seed),
                  lambda cb, p: cb.save(p), VladCodebook.load, timings)


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
            instead of localizing them again (exact; see :func:`_predict_all`).
        work_dir: folder of the planner's artifacts and the caches (default ``out_dir``); runs
            that share it share every stage their inputs have in common (``markerplace study``).
        extra_placements: more marker sets evaluated as methods: name -> markers in the
            internal (scene) frame.
    """
    from ..imaging.config import SIFT_DEFAULT
    from ..io_utils import write_json
    from ..markers import load_markers
    from ..plan.planner import prepare, validate
    from .config import validate_evaluate_config
    from .placements import build_placements, find_placement_files
    from .report import write_outputs

    t_all = time.perf_counter()
    validate_evaluate_config(config)
    validate(plan_config)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    work = Path(work_dir) if work_dir is not None else out
    cache_dir = work / "cache"
    timings: dict[str, float] = {}
    imaging = imaging_config or replace(plan_config.imaging, sift=SIFT_DEFAULT)
    lcfg = _localizer_spec(config)

    with make_executor(plan_config.runtime) as executor:
        t0 = time.perf_counter()
        data = prepare(scene_spec, plan_config, work / "plan", progress=progress, executor=executor)
        timings["plan_prepare"] = time.perf_counter() - t0
        scene = scene_spec.load()
        map_poses = np.asarray(data.disc.world_from_cam, float)
        base_key = cache.hash_of("testbed-v1", cache.scene_hash(scene), map_poses)

        t0 = time.perf_counter()
        extra = dict(extra_placements or {})
        if placements_dir is not None:
            from ..scene.worldframe import markers_to_internal, world_offset

            # placement files are in the user's (file) frame; the scene may be recentred
            extra.update({name: markers_to_internal(load_markers(p), world_offset(scene))
                          for name, p in find_placement_files(placements_dir).items()})
        placements = build_placements(data, plan_config.placement, config, extra)
        timings["placements"] = time.perf_counter() - t0
        log.info("evaluating %d marker sets: %s", len(placements), ", ".join(sorted({p.method for p in placements})))

        test_poses = _test_poses(out, config, plan_config, data, base_key, timings)
        union = list({marker_key(m): m for p in placements for m in p.markers}.values())
        tb = TestbedImaging(scene_spec, imaging, union, executor, progress)
        t0 = time.perf_counter()
        map_base = BaseImages(tb, map_poses, cache_dir / "map_base", base_key, True, "map")
        timings["map_no_markers"] = time.perf_counter() - t0
        cb_key = cache.hash_of("vlad-v1", base_key, imaging, config.localization.vlad_clusters, config.seed)
        codebook = _codebook(cache_dir / "vlad_codebook.npz", cb_key, map_base, config, timings)
        t0 = time.perf_counter()
        query_base = {ts: BaseImages(tb, test_poses[ts].world_from_cam, cache_dir / f"query_base_{ts}",
                                     cache.hash_of(base_key, test_poses[ts].world_from_cam), False, f"queries {ts}")
                      for ts in config.test.sets}
        timings["queries_no_markers"] = time.perf_counter() - t0

        predictions = _predict_all(tb, placements, map_base, query_base, test_poses, codebook, cb_key, lcfg,
                                   imaging, cache_dir, timings, reuse_unchanged)

    t0 = time.perf_counter()
    rows, summary = write_outputs(out, scene.name, placements, predictions, test_poses, data.base_score, config,
                                  plan_config, scene=scene)
    timings["report"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    write_json(out / "timings.json", {k: round(v, 3) for k, v in timings.items()})
    log.info("stage seconds: %s", ", ".join(f"{k} {v:.1f}" for k, v in timings.items()))
    return EvaluationResult(rows, summary, timings)


class _Retrieval:
    """The VLAD retrieval of the queries that see no marker, replayed in this process to tell
    which of them a placement cannot change (exact, see :func:`_predict_all`).

    ``vlad`` (M, D) float32 holds the marker-free map images' VLAD vectors exactly as a
    worker's :class:`~markerplace.localization.database.MapDatabase` computes them; a
    placement replaces the rows of its re-rendered images.
    """

    def __init__(self, codebook, map_base: BaseImages, num_candidates: int):
        self.codebook = codebook
        self.n = int(num_candidates)
        feats = map_base.features
        self.vlad = np.stack([codebook.vlad(np.asarray(feats.image(i).descriptors, np.float32))
                              for i in range(len(feats))]).astype(np.float32) if len(feats) else None
        self._queries: dict = {}

    def query_vlads(self, name: str, base: BaseImages) -> np.ndarray:
        if name not in self._queries:
            feats = base.features
            self._queries[name] = [self.codebook.vlad(np.asarray(feats.image(i).descriptors, np.float32))
                                   for i in range(len(feats))]
        return self._queries[name]

    def candidates(self, vlad: np.ndarray, query: np.ndarray) -> tuple:
        from ..localization.vlad import nearest

        return tuple(int(i) for i in nearest(vlad, query, self.n)[0])


def _predict_all(tb: TestbedImaging, placements, map_base: BaseImages, query_base: dict, test_poses: dict, codebook,
                 cb_key: str, lcfg, imaging, cache_dir: Path, timings: dict, reuse: bool = True) -> dict:
    """Predictions of every placement and test set (stage 6 of the module docstring).

    With ``reuse``, a query that no marker of a placement can change gets the no-marker
    prediction without localizing again: its view holds none of the placement's markers (so its
    features and tags are the marker-free ones), the map images its VLAD retrieval returns
    against this placement's map are the ones it returns against the marker-free map, in the
    same order, and none of them was re-rendered. The localizer then sees identical inputs
    (and seeds RANSAC per query), so the result is identical: this skips work, it approximates
    nothing (``tests/test_testbed.py`` compares both paths).
    """
    from ..localization.localizer import LOCALIZERS

    pred_dir = cache_dir / "predictions"
    timings.setdefault("map_with_markers", 0.0)
    timings.setdefault("localize", 0.0)
    predictions: dict[tuple, np.ndarray] = {}
    feature_cache: dict[tuple, ImageFeatures] = {}
    name, settings = lcfg
    conf = LOCALIZERS.lookup(name).default_conf
    retrieval = None
    if reuse and name == "sift_pnp" and map_base.world_from_cam.size:
        retrieval = _Retrieval(codebook, map_base, conf.num_candidates)
    reused = 0
    for p in placements:
        marker_arr = [(m.tag_id, m.size, np.asarray(m.world_from_marker)) for m in p.markers]
        pending = []
        for ts, tp in test_poses.items():
            key = cache.hash_of("prediction-v1", cb_key, tp.world_from_cam, marker_arr, lcfg, imaging)
            est = load_prediction(pred_dir, key)
            if est is not None:
                predictions[(p.method, p.run, p.k, ts)] = est
            else:
                pending.append((ts, key))
        if not pending:
            continue
        t0 = time.perf_counter()
        db_dir, changed, feats = _placement_map(tb, p, map_base, feature_cache, codebook,
                                                cache_dir / f"db_{cache.hash_of(cb_key, marker_arr)}")
        timings["map_with_markers"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        try:
            vlad = None
            if retrieval is not None and p.markers:
                vlad = retrieval.vlad.copy()
                for i in changed:
                    vlad[i] = codebook.vlad(np.asarray(feats.image(i).descriptors, np.float32))
            for ts, key in pending:
                tp = test_poses[ts]
                qkeys = tb.view_keys(query_base[ts].in_view, p.markers)
                base = predictions.get(("none", 0, 0, ts))
                todo = list(range(len(tp)))
                est = np.full((len(tp), 4, 4), np.nan)
                if vlad is not None and base is not None:
                    qv = retrieval.query_vlads(ts, query_base[ts])
                    same = [i for i in todo if not qkeys[i] and _unchanged(retrieval, vlad, qv[i], changed)]
                    est[same] = base[same]
                    reused += len(same)
                    todo = sorted(set(todo) - set(same))
                items = [(str(db_dir), lcfg, None if qkeys[i] else query_base[ts].features.image(i), tp.world_from_cam[i],
                          list(p.markers) if qkeys[i] else []) for i in todo]
                got = dict(tb.run(localize_task, items, f"localize {ts} {p.method} k={p.k} run {p.run}"))
                for j, i in enumerate(todo):
                    est[i] = got[j]
                save_prediction(pred_dir, key, est, method=p.method, run=p.run, k=p.k, test_set=ts,
                                localized=len(todo))
                predictions[(p.method, p.run, p.k, ts)] = est
        finally:
            shutil.rmtree(db_dir, ignore_errors=True)
        timings["localize"] += time.perf_counter() - t0
    if reused:
        log.info("localize: %d queries no placement's markers could change took the no-marker result", reused)
    return predictions


def _unchanged(retrieval: _Retrieval, vlad: np.ndarray, query: np.ndarray, changed: set) -> bool:
    """The query's retrieval against the placement's map equals the marker-free one and none
    of the retrieved images changed."""
    cand = retrieval.candidates(vlad, query)
    return not (set(cand) & changed) and cand == retrieval.candidates(retrieval.vlad, query)


def _placement_map(tb: TestbedImaging, p, map_base: BaseImages, feature_cache: dict, codebook, db_dir: Path):
    """Write the map database of placement ``p``: marker-free features, except for the images
    with one of its markers in view, re-rendered (or taken from ``feature_cache``, keyed by
    image and markers in view, which it updates). Returns the folder, the set of re-rendered
    image indices and the map's features."""
    keys = tb.view_keys(map_base.in_view, p.markers)
    need = [i for i, k in enumerate(keys) if k and (i, k) not in feature_cache]
    if need:
        got = tb.render(map_base.world_from_cam, need, p.markers, True, f"map {p.method} k={p.k} run {p.run}")
        for i in need:
            feature_cache[(i, keys[i])] = got[i]
    used = {(i, k) for i, k in enumerate(keys) if k}
    for stale in [c for c in feature_cache if c not in used]:
        del feature_cache[stale]
    feats = map_base.features.with_images({i: feature_cache[(i, k)] for i, k in enumerate(keys) if k}) \
        if used else map_base.features
    save_map(db_dir, feats, map_base.world_from_cam, p.markers, codebook.centres)
    return db_dir, {i for i, _ in used}, feats
