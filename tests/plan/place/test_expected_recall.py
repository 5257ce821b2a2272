"""Success model (logistic fit, AUC, calibration) and the expected-recall greedy."""

from __future__ import annotations

import json
import logging
import warnings

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.plan.place.expected_recall import expected_localized, expected_recall_greedy
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.success_model import SuccessModel, calibration_curve, fit_success_model, roc_auc, sigmoid
from markerplace.plan.types import MarkerCoverage

# --------------------------------------------------------------------------------------------
# Success model
# --------------------------------------------------------------------------------------------


def test_fit_recovers_known_logistic() -> None:
    rng = np.random.default_rng(0)
    n = 20000
    for a, b, mu, sd in [(-3.0, 0.7, 5.0, 2.0), (2.0, 1.5, -1.0, 1.0)]:
        s = rng.normal(mu, sd, n)
        y = rng.random(n) < sigmoid(a + b * s)
        m = fit_success_model(s, y)
        # Standard errors here are ~0.06 (intercept) and ~0.01-0.03 (slope).
        assert m.intercept == pytest.approx(a, abs=0.2)
        assert m.slope == pytest.approx(b, abs=0.08)
        assert m.n == n and m.successes == int(y.sum())
        assert m.auc == pytest.approx(roc_auc(s, y))
        assert m.score_floor == pytest.approx(s.min() - 1.0)
        # The fit is the maximum likelihood: the score equations hold (ridge is negligible).
        r = y - m.probability(s)
        assert abs(r.mean()) < 1e-6 and abs((r * (s - s.mean())).mean()) < 1e-3


def test_fit_separable_one_class_negative(caplog: pytest.LogCaptureFixture) -> None:
    rng = np.random.default_rng(1)
    s = rng.normal(0.0, 1.0, 300)
    m = fit_success_model(s, s > 0.2)
    assert np.isfinite(m.intercept) and np.isfinite(m.slope) and m.slope > 0
    assert m.auc == 1.0
    # The midpoint falls in the gap between the classes, and the classes are well separated.
    mid = -m.intercept / m.slope
    assert s[s <= 0.2].max() - 1e-9 <= mid <= s[s > 0.2].min() + 1e-9
    assert np.all(m.probability(s[s > 0.2]) > 0.5) and np.all(m.probability(s[s <= 0.2]) < 0.5)

    with caplog.at_level(logging.WARNING):
        caplog.clear()
        one = fit_success_model(s, np.ones(300, bool))
        assert one.slope == 0.0 and one.successes == 300 and np.isnan(one.auc)
        assert one.intercept == pytest.approx(np.log(0.999 / 0.001))
        assert "constant" in caplog.text
        zero = fit_success_model(s, np.zeros(300, bool))
        assert zero.slope == 0.0 and zero.intercept == pytest.approx(-np.log(0.999 / 0.001))
        caplog.clear()
        y = rng.random(300) < sigmoid(-2.0 * s)  # success falls with the score
        neg = fit_success_model(s, y)
        assert neg.slope == 0.0 and "negative" in caplog.text
        assert neg.intercept == pytest.approx(np.log(y.mean() / (1 - y.mean())))
        flat = fit_success_model(np.full(10, 3.0), np.arange(10) < 4)  # no score variation
        assert flat.slope == 0.0 and flat.probability(np.array([3.0]))[0] == pytest.approx(0.4)
    for bad in [(np.array([1.0]), np.array([True])), (np.zeros(3), np.zeros(2, bool))]:
        with pytest.raises(ValueError):
            fit_success_model(*bad)
    with pytest.raises(ValueError):
        fit_success_model(s, s > 0, ridge=0.0)


