"""Predicted recall against k, its knee, plan --target-recall, and the bounds a plan may print
(markerplace.plan.place.recall_curve, .bounds, .predicted; report.recall_section)."""

from __future__ import annotations

import itertools
import logging
from dataclasses import replace

import numpy as np
import pytest

from helpers.recall_problems import plan_data as _data
from helpers.recall_problems import problem as _problem
from helpers.recall_problems import success_model as _model
from markerplace.cli.main import build_parser
from markerplace.cli.options import plan_config_from_args
from markerplace.errors import UserError
from markerplace.plan.config import PlanConfig, validate
from markerplace.plan.place.config import K_ALL, PlacementConfig
from markerplace.plan.place.expected_recall import expected_localized, expected_recall_greedy
from markerplace.plan.place.greedy import apply_coverages
from markerplace.plan.place.predicted_recall import HOW_TO_GET, place_for_target, predicted_recall, score_bound, wants_success_model
from markerplace.plan.place.recall_curve import knee, recall_curve, target_count
from markerplace.plan.place.stage import place
from markerplace.plan.place.upper_bounds import per_pose_bound_scores, recall_upper_bound, score_upper_bound, submodularity_sample
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.success_model import SuccessModel
from markerplace.plan.types import MarkerCoverage
from markerplace.report.recall_section import recall_section


def test_curve_is_expected_recall_of_each_prefix():
    base, covs = _problem(1, C=8, E=2)
    model = _model(base)
    order = [5, 0, 7, 2]
    curve = recall_curve(base, covs[:8], order, model, existing=covs[8:])
    assert curve.shape == (5,)
    for j in range(5):
        info = apply_coverages(base, covs[8:] + [covs[m] for m in order[:j]])
        assert curve[j] == pytest.approx(expected_localized(info, model) / len(base), abs=1e-12)
    assert np.all(np.diff(curve) >= -1e-15)  # more information never lowers it


def test_knee_rule_and_target_count():
    assert knee(np.array([0.2, 0.3, 0.35, 0.355, 0.358])) == 2  # steps 10, 5, 0.5, 0.3 points
    assert knee(np.array([0.2, 0.201, 0.203])) is None  # no tag adds a point
    assert knee(np.array([0.2, 0.3, 0.302, 0.4])) == 3  # the last tag still adds: not flattened
    assert knee(np.array([0.2, 0.21])) == 1  # exactly one point counts
    curve = np.array([0.5, 0.6, 0.7, 0.75, 0.75, 0.75])
    assert target_count(curve, 0.7) == (2, True)
    assert target_count(curve, 0.55) == (1, True)
    assert target_count(curve, 0.4) == (1, True)  # already there: still one tag
    assert target_count(curve, 0.9) == (3, False)  # the later tags add nothing
    with pytest.raises(ValueError):
        target_count(np.array([0.5]), 0.9)


def test_expected_recall_greedy_stops_at_the_target_with_a_prefix():
    base, covs = _problem(2, N=50, C=12)
    model = _model(base, above=0.5)
    N = len(base)
    full = expected_recall_greedy(base, covs, 12, model)
    curve = recall_curve(base, covs, full.order, model)
    R = float(curve[4] + curve[5]) / 2  # reached by the 5th pick, not the 4th
    res = expected_recall_greedy(base, covs, 12, model, stop_at=R * N)
    assert res.order == full.order[:5] and len(res.gains) == 5
    # an unreachable target: it stops when nothing adds anything, or after every candidate
    res = expected_recall_greedy(base, covs, 12, model, stop_at=2.0 * N)
    assert res.order == full.order[:len(res.order)]
    assert len(res.order) == 12 or max(full.gains[len(res.order):]) <= 1e-9 * N


