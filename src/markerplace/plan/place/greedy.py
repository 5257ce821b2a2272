"""Marker placement: OMP greedy, plain and lazy (the algorithm; the random and uniform baselines
are in :mod:`markerplace.plan.place.baselines`; :mod:`markerplace.plan.place.methods` makes them placement
methods chosen by name).

The problem is given as information matrices: ``base_info`` (N, 6, 6), the information of every
feasible camera pose without markers (see :mod:`markerplace.plan.score.localizability`), and per candidate
marker m a :class:`MarkerCoverage`, the sparse set of poses that see it with the information
``M`` (6, 6) it adds there. Everything below is exact arithmetic on these arrays; no scene.

Definitions (paper, Methods; docs/design.md section 5)
-------------------------------------------------
* Information gain at pose c: ``I(m, c) = 1/2 [ln det(Lambda_c + M_cm) - ln det(Lambda_c)]``,
  0 where m is not seen.
* Localizability gain ``g(m | S)``: the q-th percentile over ALL N feasible poses of I(m, .),
  with the paper's ``inf{i : F_I(i) >= q/100}`` (numpy's ``method="inverted_cdf"``).
* ``P_m = 100 |C_m| / N`` where ``C_m`` are the poses in m's coverage (entries with all-zero
  information are dropped by :meth:`MarkerCoverage.from_dense`), and
  ``q = 100 - p*`` with ``p* = inf{p in [0, 100] : F_P(p) >= (100 - v)/100}``.

Tie and eligibility rules (exact, so plain and lazy greedy agree bit for bit)
-----------------------------------------------------------------------------
* Eligible candidates are those with ``P_m > p*`` (strictly above). This is exactly the set
  whose q-th percentile gain can be nonzero (a candidate with ``P_m <= p*`` has at least a
  fraction q/100 of zeros), so for v in (0, 100] it is "the most visible v percent". For
  v = 100, ``p* = 0`` (the infimum over [0, 100]) and every candidate seen by some pose is
  eligible.
* Each round picks the eligible candidate with the largest ``g(m | S)``; equal gains go to the
  smallest candidate index. Only when no eligible candidate is left are ineligible ones picked,
  ranked by their mean information gain over all N poses (their q-th percentile gain is 0),
  again ties to the smallest index.
* Pose weights (``plan --where``): ``P_m`` is the share of the total weight that sees m, q comes
  from v over the candidates with ``P_m > 0`` (:func:`weighted_q_from_v`), gains are weighted
  percentiles and means; without weights every line above holds as it is.
* Both keys only shrink as markers are placed (per-pose gains shrink as Lambda grows; a
  percentile and a mean are monotone in every element), so stale keys are upper bounds and
  the lazy greedy returns exactly the plain greedy's sequence.
"""

from __future__ import annotations

import heapq
import logging
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.plan.score.localizability import information_gain_whitened, whitening
from markerplace.plan.types import MarkerCoverage

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class PlacementResult:
    """Outcome of :func:`omp_greedy`.

    Attributes:
        order: picked candidate indices, in placement order.
        gains: localizability gain ``g(m | S)`` (nats, q-th percentile) of each pick when picked.
        mean_gains: mean information gain over all N poses of each pick when picked (nats).
        eligible: whether each pick was eligible by v (False only once eligible ones ran out).
        q: the percentile used (0-100).
        evaluations: number of candidate gain evaluations performed.
        info_after: (N, 6, 6) information of every pose with all picked (and existing) markers.
    """

    order: list[int]
    gains: list[float]
    mean_gains: list[float]
    eligible: list[bool]
    q: float
    evaluations: int
    info_after: np.ndarray = field(repr=False)


def apply_coverages(info: np.ndarray, coverages: Sequence[MarkerCoverage]) -> np.ndarray:
    """(N, 6, 6) copy of ``info`` with each coverage's information added at the poses that see
    its marker (``coverages`` in order; the sum is the same in any order up to rounding)."""
    out = np.array(info, dtype=float, copy=True)
    for cov in coverages:
        np.add.at(out, cov.pose_idx, cov.info)
    return out


