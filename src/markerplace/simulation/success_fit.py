"""Does the localizability score predict localization? Map images localized against the rest of
the map, and the success model fitted on them.

Each map image (a feasible pose) is localized by the testbed's localizer against the map
without the images of its own camera location (leave-one-location-out: the nearest map images
left are a grid step away, a test image's at most 0.71 steps: a harder case), without markers and with the
markers of a tag set in view (re-rendered, as the testbed does). As a query, a map image uses
its map features (keypoints with a 3D point), a few less than a test image's. A success is an estimate within the main
recall threshold (5 cm, 5 deg) of the image's true pose. Only map images take part: test images
never touch a fit.

* :func:`calibrate_plan` fills ``PlanData.calibration`` for every calibrated placement method
  (a :class:`~markerplace.plan.place.methods.CalibratedMethod`, e.g. ``expected-recall``; the
  fields of its :class:`~markerplace.plan.place.methods.CalibrationConfig` are the fit's
  settings): the map images are localized without tags and with
  ``calibration_runs`` seeded random sets of ``calibration_k`` candidate tags, and a
  :class:`~markerplace.plan.score.success_model.SuccessModel` is fitted on the pairs (score under the
  method's marker model, success): every map image without tags, plus with each set the images
  whose score the set changes (the sets are distinct). Cached in the plan folder
  (``calibration/``, ``success_model_<method>.json``); the localizer has the testbed's default
  settings (tag detection on), seeded with ``calibration_seed``.
* With ``calibration_poses = "offgrid"`` (``--calibration-poses offgrid``) the fit uses, instead
  of the map images, ``calibration_images`` renders at test-like poses: feasible poses drawn
  uniformly and perturbed as the testbed's test poses are (:func:`offgrid_poses`: within a grid
  cell, +-22.5 deg of yaw, in free space), from a random stream of ``calibration_seed`` that no
  test seed reaches, each localized against the whole map (as a test image is). Its score is
  its source pose's. Why: a map image left out of its own location still has map images a grid
  step away in the same directions, and localizes far more often than a test image does (the
  house: 95.4 % of map images against 78.0 % of weighted test images), so the map-image fit
  sees few failures.
* :func:`score_outcomes` gives, for ``evaluate --calibration``, the same pairs for every evaluated
  placement made of candidates and for each marker model, from which
  :mod:`markerplace.testbed.reporting.calibration` draws calibration curves and AUCs.

Existing markers (``plan --existing``) are left out of the calibration renders.
"""

from __future__ import annotations

import json
import logging
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from markerplace.imaging.engine import marker_key
from markerplace.markers import FAMILY, Marker
from markerplace.plan.place.greedy import apply_coverages
from markerplace.plan.place.methods import PLACEMENT_METHODS, CalibratedMethod, CalibrationConfig, method_conf
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.stage import coverages_with_model
from markerplace.plan.score.success_model import SuccessModel, fit_success_model
from markerplace.runtime import cache
from markerplace.runtime.atomic_io import write_json
from markerplace.runtime.stages import cached
from markerplace.simulation import pose_sampling as tp
from markerplace.simulation.config import LocalizationConfig
from markerplace.simulation.map_setup import localizer_spec, map_base_key, map_images, testbed_imaging_config, vlad_codebook
from markerplace.simulation.marker_sets import NO_MARKERS, PlacementRun, candidate_of
from markerplace.simulation.metrics import MAIN_THRESHOLD, hit_mask, pose_errors_batch
from markerplace.simulation.placement_localization import ImageSet, PredictContext, predict_placements
from markerplace.simulation.rendered_images import BaseImages, TestbedImaging

log = logging.getLogger(__name__)

__all__ = ["map_image_set", "map_successes", "offgrid_poses", "placement_candidates", "scores_with", "calibrate_plan",
           "score_outcomes"]

MAP_SET = "map"
"""Name of the map images' :class:`~markerplace.simulation.placement_localization.ImageSet`."""


