"""What a plan predicts: recall against the number of tags, a recall target, and valid bounds.

The success model is the one the plan's ``recall_model`` fits (a calibrated method, default
``expected-recall``: :func:`markerplace.simulation.success_fit.calibrate_plan`, map images only, the
method's ``tag_model``, ``corners``). A plan fits it when :func:`wants_success_model` says so: the method is
calibrated, ``--target-recall`` is given or ``--recall-curve`` asks for it; otherwise the
predicted-recall part of ``placement.json`` says how to get it (:data:`HOW_TO_GET`).

* :func:`place_for_target`: ``plan --target-recall R`` (the plan's method, nested, placed with
  the most tags allowed, then cut at the first prefix whose predicted recall reaches R).
* :func:`marker_set_curve`: R(0..k) of any candidates in any order under any pose weights
  (``evaluate --predicted`` sets each evaluated placement against its test sets with it).
* :func:`predicted_recall`: the curve R(0..k) of the plan's own order, its knee
  (:mod:`markerplace.plan.place.recall_curve`) and an upper bound on the predicted recall of any
  k candidates (:func:`markerplace.plan.place.upper_bounds.recall_upper_bound`).
* :func:`score_bound`: the plan's mean score and an upper bound on any k candidates' (every
  plan: no model needed).
"""

from __future__ import annotations

import logging
from dataclasses import replace
from typing import Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.markers import Marker, free_tag_ids
from markerplace.plan.place.config import PlacementConfig
from markerplace.plan.place.methods import PLACEMENT_METHODS, method_conf
from markerplace.plan.place.recall_curve import KNEE_POINTS, knee, recall_curve, target_count
from markerplace.plan.place.stage import place
from markerplace.plan.place.upper_bounds import recall_upper_bound, score_upper_bound
from markerplace.plan.types import Placement, PlanData

log = logging.getLogger(__name__)

__all__ = ["HOW_TO_GET", "KNEE_RULE", "marker_set_curve", "place_for_target", "predicted_recall",
           "score_bound", "wants_success_model"]

HOW_TO_GET = ("no success model was fitted for this plan: run plan again with --recall-curve (or --method "
              "expected-recall, or --target-recall R) to fit it on the map images and get the predicted recall "
              "against the number of tags; the cached stages are reused, the calibration renders and localizes "
              "the map images once")
"""Why a plan has no recall curve and how to get one (placement.json, report.html)."""

KNEE_RULE = (f"the knee is the last tag that adds at least {KNEE_POINTS:g} percentage point of predicted recall; "
             "every later tag adds less")

BOUND_WORDS = ("no set of k candidates can reach a higher predicted recall (with the existing tags, under the same "
               "model): per pose, score with the plan plus the k largest score gains given the plan, capped at the "
               "score with every candidate; valid because each pose's score is submodular and P increasing "
               "(the expected-recall objective itself is not submodular, docs/design.md section 6c)")


def wants_success_model(config: PlacementConfig) -> bool:
    """Whether a plan with ``config`` fits the success model (calibration renders and localizes
    the map images): a calibrated method, ``target_recall`` or ``recall_curve``."""
    return (PLACEMENT_METHODS.lookup(config.method).calibrated or config.target_recall is not None
            or config.recall_curve)


def model_methods(config: PlacementConfig) -> list[str]:
    """The methods to calibrate for a plan: its own, plus ``config.recall_model`` when it wants the model."""
    return [config.method] + ([config.recall_model] if wants_success_model(config) else [])


def marker_set_curve(data: PlanData, order: Sequence[int], weights: np.ndarray | None, model: str) -> np.ndarray:
    """(K + 1,) predicted recall R(0..K) after the first j candidates of ``order`` (indices, any
    order) under the success model fitted for the calibrated method ``model`` (the plan's
    ``recall_model``; ``data.calibration[model]``, which must be there), existing markers
    included, each pose weighted by ``weights`` ((N,) summing to N, or None: every pose 1). A
    plan's own curve is this with its order and ``data.pose_weight``."""
    fit = data.calibration[model]
    covs, C = fit["coverages"], data.num_candidates
    return recall_curve(data.base_info, covs[:C], np.asarray(order, dtype=np.int64), fit["model"], covs[C:], weights)


def _curve(data: PlanData, order: np.ndarray, config: PlacementConfig) -> np.ndarray:
    return marker_set_curve(data, order, data.pose_weight, config.recall_model)