def test_bounds_hold_against_brute_force():
    """The per-pose bounds are >= the best k-set's value (exhaustive), for greedy and random S."""
    rng = np.random.default_rng(0)
    for seed in range(3):
        base, covs = _problem(seed, N=24, C=7, E=1)
        cands, ex = covs[:7], covs[7:]
        model = _model(base, above=1.0)
        for k in (1, 2, 3):
            best_r = max(recall_curve(base, cands, T, model, ex)[-1] for T in itertools.combinations(range(7), k))
            best_s = max(float(np.mean(-entropy(apply_coverages(base, ex + [cands[m] for m in T]))))
                         for T in itertools.combinations(range(7), k))
            greedy = expected_recall_greedy(base, cands, k, model, existing=ex).order
            for S in (greedy, list(rng.choice(7, size=int(rng.integers(0, 5)), replace=False))):
                assert recall_upper_bound(base, cands, S, k, model, ex) >= best_r - 1e-12
                plan, bound = score_upper_bound(base, cands, S, k, ex)
                assert bound >= best_s - 1e-9 and bound >= plan - 1e-12
            score, _ = per_pose_bound_scores(base, cands, greedy, k, ex)
            assert score == pytest.approx(-entropy(apply_coverages(base, ex + [cands[m] for m in greedy])))


def test_textbook_top_k_bound_fails_for_expected_recall_but_ours_holds():
    """One pose, two tags that each add 1 nat; the logistic is steep around base + 2 nats. From
    S = {} the textbook bound f(S) + two largest marginal gains is far below f({a, b})."""
    base = np.eye(6)[None] * 1.0
    M = (np.e ** (2.0 / 6) - 1.0) * np.eye(6)[None]  # 1/2 ln det(I + M) = 1 nat
    covs = [MarkerCoverage(np.array([0]), M), MarkerCoverage(np.array([0]), M)]
    s0 = float(-entropy(base)[0])
    model = SuccessModel(-8.0 * (s0 + 1.6), 8.0, 10, 5, 1.0, s0 - 10.0)
    f = lambda T: recall_curve(base, covs, list(T), model)[-1]  # noqa: E731
    textbook = f([]) + (f([0]) - f([])) + (f([1]) - f([]))
    assert f([0, 1]) > textbook + 0.5  # the textbook bound is no bound here
    assert recall_upper_bound(base, covs, [], 2, model) >= f([0, 1]) - 1e-12


def test_submodularity_is_violated_by_expected_recall_not_by_the_score_sum():
    base, covs = _problem(3, N=40, C=10)
    model = _model(base, slope=3.0, above=2.0)  # poses start in the convex part
    rng = np.random.default_rng(0)
    er = submodularity_sample(lambda T: recall_curve(base, covs, T, model)[-1], 10, 200, rng)
    score = submodularity_sample(lambda T: float(np.mean(-entropy(apply_coverages(base, [covs[m] for m in T])))),
                                 10, 200, rng)
    assert er["violations"] > 0 and er["worst"] > 0
    assert score["violations"] == 0 and score["ratio_min"] >= 1.0 - 1e-9


def test_place_for_target_cuts_the_plan_and_says_when_it_cannot(caplog):
    data = _data(4, N=50, C=12, above=0.5)
    for method in ("omp", "expected-recall"):
        conf = PlacementConfig(method=method, k=K_ALL, target_recall=0.5)
        full = place_for_target(data, replace(conf, target_recall=1.0), progress=False)[0]
        curve = recall_curve(data.base_info, data.coverages, full.candidates, data.calibration[conf.recall_model]["model"])
        R = float(curve[2] + curve[3]) / 2
        placement, info = place_for_target(data, replace(conf, target_recall=R), progress=False)
        assert info["reached"] and info["tags"] == 3 and len(placement.markers) == 3
        assert list(placement.candidates) == list(full.candidates[:3])
        with caplog.at_level(logging.WARNING):
            caplog.clear()
            placement, info = place_for_target(data, replace(conf, target_recall=1.0), progress=False)
        assert not info["reached"] and info["limit"] == "with the candidates"
        assert len(placement.markers) == info["best_tags"] and info["best_recall"] < 1.0
        assert "not reachable" in caplog.text and f"{info['best_tags']} tags" in caplog.text
        _, info = place_for_target(data, replace(conf, k=2, target_recall=1.0), progress=False)
        assert info["limit"] == "within -k 2 tags" and info["tags"] <= 2


