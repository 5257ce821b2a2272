"""Does the localizability score predict localization? Map images localized against the rest of
the map, and the success model fitted on them.

Each map image (a feasible pose) is localized by the testbed's localizer against the map
without the images of its own camera location (leave-one-location-out: the nearest map images
left are a grid step away, as for a test image), without markers and with the markers of a
tag set in view (re-rendered, as the testbed does). A success is an estimate within the main
recall threshold (5 cm, 5 deg) of the image's true pose. Only map images take part: test images
never touch a fit.

* :func:`calibrate_plan` fills ``PlanData.calibration`` for every calibrated placement method
  (``expected-recall``): the map images are localized without tags and with
  ``calibration_runs`` seeded random sets of ``calibration_k`` candidate tags, and a
  :class:`~markerplace.plan.success_model.SuccessModel` is fitted on the pairs (score under the
  method's marker model, success): every map image without tags, plus with each set the images
  whose score the set changes. Cached in the plan folder (``calibration/``,
  ``success_model_<method>.json``).
* :func:`score_outcomes` gives, for ``evaluate --calibration``, the same pairs for every evaluated
  placement made of candidates and for each marker model, from which
  :mod:`markerplace.report.calibration_report` draws calibration curves and AUCs.

Existing markers (``plan --existing``) are left out of the calibration renders.
"""

from __future__ import annotations

import json
import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..imaging.config import SIFT_DEFAULT
from ..imaging.engine import marker_key
from ..io_utils import write_json
from ..markers import FAMILY, Marker
from ..runtime import cache
from ..runtime.stages import cached
from .images import BaseImages, TestbedImaging
from .metrics import MAIN_THRESHOLD, hit_mask, pose_errors_batch
from .placements import NO_MARKERS, PlacementRun
from .predict import ImageSet, predict_placements

log = logging.getLogger(__name__)

__all__ = ["map_image_set", "map_successes", "placement_candidates", "scores_with", "calibrate_plan",
           "score_outcomes"]

MAP_SET = "map"
"""Name of the map images' :class:`~markerplace.testbed.predict.ImageSet`."""


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


def map_successes(predictions: dict, map_poses: np.ndarray, threshold=MAIN_THRESHOLD) -> dict:
    """(method, run, k) -> (N,) bool: map images localized within ``threshold`` (metres, deg)."""
    out = {}
    for (method, run, k, name), est in predictions.items():
        if name == MAP_SET:
            out[(method, run, k)] = hit_mask(*pose_errors_batch(est, map_poses), *threshold)
    return out


def placement_candidates(markers, candidate_world_from_marker: np.ndarray, atol: float = 1e-9) -> np.ndarray | None:
    """(k,) candidate index of each marker (its pose equals the candidate's), or None when some
    marker is not a candidate (a placement file, a shifted tag)."""
    cands = np.asarray(candidate_world_from_marker, float).reshape(-1, 16)
    out = []
    for m in markers:
        d = np.abs(cands - np.asarray(m.world_from_marker, float).reshape(1, 16)).max(axis=1)
        j = int(np.argmin(d)) if len(d) else -1
        if j < 0 or d[j] > atol:
            return None
        out.append(j)
    return np.asarray(out, dtype=np.int64)


def scores_with(data, coverages: list, candidates: np.ndarray) -> np.ndarray:
    """(N,) score ``-H`` of every pose with the given candidates' tags (``coverages``: per
    candidate, e.g. under another marker model; existing markers not added)."""
    from ..plan.localizability import entropy
    from ..plan.placement import apply_coverages

    return -entropy(apply_coverages(data.base_info, [coverages[int(c)] for c in candidates]))