def place_for_target(data: PlanData, config: PlacementConfig, existing: Sequence[Marker] = (),
                     progress: bool = True) -> tuple[Placement, dict]:
    """Place tags until the predicted recall reaches ``config.target_recall``.

    The method (nested) places the most tags allowed, ``min(k, candidates, free tag ids)``
    (``expected-recall`` stops by itself at the target or when nothing adds anything); the plan
    is its first j tags, j the smallest reaching the target, else the smallest reaching the
    highest predicted recall of those tags (the later ones add nothing). One log line says which.

    Returns:
        the placement and a JSON-ready dict: ``target``, ``reached``, ``tags`` (j),
        ``best_recall`` and ``best_tags`` (the highest predicted recall of the tags placed and
        how many first reach it), ``most_tags`` and ``limit`` (what bounded the search, words).

    Raises:
        UserError: no tag id or candidate is free.
    """
    R = float(config.target_recall)
    C = data.num_candidates
    free = free_tag_ids(list(existing), config.first_tag_id)
    most = min(int(config.k), C, free)
    if most < 1:
        raise UserError(f"--target-recall: no tag can be placed ({C} candidates, {max(free, 0)} free tag ids)")
    limit = (f"within -k {config.k} tags" if most == config.k and most < C else
             f"within the {free} free tag ids" if most == free and most < C else "with the candidates")
    first = place(data, replace(config, k=most), existing, progress)
    curve = _curve(data, first.candidates, config)
    j, reached = target_count(curve, R)
    best_tags = target_count(curve, 2.0)[0]  # the smallest prefix at the maximum
    info = {"target": R, "reached": reached, "tags": j, "best_recall": float(curve[1:].max()),
            "best_tags": best_tags, "most_tags": most, "limit": limit}
    if reached:
        log.info("target recall %.1f %% reached with %d tags (predicted %.1f %%)", 100 * R, j, 100 * curve[j])
    else:
        log.warning("target recall %.1f %% not reachable %s: the best predicted recall is %.1f %% with %d tags; "
                    "placing those", 100 * R, limit, 100 * info["best_recall"], best_tags)
    placement = first if j == len(first.candidates) else place(data, replace(config, k=j), existing, False)
    return placement, info


def predicted_recall(data: PlanData, placement: Placement, config: PlacementConfig,
                     target: dict | None = None) -> dict:
    """The ``predicted_recall`` object of placement.json.

    With the success model fitted (``data.calibration[config.recall_model]``): ``available`` true,
    ``model`` (its JSON), ``marker_model``, ``k`` [0..K] and ``recall`` R(0..K) (shares) of the
    plan's order, ``knee`` (int or None) with ``knee_rule``, ``upper_bound`` (``k``, ``recall``:
    the bound of any K candidates, ``plan_recall``, ``what``) and ``target``
    (:func:`place_for_target`'s dict, or None). Without it: ``available`` false and ``how``.
    """
    fit = data.calibration.get(config.recall_model)
    if fit is None:
        return {"available": False, "how": HOW_TO_GET}
    order = np.asarray(placement.candidates, dtype=np.int64)
    curve = _curve(data, order, config)
    covs, C, K = fit["coverages"], data.num_candidates, len(order)
    bound = recall_upper_bound(data.base_info, covs[:C], order, K, fit["model"], covs[C:], data.pose_weight)
    return {"available": True, "model": fit["model"].to_json(),
            "marker_model": method_conf(config.recall_model, config).tag_model,
            "k": list(range(K + 1)), "recall": [round(float(r), 6) for r in curve],
            "knee": knee(curve), "knee_rule": KNEE_RULE,
            "upper_bound": {"k": K, "recall": round(max(bound, float(curve[-1])), 6),
                            "plan_recall": round(float(curve[-1]), 6), "what": BOUND_WORDS},
            "target": target}


def score_bound(data: PlanData, placement: Placement) -> dict:
    """The ``score_bound`` object of placement.json (the plan's marker model): ``k``, the mean
    score (nats) with the existing tags only (``mean_score_existing``), with the plan
    (``mean_score_plan``) and ``mean_score_upper_bound`` of any k candidates (the score sum is
    monotone submodular: :func:`markerplace.plan.place.upper_bounds.score_upper_bound`)."""
    C = data.num_candidates
    order = np.asarray(placement.candidates, dtype=np.int64)
    existing = data.coverages[C:]
    before, _ = score_upper_bound(data.base_info, data.coverages[:C], [], 0, existing, data.pose_weight)
    plan, bound = score_upper_bound(data.base_info, data.coverages[:C], order, len(order), existing,
                                    data.pose_weight)
    return {"k": len(order), "mean_score_existing": before, "mean_score_plan": plan,
            "mean_score_upper_bound": max(bound, plan)}
