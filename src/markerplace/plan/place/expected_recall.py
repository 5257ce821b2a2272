"""Marker placement that maximizes the expected number of poses that localize.

Objective (beyond the paper's percentile-of-gains OMP): with ``s_p(S) = -H(Lambda_p(S))`` the
localizability score (nats) of feasible pose p once markers S are placed, and ``P`` a fitted
:class:`~markerplace.plan.score.success_model.SuccessModel`,

    F(S) = sum_p P(s_p(S))        (expected number of the N poses that localize)

The greedy adds, each round, the candidate with the largest marginal gain

    Delta(m | S) = sum_{p in C_m} [P(s_p + I(m, p | S)) - P(s_p)],
    I(m, p | S) = 1/2 [ln det(Lambda_p + M_pm) - ln det Lambda_p]   (nats),

evaluated for every remaining candidate in one batched pass over the flattened coverages
(:class:`markerplace.plan.place.greedy.GreedyProblem`: cached whitening per pose,
:func:`~markerplace.plan.score.localizability.information_gain_whitened`).

F is monotone (more information never lowers a score, P is increasing) but not submodular in
general: below the logistic midpoint P is convex, so a pose an earlier marker has lifted can
gain *more* probability from the same information. Stale gains are therefore no upper bounds
and lazy evaluation would not be exact; only the plain greedy is implemented.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np

from markerplace.plan.place.greedy import GreedyProblem, PlacementResult, apply_coverages, check_k
from markerplace.plan.place.recall_curve import NEGLIGIBLE
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.success_model import SuccessModel
from markerplace.plan.types import MarkerCoverage

log = logging.getLogger(__name__)


def expected_localized(info: np.ndarray, model: SuccessModel, weights: np.ndarray | None = None) -> float:
    """``sum_p w_p P(-H(Lambda_p))``: expected number of poses that localize (poses, not percent).

    Args:
        info: (N, 6, 6) SPD information matrices (1/rad^2, 1/m^2).
        model: success model of the score.
        weights: (N,) pose weights summing to N (``plan --where``), or None (every pose 1).
    """
    info = np.asarray(info, dtype=float)
    if info.shape[0] == 0:
        return 0.0
    p = model.probability(-entropy(info))
    return float(np.sum(p if weights is None else p * weights))


class _RecallProblem(GreedyProblem):
    """:class:`GreedyProblem` plus the current score of every pose and expected-pose gains."""

    def __init__(self, base_info: np.ndarray, coverages: Sequence[MarkerCoverage],
                 model: SuccessModel, weights: np.ndarray | None = None):
        super().__init__(base_info, coverages, q=100.0, weights=weights)  # q is unused here
        self.model = model
        self.scores = -entropy(base_info) if self.N else np.zeros(0)

    def add(self, cov: MarkerCoverage) -> None:
        super().add(cov)
        if len(cov):
            self.scores[cov.pose_idx] = -entropy(self.lam[cov.pose_idx])

    def expected_gains(self, cands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(len(cands),) expected poses gained ``Delta(m | S)`` and mean information gain over
        all N poses (nats) of candidates ``cands``."""
        nz, pidx, g, seg = self.pose_gains(np.asarray(cands, dtype=np.int64))
        dp = self.model.probability_increase(self.scores[pidx], g) if len(g) else g
        w = self.pose_weight(pidx)
        return self.segment_sums(nz, seg, dp * w), self.segment_sums(nz, seg, g * w) / max(self.N, 1)


def expected_recall_greedy(base_info: np.ndarray, coverages: Sequence[MarkerCoverage], k: int,
                           model: SuccessModel,
                           existing: Sequence[MarkerCoverage] | None = None,
                           progress: Callable[[int, int, int, float], None] | None = None,
                           stop_at: float | None = None,
                           weights: np.ndarray | None = None) -> PlacementResult:
    """Greedy placement maximizing the expected number of poses that localize (plain greedy).

    Each of the k rounds evaluates ``Delta(m | S)`` (module docstring) for every remaining
    candidate and picks the largest; equal gains (a constant model gives all zero) go to the
    larger mean information gain, then to the smallest candidate index. Lazy evaluation is
    not offered: the objective is not submodular (convex part of the logistic).

    Args:
        base_info: (N, 6, 6) SPD information of every feasible pose without candidate markers
            (1/rad^2, 1/m^2).
        coverages: C candidate markers, see :class:`MarkerCoverage`.
        k: number of markers to place, 1 <= k <= C.
        model: :class:`SuccessModel` giving P(success | score).
        existing: coverages of markers already in the scene; their information is added to
            ``base_info`` before the greedy starts (they are not candidates).
        progress: optional callback ``progress(i, k, candidate, gain)`` after each pick (gain
            in expected poses).
        stop_at: expected poses that localize to stop at (``plan --target-recall``: the target
            share times N): the greedy stops after the first pick that reaches it, or before a
            pick that would add no more than :data:`~markerplace.plan.place.recall_curve.NEGLIGIBLE`
            of the poses (at least one pick is made); k is then the most picks. None: k picks.
        weights: (N,) pose weights summing to N (``plan --where``), or None (every pose 1): the
            objective is ``sum_p w_p P(s_p)``, still in poses.

    Returns:
        :class:`PlacementResult` with ``order`` (k picks, fewer with ``stop_at``); ``gains`` = expected poses gained by each pick
        when picked (poses, >= 0, so the objective never decreases); ``mean_gains`` = mean
        information gain over all N poses of each pick when picked (nats); ``eligible`` all
        True; ``q`` = NaN (no percentile); ``evaluations`` = candidate evaluations performed;
        ``info_after`` (N, 6, 6) with all existing and picked markers.

    Raises:
        UserError: k < 1 or k > C.
    """
    C = len(coverages)
    k = check_k(k, C)
    lam = apply_coverages(base_info, existing or ())  # the existing markers count as placed
    N = lam.shape[0]
    prob = _RecallProblem(lam, coverages, model, weights)
    expected = float(np.sum(model.probability(prob.scores) * prob.pose_weight(np.arange(N))))
    log.debug("expected_recall_greedy: N=%d C=%d k=%d, expected localized before %.3f", N, C, k, expected)

    order: list[int] = []
    gains: list[float] = []
    means: list[float] = []
    evaluations = 0
    remaining = np.ones(C, dtype=bool)
    for it in range(k):
        cands = np.flatnonzero(remaining)
        dg, mg = prob.expected_gains(cands)
        evaluations += len(cands)
        # the largest expected gain; equal ones (e.g. a constant model: all zero) go to the
        # larger mean information gain, then to the smallest index (cands ascending)
        i = int(np.lexsort((-mg, -dg))[0])
        if stop_at is not None and order and dg[i] <= NEGLIGIBLE * N:
            log.info("expected_recall_greedy: no candidate adds anything after %d picks", len(order))
            break
        m = int(cands[i])
        remaining[m] = False
        prob.add(coverages[m])
        order.append(m)
        gains.append(float(dg[i]))
        means.append(float(mg[i]))
        expected += float(dg[i])
        if progress is not None:
            progress(it, k, m, float(dg[i]))
        if stop_at is not None and expected >= stop_at - 1e-12 * max(N, 1):
            break
    log.info("expected_recall_greedy: placed %d markers, +%.3f expected poses of %d "
             "(%d evaluations)", len(order), float(sum(gains)), N, evaluations)
    return PlacementResult(order, gains, means, [True] * len(order), float("nan"), evaluations, lam)


__all__ = ["expected_localized", "expected_recall_greedy"]