def map_image_set(map_base: BaseImages, location_index: np.ndarray) -> ImageSet:
    """The map images as an image set, each leaving its own location's images out of retrieval.

    Args:
        map_base: the marker-free map images.
        location_index: (N,) camera location of each map image.
    """
    loc = np.asarray(location_index, dtype=np.int64)
    members: dict[int, tuple] = {}
    for l in np.unique(loc):
        members[int(l)] = tuple(int(i) for i in np.flatnonzero(loc == l))
    return ImageSet(MAP_SET, map_base.world_from_cam, map_base, [members[int(l)] for l in loc], own=True)


OFFGRID_SET = "calibration"
"""Name of the off-grid calibration images' :class:`~markerplace.simulation.placement_localization.ImageSet`."""
OFFGRID_STREAM = 1
"""Random stream of the off-grid poses (:attr:`~markerplace.simulation.pose_sampling.TestPoseConfig.stream`)."""


def map_successes(predictions: dict, world_from_cam: np.ndarray, threshold=MAIN_THRESHOLD,
                  set_name: str = MAP_SET) -> dict:
    """(method, run, k) -> (N,) bool: images of set ``set_name`` (default the map images)
    localized within ``threshold`` (metres, deg) of ``world_from_cam`` ((N, 4, 4), their true poses)."""
    out = {}
    for (method, run, k, name), est in predictions.items():
        if name == set_name:
            out[(method, run, k)] = hit_mask(*pose_errors_batch(est, world_from_cam), *threshold)
    return out


def offgrid_poses(data, grid_spacing: float, num: int, seed: int):
    """``num`` test-like calibration poses (:class:`~markerplace.simulation.pose_sampling.TestPoses`): feasible
    poses drawn uniformly, perturbed like test poses, in free space, from stream
    :data:`OFFGRID_STREAM` of ``seed`` (never the test images: those use stream 0)."""
    tcfg = tp.TestPoseConfig(num=num, mode="uniform", seed=seed, stream=OFFGRID_STREAM)
    return tp.sample_test_poses(np.asarray(data.disc.world_from_cam, float), data.base_score, grid_spacing, tcfg,
                                tp.free_space_of(data.disc, tcfg.min_clearance))


def placement_candidates(markers, candidate_world_from_marker: np.ndarray, tag_size: float,
                         atol: float = 1e-5) -> np.ndarray | None:
    """(k,) candidate index of each marker (its pose equals the candidate's within ``atol``,
    above the 1e-6 rounding of placement.json, and its size is ``tag_size``), or None when some
    marker is not a candidate (a shifted tag, one printed at another size, a placement file
    with its own spots)."""
    out = []
    for m in markers:
        j = candidate_of(m.world_from_marker, candidate_world_from_marker, atol)
        if j < 0 or abs(float(m.size) - float(tag_size)) > 1e-9:
            return None
        out.append(j)
    return np.asarray(out, dtype=np.int64)


def scores_with(data, coverages: list, candidates: np.ndarray) -> np.ndarray:
    """(N,) score ``-H`` of every pose with the given candidates' tags (``coverages``: per
    candidate, e.g. under another marker model; existing markers not added)."""
    return -entropy(apply_coverages(data.base_info, [coverages[int(c)] for c in candidates]))