def _pairs(data, coverages, success: dict, sets: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pooled (score, success, with tags) of the map images: all of them without tags, and with
    each tag set those whose score it changes. ``sets``: (method, run, k) -> candidates."""
    base = np.asarray(data.base_score, float)
    s, y, tagged = [base], [success[(NO_MARKERS, 0, 0)]], [np.zeros(len(base), bool)]
    for key, cands in sets.items():
        if key not in success or cands is None:
            continue
        sc = scores_with(data, coverages, cands)
        changed = sc != base
        s.append(sc[changed])
        y.append(success[key][changed])
        tagged.append(np.ones(int(changed.sum()), bool))
    return np.concatenate(s), np.concatenate(y).astype(bool), np.concatenate(tagged)


def _imaging(plan_config):
    return replace(plan_config.imaging, sift=SIFT_DEFAULT)


def _localizer_spec(seed: int) -> tuple:
    return "sift_pnp", (("use_tags", True), ("tag_corners", False), ("seed", int(seed)))


def calibrate_plan(scene_spec, data, plan_config, run_dir: str | Path, executor, methods=None,
                   progress: bool = True) -> None:
    """Fill ``data.calibration[name]`` (the fitted model and the method's coverages) for every
    calibrated method in ``methods`` (names; default ``plan_config.placement.method``).

    Args:
        scene_spec: the scene.
        data: the prepared plan (:func:`markerplace.plan.planner.prepare`); updated in place.
        plan_config: the plan's settings.
        run_dir: the plan folder (``calibration/`` and ``success_model_<method>.json`` go here).
        executor: where renders and localizations run.
        methods: placement method names about to be placed.
        progress: progress bars.
    """
    from ..localization.vlad import VladCodebook
    from ..plan.methods import PLACEMENT_METHODS, get_placement_method
    from ..plan.planner import coverages_with_model
    from ..plan.success_model import SuccessModel, fit_success_model

    names = [plan_config.placement.method] if methods is None else list(methods)
    run_dir = Path(run_dir)
    for name in dict.fromkeys(names):
        cls = PLACEMENT_METHODS.get(name)
        if cls is None or not cls.calibrated or name in data.calibration:
            continue
        conf = get_placement_method(name).conf
        covs = coverages_with_model(data, plan_config, conf.tag_model)
        C = data.num_candidates
        kc = min(C, int(conf.calibration_k))
        rng = np.random.default_rng(conf.calibration_seed)
        sets = {("calibration", r, kc): np.sort(rng.choice(C, size=kc, replace=False)) for r in range(conf.calibration_runs)}
        imaging = _imaging(plan_config)
        lcfg = _localizer_spec(conf.calibration_seed)
        map_poses = np.asarray(data.disc.world_from_cam, float)
        base_key = cache.hash_of("calibration-v1", cache.scene_hash(scene_spec.load()), map_poses, imaging)
        key = cache.hash_of(base_key, data.base_score, conf, plan_config.noise, [cv.pose_idx for cv in covs],
                            data.disc.location_index, MAIN_THRESHOLD)

        def fit() -> SuccessModel:
            placements = [PlacementRun(NO_MARKERS, 0, 0, ())]
            for (m, r, k), cands in sets.items():
                placements.append(PlacementRun(m, r, k, tuple(
                    Marker(i, plan_config.placement.tag_size, data.disc.candidate_world_from_marker[c].copy(), FAMILY)
                    for i, c in enumerate(cands))))
            union = list({marker_key(mk): mk for p in placements for mk in p.markers}.values())
            tb = TestbedImaging(scene_spec, imaging, union, executor, progress)
            folder = run_dir / "calibration"
            map_base = BaseImages(tb, map_poses, folder / "map_base", base_key, True, "calibration map")
            timings: dict = {}
            cb_key = cache.hash_of("vlad-v1", base_key, 64, conf.calibration_seed)
            codebook = cached("vlad_codebook", folder / "vlad_codebook.npz", cb_key,
                              lambda: VladCodebook.train(np.asarray(map_base.features.descriptors, np.float32),
                                                         num_clusters=64, seed=conf.calibration_seed),
                              lambda cb, p: cb.save(p), VladCodebook.load, timings)
            image_set = map_image_set(map_base, data.disc.location_index)
            preds = predict_placements(tb, placements, map_base, {MAP_SET: image_set}, codebook, cb_key, lcfg,
                                       imaging, folder, timings)
            s, y, tagged = _pairs(data, covs, map_successes(preds, map_poses), sets)
            model = fit_success_model(s, y)
            log.info("calibration (%s, %s model): %d map images localized against the rest of the map, %d of %d "
                     "samples succeed (%d with tags); P(success) = sigmoid(%.3f + %.3f s), AUC %.3f", name,
                     conf.tag_model, len(map_poses), int(y.sum()), len(y), int(tagged.sum()), model.intercept,
                     model.slope, model.auc)
            return model

        model = cached(f"calibration {name}", run_dir / f"success_model_{name}.json", key, fit,
                       lambda m, p: write_json(p, m.to_json()),
                       lambda p: SuccessModel.from_json(json.loads(Path(p).read_text())),
                       data.timings)
        data.calibration[name] = {"model": model, "coverages": covs}


def score_outcomes(data, plan_config, placements, success: dict, models=("paper", "corners")) -> dict:
    """Per marker model: pooled (score, success, with tags) of the map images, without tags
    and with each placement of ``placements`` whose markers are candidates (others skipped).

    Args:
        data: the prepared plan.
        plan_config: the plan's settings.
        placements: evaluated :class:`~markerplace.testbed.placements.PlacementRun` list.
        success: (method, run, k) -> (N,) map-image successes (:func:`map_successes`).
        models: marker model names.

    Returns:
        model name -> dict with ``score``, ``success``, ``tagged`` arrays and ``placements``
        (the (method, run, k) keys used).
    """
    from ..plan.planner import coverages_with_model

    sets = {}
    for p in placements:
        if p.method == NO_MARKERS or (p.method, p.run, p.k) not in success:
            continue
        cands = placement_candidates(p.markers, data.disc.candidate_world_from_marker)
        if cands is None:
            log.info("calibration: %s k=%d run %d is not made of candidates; left out", p.method, p.k, p.run)
            continue
        sets[(p.method, p.run, p.k)] = cands
    out = {}
    for model in models:
        s, y, tagged = _pairs(data, coverages_with_model(data, plan_config, model), success, sets)
        out[model] = {"score": s, "success": y, "tagged": tagged, "placements": list(sets)}
    return out
