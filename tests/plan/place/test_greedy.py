"""OMP greedy (plain vs lazy), percentiles, q-from-v, baselines, input errors."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.plan.place.baselines import random_placement, uniform_placement
from markerplace.plan.place.greedy import (
    GreedyProblem,
    coverage_percentages,
    inverted_cdf_rank,
    omp_greedy,
    percentile_with_zeros,
    q_from_v,
    weighted_q_from_v,
)
from markerplace.plan.score.localizability import information_gain
from markerplace.plan.types import MarkerCoverage


def random_problem(rng: np.random.Generator, N: int, C: int, max_cov: int, ties: bool = False):
    A = rng.normal(size=(N, 6, 8))
    base = A @ A.transpose(0, 2, 1) * 10.0 + 100.0 * np.eye(6)
    if ties:  # identical base everywhere and duplicated coverages -> exactly equal gains
        base[:] = base[0]
    covs = []
    for m in range(C):
        if ties and m % 3 == 2:
            covs.append(covs[m - 1])
            continue
        n = int(rng.integers(0, max_cov + 1))
        idx = np.sort(rng.choice(N, n, replace=False))
        B = rng.normal(size=(n, 6, int(rng.integers(2, 7))))
        info = B @ B.transpose(0, 2, 1) * 10.0 ** rng.uniform(0, 5)
        if ties:
            info[:] = 1e3 * np.eye(6)
        covs.append(MarkerCoverage(idx, info))
    return base, covs


@pytest.mark.parametrize("seed", range(24))
def test_lazy_equals_plain(seed: int) -> None:
    rng = np.random.default_rng(seed)
    N = int(rng.integers(20, 300))
    C = int(rng.integers(5, 60))
    base, covs = random_problem(rng, N, C, max_cov=int(rng.integers(1, N)), ties=seed % 4 == 0)
    k = int(rng.integers(1, C + 1))
    v = [90.0, 50.0, 100.0, 0.0, 99.0, 10.0][seed % 6]
    plain = omp_greedy(base, covs, k, v=v, lazy=False)
    lazy = omp_greedy(base, covs, k, v=v, lazy=True)
    assert lazy.order == plain.order
    assert lazy.gains == plain.gains
    assert lazy.eligible == plain.eligible
    assert len(set(plain.order)) == k
    assert lazy.evaluations <= plain.evaluations
    np.testing.assert_array_equal(lazy.info_after, plain.info_after)
    # Eligible picks first, then the rest; gains of eligible picks never increase.
    el = plain.eligible
    assert el == sorted(el, reverse=True)
    g = [x for x, e in zip(plain.gains, el) if e]
    assert all(a >= b for a, b in zip(g, g[1:]))


def test_greedy_picks_match_brute_force_and_info_after() -> None:
    rng = np.random.default_rng(42)
    base, covs = random_problem(rng, 80, 12, max_cov=40)
    res = omp_greedy(base, covs, 4, v=90.0, lazy=True)
    q, eligible = q_from_v(coverage_percentages(covs, 80), 90.0)
    lam = base.copy()
    for step, m in enumerate(res.order):
        full = np.zeros((len(covs), 80))
        for c, cov in enumerate(covs):
            full[c, cov.pose_idx] = information_gain(lam[cov.pose_idx], cov.info)
        naive = np.percentile(full, q, axis=1, method="inverted_cdf")
        naive[~eligible] = -np.inf
        naive[res.order[:step]] = -np.inf
        assert m == int(np.argmax(naive))
        assert res.gains[step] == pytest.approx(naive[m], rel=1e-12)
        lam[covs[m].pose_idx] += covs[m].info
    np.testing.assert_allclose(res.info_after, lam)


def test_percentile_shortcut_equals_numpy() -> None:
    rng = np.random.default_rng(3)
    for _ in range(300):
        N = int(rng.integers(1, 400))
        n = int(rng.integers(0, N + 1))
        vals = rng.exponential(size=n) * (rng.random(n) > 0.2)  # some exact zeros too
        if rng.random() < 0.3:
            vals = np.round(vals, 1)  # ties
        q = float(rng.choice([0.0, 100.0, 50.0, rng.uniform(0, 100), 99.76]))
        full = np.concatenate([vals, np.zeros(N - n)])
        rng.shuffle(full)
        assert percentile_with_zeros(vals, N, q) == np.percentile(full, q, method="inverted_cdf")


def test_batched_evaluation_equals_naive_percentile() -> None:
    rng = np.random.default_rng(4)
    base, covs = random_problem(rng, 150, 20, max_cov=149)
    for q in [0.0, 37.0, 90.0, 99.5, 100.0]:
        prob = GreedyProblem(base.copy(), covs, q)
        qg, mg = prob.evaluate(np.arange(len(covs)))
        for m, cov in enumerate(covs):
            full = np.zeros(150)
            full[cov.pose_idx] = information_gain(base[cov.pose_idx], cov.info)
            assert qg[m] == np.percentile(full, q, method="inverted_cdf")
            assert mg[m] == pytest.approx(full.mean(), rel=1e-12, abs=1e-15)
            single_q, single_m = prob.evaluate(np.array([m]))
            assert single_q[0] == qg[m] and single_m[0] == mg[m]  # bit-identical


def test_inverted_cdf_rank() -> None:
    x = np.arange(10.0)
    for q in [0, 1, 9.9, 10, 10.1, 50, 99.76, 100]:
        assert x[inverted_cdf_rank(10, q) - 1] == np.percentile(x, q, method="inverted_cdf")


def test_q_from_v_examples() -> None:
    P = np.array([10.0, 20, 30, 40, 50, 60, 70, 80, 90, 100])
    q, el = q_from_v(P, 90.0)  # 10th percentile of P is 10 -> q = 90; the 9 above compete
    assert q == 90.0 and el.sum() == 9 and not el[0]
    q, el = q_from_v(P, 50.0)
    assert q == 50.0 and el.tolist() == [False] * 5 + [True] * 5
    q, el = q_from_v(P, 100.0)  # inf over [0, 100] of F_P(p) >= 0 is 0
    assert q == 100.0 and el.all()
    q, el = q_from_v(P, 0.0)
    assert q == 0.0 and not el.any()
    # The paper's figure: 10th percentile of coverage 0.24 % -> q = 99.76.
    P2 = np.r_[np.full(10, 0.24), np.linspace(0.3, 5, 90)]
    q, el = q_from_v(P2, 90.0)
    assert q == pytest.approx(99.76) and el.sum() == 90
    # Ties at the percentile are excluded (strictly above).
    q, el = q_from_v(np.array([1.0, 1.0, 1.0, 2.0]), 90.0)
    assert q == 99.0 and el.tolist() == [False, False, False, True]
    with pytest.raises(UserError):
        q_from_v(P, 100.5)
    with pytest.raises(UserError):
        q_from_v(P, -1.0)


def test_ineligible_fallback_and_existing() -> None:
    rng = np.random.default_rng(5)
    base, covs = random_problem(rng, 100, 10, max_cov=60)
    res = omp_greedy(base, covs, 10, v=50.0)
    assert sorted(res.order) == list(range(10))
    n_el = int(q_from_v(coverage_percentages(covs, 100), 50.0)[1].sum())
    assert res.eligible == [True] * n_el + [False] * (10 - n_el)
    # Existing markers are applied first: the same marker already present lowers the gain.
    first = res.order[0]
    res2 = omp_greedy(base, covs, 1, v=50.0, existing=[covs[first]])
    assert res2.gains[0] <= res.gains[0]
    seen = []
    omp_greedy(base, covs, 3, progress=lambda i, k, m, g: seen.append((i, k, m)))
    assert [s[0] for s in seen] == [0, 1, 2] and all(s[1] == 3 for s in seen)


def test_greedy_errors() -> None:
    rng = np.random.default_rng(6)
    base, covs = random_problem(rng, 30, 5, max_cov=10)
    for k in [0, -1, 6, 2.5]:
        with pytest.raises(UserError):
            omp_greedy(base, covs, k)
    for v in [-0.1, 100.1]:
        with pytest.raises(UserError):
            omp_greedy(base, covs, 2, v=v)
    with pytest.raises(UserError):
        random_placement(5, 6, seed=0)
    with pytest.raises(UserError):
        uniform_placement(np.arange(5.0), 5.0, 0, seed=0)
    with pytest.raises(ValueError):
        MarkerCoverage(np.array([1, 1]), np.zeros((2, 6, 6)))


def test_coverage_from_dense() -> None:
    info = np.zeros((5, 6, 6))
    info[[1, 3, 4]] = np.eye(6)
    cov = MarkerCoverage.from_dense(info, visible=np.array([True, True, True, True, False]))
    assert cov.pose_idx.tolist() == [1, 3] and len(cov) == 2


def test_random_placement_reproducible() -> None:
    a = random_placement(100, 20, seed=7)
    assert a == random_placement(100, 20, seed=7)
    assert a != random_placement(100, 20, seed=8)
    assert len(set(a)) == 20 and all(0 <= i < 100 for i in a)
    assert sorted(random_placement(5, 5, seed=1)) == [0, 1, 2, 3, 4]


def test_uniform_placement_spread() -> None:
    L = 100.0
    s = np.arange(200) * 0.5  # candidates every 0.5 m around a 100 m perimeter
    for seed in range(5):
        picks = uniform_placement(s, L, 10, seed=seed)
        assert picks == uniform_placement(s, L, 10, seed=seed)
        assert len(set(picks)) == 10
        pos = np.sort(s[picks])
        gaps = np.diff(np.r_[pos, pos[0] + L])
        assert np.all(np.abs(gaps - 10.0) <= 0.5 + 1e-9)
    # Clustered candidates: still distinct, nearest to the targets.
    s2 = np.array([0.0, 0.1, 0.2, 50.0, 50.1])
    picks = uniform_placement(s2, 100.0, 4, seed=0)
    assert len(set(picks)) == 4
    assert sorted(uniform_placement(s2, 100.0, 5, seed=3)) == [0, 1, 2, 3, 4]


# --------------------------------------------------------------------------------------------
# Pose weights (plan --where)
# --------------------------------------------------------------------------------------------


def weighted_percentile_reference(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """The smallest value whose cumulative weight (values sorted ascending) reaches q/100 of the total."""
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    i = int(np.argmax(cum >= q / 100.0 * weights.sum()))
    return float(values[order][i])


@pytest.mark.parametrize("seed", range(8))
def test_weighted_gains_match_a_dense_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    N, C = int(rng.integers(20, 120)), int(rng.integers(3, 20))
    base, covs = random_problem(rng, N, C, max_cov=N)
    w = rng.uniform(0, 3, N) * (rng.uniform(size=N) < 0.6)
    w *= N / w.sum()
    q = float(rng.uniform(5, 95))
    prob = GreedyProblem(base.copy(), covs, q, w)
    qg, mg = prob.evaluate(np.arange(C))
    for m, cov in enumerate(covs):
        dense = np.zeros(N)
        if len(cov):
            dense[cov.pose_idx] = information_gain(base[cov.pose_idx], cov.info)
        assert qg[m] == pytest.approx(weighted_percentile_reference(dense, w, q), rel=1e-9, abs=1e-12)
        assert mg[m] == pytest.approx(np.sum(w * dense) / N, rel=1e-9, abs=1e-12)
    np.testing.assert_allclose(coverage_percentages(covs, N, w),
                               [100 * w[c.pose_idx].sum() / w.sum() for c in covs])


@pytest.mark.parametrize("seed", range(6))
def test_weighted_lazy_equals_plain_and_unit_weights_change_nothing(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    N, C = int(rng.integers(30, 200)), int(rng.integers(5, 40))
    base, covs = random_problem(rng, N, C, max_cov=N // 2)
    k = int(rng.integers(1, C + 1))
    w = rng.uniform(0, 2, N) * (rng.uniform(size=N) < 0.5)
    w *= N / w.sum()
    plain = omp_greedy(base, covs, k, lazy=False, weights=w)
    lazy = omp_greedy(base, covs, k, lazy=True, weights=w)
    assert lazy.order == plain.order and lazy.gains == plain.gains
    unweighted, ones = omp_greedy(base, covs, k), omp_greedy(base, covs, k, weights=np.ones(N))
    assert ones.order == unweighted.order
    np.testing.assert_allclose(ones.gains, unweighted.gains, rtol=1e-12)


def test_weights_pull_the_pick_to_where_the_cameras_are() -> None:
    """Two equal tags, one seen by poses 0..9, the other by 10..19: unweighted, the tie goes to
    the lower index; with weight only on 10..19, the second tag wins and the first gains 0."""
    N = 20
    base = np.repeat((100.0 * np.eye(6))[None], N, axis=0)
    covs = [MarkerCoverage(np.arange(10), np.repeat((1e3 * np.eye(6))[None], 10, axis=0)),
            MarkerCoverage(np.arange(10, 20), np.repeat((1e3 * np.eye(6))[None], 10, axis=0))]
    assert omp_greedy(base, covs, 1, v=100).order == [0]
    w = np.r_[np.zeros(10), np.full(10, 2.0)]
    res = omp_greedy(base, covs, 2, v=100, weights=w)
    assert res.order == [1, 0] and res.gains[0] > 0 and res.gains[1] == 0.0


def test_weighted_gain_does_not_depend_on_the_batch_and_q_is_taken_over_seen_candidates() -> None:
    """Lazy greedy evaluates a candidate alone: its weighted gain must be the one it gets in a
    batch, bit for bit (q = 100 included, where rounding could miss the threshold); and the
    q-from-v rule runs over the candidates some weighted pose sees."""
    rng = np.random.default_rng(7)
    N, C = 90, 25
    base, covs = random_problem(rng, N, C, max_cov=60)
    w = np.where(rng.uniform(size=N) < 0.3, 10.0 / 3.0, 0.0)
    w *= N / w.sum()
    for q in (100.0, 97.3, 50.0):
        prob = GreedyProblem(base.copy(), covs, q, w)
        together = prob.evaluate(np.arange(C))[0]
        alone = np.array([prob.evaluate(np.array([m]))[0][0] for m in range(C)])
        np.testing.assert_array_equal(together, alone)
        if q == 100.0:  # the largest gain over the weighted poses
            for m, cov in enumerate(covs):
                g = information_gain(base[cov.pose_idx], cov.info) if len(cov) else np.zeros(0)
                assert together[m] == pytest.approx(max(g[w[cov.pose_idx] > 0], default=0.0), rel=1e-12)
    P = np.array([0.0, 0.0, 5.0, 10.0, 20.0, 40.0])
    q, eligible = weighted_q_from_v(P, 75.0, True)
    q_seen, el_seen = q_from_v(P[2:], 75.0)
    assert q == q_seen and eligible.tolist() == [False, False, *el_seen.tolist()]
    assert weighted_q_from_v(P, 75.0, False)[0] == q_from_v(P, 75.0)[0]
    assert weighted_q_from_v(np.zeros(3), 90.0, True) == (100.0, pytest.approx(np.zeros(3, bool)))