def _pairs(data, coverages, success: dict, sets: dict, source_index: np.ndarray | None = None
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pooled (score, success, with tags) of the images: all of them without tags, and with
    each tag set those whose score it changes. ``sets``: (method, run, k) -> candidates. The
    images are the map images, or (``source_index``, (M,)) images scored by those feasible poses."""
    src = np.arange(len(data.base_score)) if source_index is None else np.asarray(source_index, np.int64)
    base = np.asarray(data.base_score, float)[src]
    s, y, tagged = [base], [success[(NO_MARKERS, 0, 0)]], [np.zeros(len(base), bool)]
    for key, cands in sets.items():
        if key not in success or cands is None:
            continue
        sc = scores_with(data, coverages, cands)[src]
        changed = sc != base
        s.append(sc[changed])
        y.append(success[key][changed])
        tagged.append(np.ones(int(changed.sum()), bool))
    return np.concatenate(s), np.concatenate(y).astype(bool), np.concatenate(tagged)


def calibrate_plan(scene_spec, data, plan_config, run_dir: str | Path, executor, methods=None,
                   progress: bool = True, cache_dir: str | Path | None = None, imaging_config=None) -> None:
    """Fill ``data.calibration[name]`` (the fitted model and the method's coverages) for every
    calibrated method in ``methods`` (names; default ``plan_config.placement.method``).

    Args:
        scene_spec: the scene.
        data: the prepared plan (:func:`markerplace.pipelines.plan.prepare`); updated in place.
        plan_config: the plan's settings.
        run_dir: the plan folder (``success_model_<method>.json`` goes here).
        executor: where renders and localizations run.
        methods: placement method names about to be placed.
        progress: progress bars.
        cache_dir: folder of the marker-free map features, the VLAD codebook and the
            predictions (default ``run_dir/calibration``); ``evaluate`` passes its own cache, so
            the map is rendered and the codebook trained once for both
            (:mod:`markerplace.simulation.map_setup`).
        imaging_config: the testbed's imaging (default: the plan's camera, OpenCV SIFT).
    """
    names = [plan_config.placement.method] if methods is None else list(methods)
    run_dir = Path(run_dir)
    folder = run_dir / "calibration" if cache_dir is None else Path(cache_dir)
    for name in dict.fromkeys(names):
        cls = PLACEMENT_METHODS.get(name)
        if cls is None or not issubclass(cls, CalibratedMethod) or name in data.calibration:
            continue
        own = method_conf(name, plan_config.placement)
        conf = CalibrationConfig(**{f.name: getattr(own, f.name) for f in fields(CalibrationConfig)})  # the fit's
        offgrid = conf.calibration_poses == "offgrid"
        covs = coverages_with_model(data, conf.tag_model, plan_config.noise, plan_config.imaging.camera.K)
        C = data.num_candidates
        kc = min(C, int(conf.calibration_k))
        rng = np.random.default_rng(conf.calibration_seed)
        drawn = {tuple(np.sort(rng.choice(C, size=kc, replace=False)).tolist()) for _ in range(conf.calibration_runs)} \
            if kc else set()
        sets = {("calibration", r, kc): np.asarray(c, np.int64) for r, c in enumerate(sorted(drawn))}  # distinct sets
        imaging = testbed_imaging_config(plan_config, imaging_config)
        localization = LocalizationConfig()
        lcfg = localizer_spec(localization, conf.calibration_seed)
        map_poses = np.asarray(data.disc.world_from_cam, float)
        base_key = map_base_key(scene_spec.load(), map_poses)
        tag_size = plan_config.placement.tag_size
        fit_conf = conf if offgrid else replace(conf, calibration_images=0)  # unused by a map fit
        queries = offgrid_poses(data, plan_config.discretize.grid_spacing, conf.calibration_images,
                                conf.calibration_seed) if offgrid else None
        key = cache.hash_of("calibration-v2", base_key, imaging, lcfg, localization.vlad_clusters, data.base_score,
                            fit_conf, tag_size, data.disc.candidate_world_from_marker,
                            data.disc.location_index, [(cv.pose_idx, cv.info) for cv in covs], sorted(drawn),
                            MAIN_THRESHOLD, None if queries is None else queries.world_from_cam)

        def fit() -> SuccessModel:
            placements = [PlacementRun(NO_MARKERS, 0, 0, ())]
            for (m, r, k), cands in sets.items():
                placements.append(PlacementRun(m, r, k, tuple(
                    Marker(i, tag_size, data.disc.candidate_world_from_marker[c].copy(), FAMILY)
                    for i, c in enumerate(cands))))
            union = list({marker_key(mk): mk for p in placements for mk in p.markers}.values())
            tb = TestbedImaging(scene_spec, imaging, union, executor, progress)
            map_base = map_images(tb, map_poses, folder, base_key)
            timings: dict = {}
            codebook, cb_key = vlad_codebook(folder, base_key, imaging, map_base, localization.vlad_clusters,
                                             conf.calibration_seed, timings)
            if queries is None:
                image_set, true_poses, source, what = (map_image_set(map_base, data.disc.location_index), map_poses,
                                                       None, "map images localized against the rest of the map")
            else:
                base = BaseImages(tb, queries.world_from_cam, folder / "offgrid_base",
                                  cache.hash_of(base_key, queries.world_from_cam), False, "calibration images")
                image_set = ImageSet(OFFGRID_SET, queries.world_from_cam, base)
                true_poses, source = queries.world_from_cam, queries.source_index
                what = "off-grid images localized against the map"
            # (its renders are not kept: the fitted model is what is cached, and its random tag
            # sets rarely recur in an evaluation)
            ctx = PredictContext(tb, map_base, codebook, cb_key, lcfg, imaging, folder, timings, keep_renders=False)
            preds = predict_placements(ctx, placements, {image_set.name: image_set})
            s, y, tagged = _pairs(data, covs, map_successes(preds, true_poses, set_name=image_set.name), sets, source)
            model = fit_success_model(s, y)
            log.info("calibration (%s, %s model): %d %s, %d of %d samples succeed (%d with tags); "
                     "P(success) = sigmoid(%.3f + %.3f s), AUC %.3f", name, conf.tag_model, len(true_poses), what,
                     int(y.sum()), len(y), int(tagged.sum()), model.intercept, model.slope, model.auc)
            return model

        model = cached(f"calibration {name}", run_dir / f"success_model_{name}.json", key, fit,
                       lambda m, p: write_json(p, m.to_json(), digits=None),  # exact: reruns reuse it
                       lambda p: SuccessModel.from_json(json.loads(Path(p).read_text())), data.timings,
                       # (not the in-view masks: each is a function of the key's inputs and of the markers
                       # of whoever wrote it last, and evaluate rewrites the map's with its own placements)
                       upstream=[folder / "map_base" / "features", folder / "vlad_codebook.npz",
                                 folder / "offgrid_base" / "features"])
        data.calibration[name] = {"model": model, "coverages": covs}


def score_outcomes(data, plan_config, placements, success: dict, models=("paper", "corners")) -> dict:
    """Per marker model: pooled (score, success, with tags) of the map images, without tags
    and with each placement of ``placements`` whose markers are candidates (others skipped).

    Args:
        data: the prepared plan.
        plan_config: the plan's settings.
        placements: evaluated :class:`~markerplace.simulation.marker_sets.PlacementRun` list.
        success: (method, run, k) -> (N,) map-image successes (:func:`map_successes`).
        models: marker model names.

    Returns:
        model name -> dict with ``score``, ``success``, ``tagged`` arrays and ``placements``
        (the (method, run, k) keys used).
    """
    sets = {}
    for p in placements:
        if p.method == NO_MARKERS or (p.method, p.run, p.k) not in success:
            continue
        cands = placement_candidates(p.markers, data.disc.candidate_world_from_marker, plan_config.placement.tag_size)
        if cands is None:
            log.info("calibration: %s k=%d run %d is not made of candidates; left out", p.method, p.k, p.run)
            continue
        sets[(p.method, p.run, p.k)] = cands
    out = {}
    for model in models:
        s, y, tagged = _pairs(data, coverages_with_model(data, model, plan_config.noise, plan_config.imaging.camera.K), success, sets)
        out[model] = {"score": s, "success": y, "tagged": tagged, "placements": list(sets)}
    return out