def test_probability_nonfinite_stable_and_json() -> None:
    s = np.array([np.nan, -np.inf, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
    y = np.array([0, 0, 0, 1, 0, 1, 1, 1], bool)
    m = fit_success_model(s, y)
    assert m.score_floor == -1.0
    p = m.probability(s)
    assert p[0] == p[1] == m.probability(np.array([-1.0]))[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        big = SuccessModel(0.0, 1.0, 2, 1, 0.5, 0.0)
        x = np.array([-1e308, -800.0, -40.0, 0.0, 40.0, 800.0, 1e308])
        p = big.probability(x)
        assert np.all(np.isfinite(p)) and p[0] == 0.0 and p[-1] == 1.0 and p[3] == 0.5
        assert np.all(np.diff(p) >= 0)
        d = big.probability_increase(x, np.full(x.shape, 1.0))
        assert np.all(np.isfinite(d)) and np.all(d >= 0)
    # probability_increase equals the plain difference, and keeps precision near 1.
    x = np.linspace(-10, 10, 41)
    g = np.linspace(0, 3, 41)
    np.testing.assert_allclose(big.probability_increase(x, g),
                               big.probability(x + g) - big.probability(x), atol=1e-15)
    assert big.probability_increase(np.array([40.0]), np.array([1.0]))[0] == pytest.approx(
        np.exp(-40.0) * (1 - np.exp(-1.0)), rel=1e-12)
    for model in [m, SuccessModel(0.1, 0.0, 5, 5, float("nan"), -3.0)]:
        d = json.loads(json.dumps(model.to_json(), allow_nan=False))
        back = SuccessModel.from_json(d)
        for f in ["intercept", "slope", "n", "successes", "score_floor"]:
            assert getattr(back, f) == getattr(model, f)
        assert back.auc == model.auc or (np.isnan(back.auc) and np.isnan(model.auc))
    assert SuccessModel.from_json(m.to_json()) == m
    with pytest.raises(ValueError):
        SuccessModel.from_json({"intercept": 0.0})
    with pytest.raises(ValueError):
        SuccessModel(0.0, -1.0, 2, 1, 0.5, 0.0)


def test_roc_auc_brute_force_and_calibration() -> None:
    rng = np.random.default_rng(2)
    for trial in range(20):
        n = int(rng.integers(2, 60))
        s = np.round(rng.normal(size=n), 1)  # many ties
        if trial % 3 == 0:
            s[rng.random(n) < 0.2] = -np.inf
            s[rng.random(n) < 0.1] = np.nan
        y = rng.random(n) < 0.4
        pos = np.where(np.isfinite(s), s, -np.inf)
        a, b = pos[y], pos[~y]
        if len(a) == 0 or len(b) == 0:
            assert np.isnan(roc_auc(s, y))
            continue
        gt = (a[:, None] > b[None, :]).sum() + 0.5 * (a[:, None] == b[None, :]).sum()
        assert roc_auc(s, y) == pytest.approx(gt / (len(a) * len(b)), abs=1e-12)
        cal = calibration_curve(s, y, bins=int(rng.integers(1, 12)))
        assert cal["count"].sum() == n and np.all(cal["count"] > 0)
        assert np.all(np.diff(cal["score_mean"]) > 0)
        assert np.all((cal["success_rate"] >= 0) & (cal["success_rate"] <= 1))
        assert (cal["success_rate"] * cal["count"]).sum() == pytest.approx(y.sum())
    s = np.arange(100.0)
    cal = calibration_curve(s, s >= 50, bins=4)
    assert cal["count"].tolist() == [25, 25, 25, 25]
    assert cal["success_rate"].tolist() == [0.0, 0.0, 1.0, 1.0]
    assert roc_auc(s, s >= 50) == 1.0 and roc_auc(s, s < 50) == 0.0
    assert roc_auc(np.ones(6), np.arange(6) < 3) == 0.5
    with pytest.raises(ValueError):
        calibration_curve(s, s > 3, bins=0)


# --------------------------------------------------------------------------------------------
# Expected-recall greedy
# --------------------------------------------------------------------------------------------


def random_problem(rng: np.random.Generator, N: int, C: int, max_cov: int):
    """Random SPD base information and PSD coverages, as tests/plan/place/test_greedy.py builds them."""
    A = rng.normal(size=(N, 6, 8))
    base = A @ A.transpose(0, 2, 1) * 10.0 + 100.0 * np.eye(6)
    covs = []
    for _ in range(C):
        n = int(rng.integers(0, max_cov + 1))
        idx = np.sort(rng.choice(N, n, replace=False))
        B = rng.normal(size=(n, 6, int(rng.integers(2, 7))))
        covs.append(MarkerCoverage(idx, B @ B.transpose(0, 2, 1) * 10.0 ** rng.uniform(0, 3)))
    return base, covs


def centred_model(base: np.ndarray, slope: float) -> SuccessModel:
    """A model whose midpoint lies one nat above the median base score (both logistic halves)."""
    mid = float(np.median(-entropy(base))) + 1.0
    return SuccessModel(-slope * mid, slope, 100, 50, 0.8, 0.0)


def naive_objective(lam: np.ndarray, model: SuccessModel) -> float:
    return float(np.sum(model.probability(-entropy(lam))))


@pytest.mark.parametrize("seed", range(8))
def test_greedy_equals_naive_reference(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    N = int(rng.integers(30, 50))
    C = int(rng.integers(6, 10))
    base, covs = random_problem(rng, N, C, max_cov=N // 2)
    model = centred_model(base, slope=[0.5, 1.0, 2.0, 4.0][seed % 4])
    k = C if seed % 2 else int(rng.integers(1, C + 1))
    seen = []
    res = expected_recall_greedy(base, covs, k, model,
                                 progress=lambda i, kk, m, g: seen.append((i, kk, m, g)))
    lam = base.copy()
    f_prev = naive_objective(lam, model)
    assert expected_localized(lam, model) == pytest.approx(f_prev, rel=1e-14)
    for step, m in enumerate(res.order):
        vals = np.full(C, -np.inf)
        for c, cov in enumerate(covs):
            if c in res.order[:step]:
                continue
            trial = lam.copy()
            trial[cov.pose_idx] += cov.info
            vals[c] = naive_objective(trial, model) - f_prev
        best = np.max(vals)
        # The pick is the naive argmax (ties to the smallest index, up to rounding of sums).
        assert vals[m] >= best - 1e-10
        assert m == int(np.flatnonzero(vals >= best - 1e-10)[0])
        assert res.gains[step] == pytest.approx(vals[m], rel=1e-9, abs=1e-11)
        mean_gain = np.sum(entropy(lam[covs[m].pose_idx])
                                 - entropy(lam[covs[m].pose_idx] + covs[m].info)) / N
        assert res.mean_gains[step] == pytest.approx(mean_gain, rel=1e-9, abs=1e-12)
        lam[covs[m].pose_idx] += covs[m].info
        f_new = naive_objective(lam, model)
        assert f_new >= f_prev - 1e-12 and res.gains[step] >= 0.0
        f_prev = f_new
    assert len(set(res.order)) == k and res.eligible == [True] * k and np.isnan(res.q)
    assert res.evaluations == sum(C - i for i in range(k))
    np.testing.assert_allclose(res.info_after, lam)
    assert [(i, kk, m) for i, kk, m, _ in seen] == [(i, k, m) for i, m in enumerate(res.order)]
    assert [g for *_, g in seen] == res.gains


def test_mean_gain_uses_half_logdet() -> None:
    """mean_gains is in nats: 1/2 ln det ratio, i.e. the entropy decrease, averaged over N."""
    base = np.tile(np.eye(6), (4, 1, 1))
    cov = MarkerCoverage(np.array([0, 2]), np.tile(np.diag([np.e**2 - 1] * 6), (2, 1, 1)))
    res = expected_recall_greedy(base, [cov], 1, SuccessModel(0.0, 1.0, 2, 1, 0.5, 0.0))
    assert res.mean_gains[0] == pytest.approx(2 * 6.0 / 4)  # 1/2 * 6 * ln e^2 per seeing pose


def test_existing_ties_and_errors() -> None:
    rng = np.random.default_rng(7)
    base, covs = random_problem(rng, 40, 8, max_cov=20)
    model = centred_model(base, 1.0)
    res = expected_recall_greedy(base, covs, 3, model)
    first = res.order[0]
    # An existing marker changes the base: same result as starting from the augmented base.
    ex = expected_recall_greedy(base, covs, 3, model, existing=[covs[first]])
    lam = base.copy()
    lam[covs[first].pose_idx] += covs[first].info
    ref = expected_recall_greedy(lam, covs, 3, model)
    assert ex.order == ref.order and ex.gains == ref.gains
    np.testing.assert_array_equal(ex.info_after, ref.info_after)
    # The marker already present gains less when placed again (it is still a candidate).
    g_again = ex.gains[ex.order.index(first)] if first in ex.order else 0.0
    assert g_again < res.gains[0]
    # Exact ties (duplicate coverages, empty coverages) go to the smallest index.
    dup = [covs[first], MarkerCoverage(np.zeros(0, int), np.zeros((0, 6, 6))), covs[first]]
    r = expected_recall_greedy(base, dup, 3, model)
    assert r.order[0] == 0 and r.gains[0] == res.gains[0]
    # A constant model (slope 0): nothing gains; picks go by the mean information gain (not
    # blindly in index order, which could put every tag on one wall).
    flat = SuccessModel(0.0, 0.0, 10, 10, float("nan"), 0.0)
    r = expected_recall_greedy(base, covs, 4, flat)
    first_means = [np.sum(entropy(base[c.pose_idx]) - entropy(base[c.pose_idx] + c.info)) / len(base) for c in covs]
    assert r.gains == [0.0] * 4 and r.order[0] == int(np.argmax(first_means))
    assert r.mean_gains[0] == pytest.approx(max(first_means))
    for k in [0, -1, 9, 2.5]:
        with pytest.raises(UserError):
            expected_recall_greedy(base, covs, k, model)


def test_objective_not_submodular() -> None:
    """Below the logistic midpoint the second copy of a marker gains more than the first: the
    reason the greedy has no lazy variant."""
    base = np.eye(6)[None]
    cov = MarkerCoverage(np.array([0]), 3.0 * np.eye(6)[None])
    s0 = float(-entropy(base)[0])
    model = SuccessModel(-4.0 * (s0 + 10.0), 4.0, 2, 1, 0.5, 0.0)  # midpoint 10 nats higher
    res = expected_recall_greedy(base, [cov, cov], 2, model)
    assert 0.0 < res.gains[0] < res.gains[1]