# --------------------------------------------------------------------------------------------
# Percentiles
# --------------------------------------------------------------------------------------------


def inverted_cdf_rank(n: int, q: float) -> int:
    """1-based rank k such that ``np.percentile(x, q, method="inverted_cdf") == sort(x)[k-1]``.

    This is ``inf{i : F(i) >= q/100}`` for n values; computed with numpy itself (on the ranks
    0..n-1) so floating-point edge cases match numpy exactly.
    """
    if n < 1:
        raise ValueError("need at least one value")
    return int(np.percentile(np.arange(n), q, method="inverted_cdf")) + 1


def percentile_with_zeros(values: np.ndarray, n_total: int, q: float,
                          rank: int | None = None) -> float:
    """q-th percentile (inverted_cdf) of ``values`` padded with zeros to ``n_total`` entries.

    Args:
        values: (n,) nonnegative values (the nonzero part; zeros allowed), n <= n_total.
        n_total: total number of entries N (the rest are zeros).
        q: percentile in [0, 100].
        rank: precomputed :func:`inverted_cdf_rank` (n_total, q).

    Equals ``np.percentile(np.concatenate([values, np.zeros(n_total - n)]), q,
    method="inverted_cdf")`` without materialising N values.
    """
    values = np.asarray(values, dtype=float).reshape(-1)
    k = inverted_cdf_rank(n_total, q) if rank is None else rank
    zeros = n_total - values.shape[0]
    if k <= zeros:
        return 0.0
    j = k - zeros - 1
    return float(np.partition(values, j)[j])


def coverage_percentages(coverages: Sequence[MarkerCoverage], num_poses: int,
                         weights: np.ndarray | None = None) -> np.ndarray:
    """(C,) ``P_m = 100 |C_m| / N``: percentage of feasible poses that see each candidate; with
    (N,) pose ``weights``, the percentage of the total weight."""
    if weights is None:
        return np.array([100.0 * len(c) / num_poses for c in coverages], dtype=float)
    w = np.asarray(weights, dtype=float)
    total = max(float(w.sum()), 1e-300)
    return np.array([100.0 * float(w[c.pose_idx].sum()) / total for c in coverages], dtype=float)


def q_from_v(coverage_pct: np.ndarray, v: float) -> tuple[float, np.ndarray]:
    """The paper's percentile q from the hyperparameter v (eq. q-v relation).

    ``p* = inf{p in [0, 100] : F_P(p) >= (100 - v)/100}`` (numpy ``inverted_cdf`` for
    v < 100, and 0 for v = 100), ``q = 100 - p*``.

    Args:
        coverage_pct: (C,) percentages P_m of poses that see each candidate.
        v: percent of most visible candidates that should earn nonzero gains, [0, 100].

    Returns:
        q in [0, 100] and the (C,) bool eligibility mask ``P_m > p*`` (strict; see module
        docstring).
    """
    v = float(v)
    if not 0.0 <= v <= 100.0:
        raise UserError(f"v = {v} is outside [0, 100]: give the percent of most visible markers")
    P = np.asarray(coverage_pct, dtype=float).reshape(-1)
    if P.size == 0:
        raise UserError("no candidate markers: nothing to place")
    p_star = 0.0 if v == 100.0 else float(np.percentile(P, 100.0 - v, method="inverted_cdf"))
    return 100.0 - p_star, P > p_star


