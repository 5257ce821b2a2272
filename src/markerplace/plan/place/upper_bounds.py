"""Upper bounds on what any k tags could achieve, valid for the objectives a plan reports.

The score of pose p with tags T, ``s_p(T) = 1/2 ln det(Lambda_p + sum_{m in T} M_pm) + const``
(nats), is monotone and submodular in T (log det of a sum of PSD matrices added to an SPD one:
the gain ``1/2 ln det(I + M^(1/2) A^-1 M^(1/2))`` of a tag only shrinks as A grows). The
expected-recall objective ``F(T) = sum_p P(s_p(T))`` with a logistic P is monotone but not
submodular (P is convex below its midpoint), so the textbook data-dependent bound
``F(OPT) <= F(S) + sum of the k largest marginal gains Delta(m | S)`` (Krause & Golovin,
"Submodular function maximization", 2014, for monotone submodular F) does NOT hold for it; a
monotone function need not satisfy it, and the Das & Kempe (2011) weakened form
``F(OPT) <= F(S) + (1/gamma) sum top-k`` needs the submodularity ratio gamma, a minimum over all
sets that a sample can only over-estimate (a sampled gamma gives no bound).

What does hold, pose by pose, for any set S and any k-set T (``g_p(m | S)`` the score gain of m
at p given S, ``top_k`` the sum of the k largest over candidates not in S):

    s_p(T) <= s_p(S ∪ T) <= s_p(S) + sum_{m in T \\ S} g_p(m | S) <= s_p(S) + top_k(g_p(. | S))

(monotone, then submodular), and ``s_p(T) <= s_p(all candidates)`` (monotone). P is increasing,
so for every k-set T

    F(T)          <= sum_p P(min(s_p(S) + top_k g_p, s_p(all)))           (:func:`recall_upper_bound`)
    sum_p s_p(T)  <= sum_p min(s_p(S) + top_k g_p, s_p(all))              (:func:`score_upper_bound`)

Both are data-dependent (computed at the plan's S) and at least as tight as their textbook
form for the score sum (whose bound sums the k largest *totals* over poses). They bound the best
k-set among the candidates under the same model, never localization itself.

:func:`submodularity_sample` measures, on random nested sets, how often an objective breaks
diminishing returns and the smallest sampled ratio (tests and ``benchmarks/submodularity.py``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from markerplace.plan.place.greedy import GreedyProblem, apply_coverages
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.success_model import SuccessModel
from markerplace.plan.types import MarkerCoverage

__all__ = ["per_pose_bound_scores", "recall_upper_bound", "score_upper_bound", "submodularity_sample"]


def per_pose_bound_scores(base_info: np.ndarray, coverages: Sequence[MarkerCoverage], chosen: Sequence[int],
                          k: int, existing: Sequence[MarkerCoverage] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Per pose, the score with ``chosen`` and an upper bound on its score with any k candidates.

    Args:
        base_info: (N, 6, 6) SPD information without markers (1/rad^2, 1/m^2).
        coverages: C candidate coverages.
        chosen: the plan's candidate indices S (any size).
        k: the budget the bound is for, >= 0.
        existing: coverages of markers on the walls (in every score).

    Returns:
        (N,) score ``s_p(S)`` and (N,) bound ``min(s_p(S) + top_k g_p(. | S), s_p(all))``, nats.
    """
    lam = apply_coverages(base_info, list(existing))
    every = apply_coverages(lam, list(coverages))
    lam = apply_coverages(lam, [coverages[int(m)] for m in chosen])
    N, C = lam.shape[0], len(coverages)
    score = -entropy(lam) if N else np.zeros(0)
    rest = np.setdiff1d(np.arange(C), np.asarray(chosen, dtype=np.int64))
    add = np.zeros(N)
    if k > 0 and len(rest) and N:
        prob = GreedyProblem(lam, coverages, q=100.0)
        _, pidx, g, _ = prob.pose_gains(rest)
        if len(g):
            srt = np.lexsort((-g, pidx))  # per pose, largest gain first
            p, gs = pidx[srt], g[srt]
            starts = np.searchsorted(p, p, side="left")
            keep = (np.arange(len(p)) - starts) < k
            add = np.bincount(p[keep], weights=gs[keep], minlength=N)
    return score, np.minimum(score + add, -entropy(every) if N else score)