def test_predicted_recall_and_score_bound_objects():
    data = _data(5, N=40, C=9, E=1)
    conf = PlacementConfig(method="omp", k=4)
    placement = place(data, conf, progress=False)
    pr = predicted_recall(data, placement, conf)
    K = len(placement.candidates)
    assert pr["available"] and pr["k"] == list(range(K + 1)) and len(pr["recall"]) == K + 1
    assert pr["upper_bound"]["recall"] >= pr["upper_bound"]["plan_recall"] == pr["recall"][-1]
    assert pr["marker_model"] == "corners" and pr["target"] is None
    sb = score_bound(data, placement)
    assert sb["mean_score_upper_bound"] >= sb["mean_score_plan"] >= sb["mean_score_existing"]
    html = recall_section({"predicted_recall": pr, "score_bound": sb})
    assert "<svg" in html and "Upper bound" in html and "predicted recall" in html
    none = predicted_recall(replace(data, calibration={}), placement, conf)
    assert none == {"available": False, "how": HOW_TO_GET}
    html = recall_section({"predicted_recall": none, "score_bound": sb})
    assert "--recall-curve" in html and "<svg" not in html
    assert recall_section({}) == ""


def test_settings_target_recall_and_recall_curve(tmp_path):
    with pytest.raises(UserError, match="--target-recall 0 must be above 0"):
        validate(PlanConfig(placement=PlacementConfig(target_recall=0.0)))
    with pytest.raises(UserError, match="--target-recall needs a method .* not --method random"):
        validate(PlanConfig(placement=PlacementConfig(method="random", target_recall=0.9)))
    validate(PlanConfig(placement=PlacementConfig(method="expected-recall", target_recall=1.0)))
    assert not wants_success_model(PlacementConfig())
    assert wants_success_model(PlacementConfig(recall_curve=True))
    assert wants_success_model(PlacementConfig(target_recall=0.9))
    assert wants_success_model(PlacementConfig(method="expected-recall"))
    parse = build_parser().parse_args
    assert plan_config_from_args(parse(["plan", "room", "--out", "x", "--target-recall", "0.9"])).placement.k == K_ALL
    conf = plan_config_from_args(parse(["plan", "room", "--out", "x", "--target-recall", "0.9", "-k", "7"])).placement
    assert conf.k == 7 and conf.target_recall == 0.9
    assert plan_config_from_args(parse(["plan", "room", "--out", "x"])).placement.k == 20
    assert plan_config_from_args(parse(["plan", "room", "--out", "x", "--recall-curve"])).placement.recall_curve
    toml = tmp_path / "site.toml"
    toml.write_text("[placement]\ntarget_recall = 0.8\n")
    assert plan_config_from_args(parse(["plan", "room", "--out", "x", "--config", str(toml)])).placement.k == K_ALL
    toml.write_text("[placement]\ntarget_recall = 0.8\nk = 9\n")
    assert plan_config_from_args(parse(["plan", "room", "--out", "x", "--config", str(toml)])).placement.k == 9
    toml.write_text("[placement]\nv = 80.0\n")
    assert plan_config_from_args(parse(["plan", "room", "--out", "x", "--config", str(toml)])).placement.k == 20


def test_weighted_curve_bounds_and_expected_recall() -> None:
    """Pose weights (plan --where): an indicator weight scaled to sum to N gives the curve, the
    bounds and the expected-recall objective of the weighted poses alone."""
    base, covs = _problem(seed=3, N=40, C=10)
    model = SuccessModel(-0.5 * float(np.median(-entropy(base))), 0.5, 100, 50, 0.8, 0.0)
    keep = np.arange(40) % 3 == 0
    w = keep * (40 / keep.sum())
    order = [2, 5, 7]
    sub = [MarkerCoverage(np.searchsorted(np.flatnonzero(keep), c.pose_idx[keep[c.pose_idx]]),
                          c.info[keep[c.pose_idx]]) for c in covs]
    np.testing.assert_allclose(recall_curve(base, covs, order, model, weights=w),
                               recall_curve(base[keep], sub, order, model))
    assert recall_upper_bound(base, covs, order, 3, model, weights=w) == pytest.approx(
        recall_upper_bound(base[keep], sub, order, 3, model))
    np.testing.assert_allclose(score_upper_bound(base, covs, order, 3, weights=w),
                               score_upper_bound(base[keep], sub, order, 3))
    res, ref = expected_recall_greedy(base, covs, 3, model, weights=w), expected_recall_greedy(base[keep], sub, 3, model)
    assert res.order == ref.order
    np.testing.assert_allclose(np.asarray(res.gains) * keep.sum() / 40, ref.gains, rtol=1e-9)
    assert expected_localized(base, model, w) == pytest.approx(expected_localized(base[keep], model) * 40 / keep.sum())