def weighted_q_from_v(coverage_pct: np.ndarray, v: float, weighted: bool) -> tuple[float, np.ndarray]:
    """:func:`q_from_v`, and with pose weights (``plan --where``) taken over the candidates some
    weighted pose sees (``P_m > 0``): as the planner drops spots no camera pose sees, a spot no
    weighted pose sees does not compete (nor pull p* to 0, which would make q = 100, the
    largest gain). When no candidate is seen from a weighted pose, q = 100 and none is eligible
    (the picks then go by mean gain, 0: the lowest indices), with a warning."""
    if not weighted:
        return q_from_v(coverage_pct, v)
    P = np.asarray(coverage_pct, dtype=float).reshape(-1)
    seen = P > 0.0
    eligible = np.zeros(len(P), dtype=bool)
    if not seen.any():
        q_from_v(P, v)  # the same errors (v out of range, no candidates)
        log.warning("no candidate tag is seen from a camera pose with a weight above 0 (--where): the picks are "
                    "arbitrary; widen the zones or routes, or set default_weight above 0")
        return 100.0, eligible
    q, eligible[seen] = q_from_v(P[seen], v)
    return q, eligible


# --------------------------------------------------------------------------------------------
# Greedy
# --------------------------------------------------------------------------------------------


class GreedyProblem:
    """Flattened coverages for batched gain evaluation."""

    def __init__(self, base_info: np.ndarray, coverages: Sequence[MarkerCoverage], q: float,
                 weights: np.ndarray | None = None):
        self.N = base_info.shape[0]
        self.weights = None if weights is None else np.asarray(weights, dtype=float).reshape(self.N)
        self.q = float(q)
        self.sizes = np.array([len(c) for c in coverages], dtype=np.int64)
        self.offsets = np.zeros(len(coverages) + 1, dtype=np.int64)
        np.cumsum(self.sizes, out=self.offsets[1:])
        self.coverages = coverages
        self.rank = inverted_cdf_rank(self.N, q)
        self.lam = base_info
        self.linv = whitening(base_info)  # (N, 6, 6) cached L^-1 per pose
        for c in coverages:
            if len(c) and (c.pose_idx.min() < 0 or c.pose_idx.max() >= self.N):
                raise ValueError("MarkerCoverage.pose_idx out of range of base_info")

    def add(self, cov: MarkerCoverage) -> None:
        """Place a marker: add its information and refresh the whitening where it changed."""
        self.lam[cov.pose_idx] += cov.info
        self.linv[cov.pose_idx] = whitening(self.lam[cov.pose_idx])

    def pose_gains(self, cands: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per-pose information gains (nats) of candidates ``cands``, flattened.

        Returns:
            nz (len(cands),) bool: the candidate is seen by some pose; pidx (L,) the poses of
            the seen candidates, one segment each, in order; g (L,) their gains; seg (L,) the
            segment (index into ``cands[nz]``) of each entry.
        """
        cands = np.asarray(cands, dtype=np.int64)
        sizes = self.sizes[cands]
        nz = sizes > 0
        live = cands[nz]
        if not len(live):
            return nz, np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
        pidx = np.concatenate([self.coverages[m].pose_idx for m in live])
        info = np.concatenate([self.coverages[m].info for m in live])
        g = information_gain_whitened(self.linv[pidx], info)
        return nz, pidx, g, np.repeat(np.arange(len(live)), sizes[nz])

    def segment_sums(self, nz: np.ndarray, seg: np.ndarray, values: np.ndarray) -> np.ndarray:
        """(len(nz),) sum of ``values`` per candidate (0 where ``nz`` is False), from the
        flattened ``seg``/``values`` of :meth:`pose_gains`."""
        out = np.zeros(len(nz))
        if np.any(nz):
            out[nz] = np.bincount(seg, weights=values, minlength=int(np.count_nonzero(nz)))
        return out

    def pose_weight(self, pidx: np.ndarray) -> np.ndarray | float:
        """Weights of poses ``pidx`` (1.0 when the problem has none)."""
        return 1.0 if self.weights is None else self.weights[pidx]

    def evaluate(self, cands: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """q-th percentile gains and mean gains (nats) of candidates ``cands``; with pose
        weights, the weighted percentile and the weighted mean (:meth:`_weighted_percentiles`)."""
        cands = np.asarray(cands, dtype=np.int64)
        sizes = self.sizes[cands]
        qg = np.zeros(len(cands))
        nz, pidx, g, seg = self.pose_gains(cands)
        mg = self.segment_sums(nz, seg, g * self.pose_weight(pidx)) / max(self.N, 1)
        if not np.any(nz):
            return qg, mg
        if self.weights is not None:
            qg[nz] = self._weighted_percentiles(pidx, g, seg, int(np.count_nonzero(nz)))
            return qg, mg
        live = cands[nz]
        # Per-segment k-th smallest: sort by (segment, gain); segments stay in place.
        srt = g[np.lexsort((g, seg))]
        starts = np.zeros(len(live), dtype=np.int64)
        np.cumsum(sizes[nz][:-1], out=starts[1:])
        j = self.rank - (self.N - sizes[nz])  # 1-based rank among the segment's values
        pos = j > 0
        out = np.zeros(len(live))
        out[pos] = srt[starts[pos] + j[pos] - 1]
        qg[nz] = out
        return qg, mg

    def _weighted_percentiles(self, pidx: np.ndarray, g: np.ndarray, seg: np.ndarray, n: int) -> np.ndarray:
        """(n,) weighted q-th percentile per segment of the gains padded with zeros: the
        smallest gain x with (weight of the poses whose gain is <= x) >= q/100 of the total
        weight, the unseen poses gaining 0 (``inverted_cdf`` with weights; with every weight 1
        it is the unweighted rule: the tests check the same picks).

        Each segment is summed on its own, in its own sorted order, so a candidate's gain does
        not depend on which others are evaluated with it (lazy greedy evaluates it alone); when
        rounding leaves the last cumulative weight a hair under the threshold (q = 100), the
        largest gain of a weighted pose is taken, as exact arithmetic would."""
        w = self.weights
        total = float(w.sum())
        thresh = self.q / 100.0 * total  # compared exactly, as numpy's inverted_cdf does
        order = np.lexsort((g, seg))
        srt, ws = g[order], w[pidx][order]
        bounds = np.searchsorted(seg[order], np.arange(n + 1))
        out = np.zeros(n)
        for j in range(n):
            a, b = bounds[j], bounds[j + 1]
            keep = ws[a:b] > 0.0  # poses that weigh nothing cannot move a weighted percentile
            if not keep.any():
                continue
            vals, cum = srt[a:b][keep], np.cumsum(ws[a:b][keep])
            need = thresh - (total - float(cum[-1]))  # what the seen poses must add to the unseen ones' zeros
            if need <= 0.0:
                continue
            out[j] = vals[min(int(np.searchsorted(cum, need, side="left")), len(vals) - 1)]
        return out


def check_k(k: int, num_candidates: int) -> int:
    """``k`` as an int; :class:`UserError` unless 1 <= k <= ``num_candidates`` (integer)."""
    if int(k) != k or k < 1:
        raise UserError(f"k = {k}: the number of markers must be a positive integer")
    if k > num_candidates:
        raise UserError(f"{k} markers requested but only {num_candidates} candidate marker poses were found: ask for "
                        "fewer markers or reduce --marker-spacing")
    return int(k)


def omp_greedy(base_info: np.ndarray, coverages: Sequence[MarkerCoverage], k: int,
               v: float = 90.0, lazy: bool = True,
               existing: Sequence[MarkerCoverage] | None = None,
               progress: Callable[[int, int, int, float], None] | None = None,
               weights: np.ndarray | None = None) -> PlacementResult:
    """Optimized marker placement (the paper's Algorithm 1), optionally with lazy evaluation.

    Args:
        base_info: (N, 6, 6) information of every feasible pose without candidate markers.
        coverages: C candidate markers, see :class:`MarkerCoverage`.
        k: number of markers to place, 1 <= k <= C.
        v: hyperparameter of the q-from-v rule, [0, 100] (paper default 90).
        lazy: use the exact lazy (priority queue of stale upper bounds) greedy.
        existing: coverages of markers already in the scene; their information is added to
            ``base_info`` before the greedy starts (they are not candidates).
        progress: optional callback ``progress(i, k, candidate, gain)`` after each pick.
        weights: (N,) pose weights >= 0 (``plan --where``), or None (every pose 1): ``P_m`` is
            the share of the total weight that sees m, the gain the weighted q-th percentile and
            the mean the weighted mean (still monotone in every pose's gain, so lazy stays exact).

    Returns:
        :class:`PlacementResult`. Plain and lazy return identical order and gains.

    Raises:
        UserError: k < 1, k > C, or v outside [0, 100].
    """
    C = len(coverages)
    k = check_k(k, C)
    lam = apply_coverages(base_info, existing or ())  # the existing markers count as placed
    N = lam.shape[0]
    q, eligible = weighted_q_from_v(coverage_percentages(coverages, N, weights), v, weights is not None)
    prob = GreedyProblem(lam, coverages, q, weights)
    log.debug("omp_greedy: N=%d C=%d k=%d v=%g q=%.4f eligible=%d lazy=%s",
              N, C, k, v, q, int(eligible.sum()), lazy)

    order: list[int] = []
    gains: list[float] = []
    means: list[float] = []
    elig: list[bool] = []
    evaluations = 0

    def keyval(m: int, qg: float, mg: float) -> float:
        return qg if eligible[m] else mg

    if lazy:
        all_c = np.arange(C)
        qg, mg = prob.evaluate(all_c)
        evaluations += C
        # Heap entries: (not eligible, -value, index, round evaluated, q gain, mean gain).
        heap = [(not eligible[m], -keyval(m, qg[m], mg[m]), m, 0, qg[m], mg[m]) for m in range(C)]
        heapq.heapify(heap)
        for it in range(k):
            while True:
                ne, negval, m, stamp, qgm, mgm = heapq.heappop(heap)
                if stamp == it:
                    break
                qn, mn = prob.evaluate(np.array([m]))
                evaluations += 1
                heapq.heappush(heap, (ne, -keyval(m, qn[0], mn[0]), m, it, qn[0], mn[0]))
            prob.add(coverages[m])
            order.append(int(m))
            gains.append(float(qgm))
            means.append(float(mgm))
            elig.append(bool(eligible[m]))
            if progress is not None:
                progress(it, k, int(m), float(qgm))
    else:
        remaining = np.ones(C, dtype=bool)
        for it in range(k):
            cands = np.flatnonzero(remaining)
            qg, mg = prob.evaluate(cands)
            evaluations += len(cands)
            el = eligible[cands]
            val = np.where(el, qg, mg)
            # Lexicographic max of (eligible, value, -index): cands is sorted ascending, so
            # argmax (first occurrence) gives the smallest index among ties.
            pool = el if np.any(el) else np.ones_like(el)
            val_pool = np.where(pool, val, -np.inf)
            i = int(np.argmax(val_pool))
            m = int(cands[i])
            remaining[m] = False
            prob.add(coverages[m])
            order.append(m)
            gains.append(float(qg[i]))
            means.append(float(mg[i]))
            elig.append(bool(eligible[m]))
            if progress is not None:
                progress(it, k, m, float(qg[i]))
    log.info("omp_greedy: placed %d markers (q=%.3f, %d evaluations)", k, q, evaluations)
    return PlacementResult(order, gains, means, elig, q, evaluations, lam)


__all__ = [
    "GreedyProblem", "PlacementResult", "apply_coverages", "check_k", "coverage_percentages", "inverted_cdf_rank",
    "omp_greedy", "percentile_with_zeros", "q_from_v", "weighted_q_from_v",
]