def recall_upper_bound(base_info: np.ndarray, coverages: Sequence[MarkerCoverage], chosen: Sequence[int], k: int,
                       model: SuccessModel, existing: Sequence[MarkerCoverage] = (),
                       weights: np.ndarray | None = None) -> float:
    """Upper bound on the predicted recall (share of the N poses, in [0, 1]) of ANY k candidates
    (with the existing markers), from the plan ``chosen`` (module docstring; valid because each
    pose's score is submodular and P increasing, not because F is submodular: it is not). With
    (N,) pose ``weights`` >= 0 (``plan --where``) the share is weighted (still a bound: each
    pose's term is)."""
    _, bound = per_pose_bound_scores(base_info, coverages, chosen, k, existing)
    return _mean(model.probability(bound), weights) if len(bound) else 0.0


def _mean(values: np.ndarray, weights: np.ndarray | None) -> float:
    """Mean of (N,) values, weighted by (N,) ``weights`` when given."""
    return float(np.mean(values)) if weights is None else float(np.sum(values * weights) / np.sum(weights))


def score_upper_bound(base_info: np.ndarray, coverages: Sequence[MarkerCoverage], chosen: Sequence[int], k: int,
                      existing: Sequence[MarkerCoverage] = (),
                      weights: np.ndarray | None = None) -> tuple[float, float]:
    """(mean score of the plan ``chosen``, upper bound on the mean score of ANY k candidates),
    nats over the N poses (module docstring; the score sum is monotone submodular), weighted by
    (N,) pose ``weights`` when given."""
    score, bound = per_pose_bound_scores(base_info, coverages, chosen, k, existing)
    if not len(score):
        return 0.0, 0.0
    return _mean(score, weights), _mean(bound, weights)


def submodularity_sample(f: Callable[[Sequence[int]], float], C: int, trials: int, rng: np.random.Generator,
                         tol: float = 1e-9) -> dict:
    """Sample diminishing returns of a set function on subsets of range(C).

    Each trial draws a random T, a random S inside it and a candidate m outside T, and checks
    ``f(S + m) - f(S) >= f(T + m) - f(T) - tol``; it also draws a set A outside S and records the
    submodularity ratio sample ``sum_{a in A} Delta(a | S) / Delta(A | S)`` (Das & Kempe; 1 or
    more for a submodular f). A sampled minimum over-estimates the true ratio: it is no bound.

    Args:
        f: set function on lists of candidate indices.
        C: number of candidates, >= 3.
        trials: number of samples.
        rng: random generator.
        tol: slack of the comparison (absolute, in f's units).

    Returns:
        dict with ``trials``, ``violations`` (count), ``rate`` (violations / trials),
        ``worst`` (largest ``Delta(m | T) - Delta(m | S)``) and ``ratio_min`` (smallest sampled
        ratio, NaN when no A had a positive joint gain).
    """
    viol, worst, ratios = 0, 0.0, []
    for _ in range(int(trials)):
        perm = rng.permutation(C)
        t = int(rng.integers(1, C - 1))
        s = int(rng.integers(0, t))
        T, S, m = list(perm[:t]), list(perm[:s]), int(perm[t])
        fS, fT = f(S), f(T)
        dS, dT = f(S + [m]) - fS, f(T + [m]) - fT
        if dS < dT - tol:
            viol += 1
        worst = max(worst, dT - dS)
        A = list(perm[s:s + int(rng.integers(2, C - s + 1))]) if C - s >= 2 else []
        joint = f(S + A) - fS if A else 0.0
        if joint > tol:
            ratios.append(sum(f(S + [a]) - fS for a in A) / joint)
    return {"trials": int(trials), "violations": viol, "rate": viol / max(int(trials), 1), "worst": worst,
            "ratio_min": float(min(ratios)) if ratios else float("nan")}
