"""Predicted recall against the number of tags: the diminishing-returns curve of a plan.

With a fitted :class:`~markerplace.plan.score.success_model.SuccessModel` ``P`` and the plan's own
order of tags m_1, m_2, ..., the *predicted recall* after the first j tags is

    R(j) = (1/N) sum_p P(s_p({m_1, ..., m_j}))        (share of the N feasible poses, in [0, 1])

with ``s_p`` the localizability score (nats) of pose p with the existing markers and those j
tags. ``R(0)`` is the recall without new tags. :func:`recall_curve` computes R(0..K) with one
incremental pass over the coverages.

The knee (:func:`knee`): the largest j whose own tag added at least :data:`KNEE_POINTS`
percentage points of predicted recall, ``R(j) - R(j-1) >= KNEE_POINTS / 100``; every tag after
it adds less. None when no tag adds that much. The rule does not depend on how many tags were
placed beyond it (a chord-distance knee would move with K), and it reads as what it is: "after
the knee each further tag adds less than one point".

:func:`target_count` cuts a curve at a recall target (``plan --target-recall``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.success_model import SuccessModel
from markerplace.plan.types import MarkerCoverage

log = logging.getLogger(__name__)

__all__ = ["KNEE_POINTS", "NEGLIGIBLE", "knee", "recall_curve", "target_count"]

KNEE_POINTS = 1.0
"""Percentage points of predicted recall a tag must add to be at or before the knee."""

NEGLIGIBLE = 1e-9
"""A change of predicted recall (share of poses) at most this counts as nothing."""


def recall_curve(base_info: np.ndarray, coverages: Sequence[MarkerCoverage], order: Sequence[int],
                 model: SuccessModel, existing: Sequence[MarkerCoverage] = (),
                 weights: np.ndarray | None = None) -> np.ndarray:
    """(K + 1,) predicted recall R(0), ..., R(K) after the first j tags of ``order`` (module docstring).

    Args:
        base_info: (N, 6, 6) SPD information of every feasible pose without markers
            (1/rad^2, 1/m^2).
        coverages: per candidate, :class:`MarkerCoverage` under the model's marker model.
        order: (K,) candidate indices in placement order.
        model: P(success | score).
        existing: coverages of markers already on the walls (in every R(j), R(0) included).
        weights: (N,) pose weights summing to N (``plan --where``): R(j) = (1/N) sum_p w_p P(.);
            None: every pose 1.

    Returns:
        shares in [0, 1] (NaN-free); all zeros when N == 0.
    """
    lam = np.array(base_info, dtype=float, copy=True)
    N = lam.shape[0]
    out = np.zeros(len(order) + 1)
    if N == 0:
        return out
    for ex in existing:
        np.add.at(lam, ex.pose_idx, ex.info)
    prob = model.probability(-entropy(lam))
    total = float(prob.sum()) if weights is None else float(np.sum(prob * weights))
    out[0] = total / N
    for j, m in enumerate(order, start=1):
        cov = coverages[int(m)]
        if len(cov):
            lam[cov.pose_idx] += cov.info
            new = model.probability(-entropy(lam[cov.pose_idx]))
            change = new - prob[cov.pose_idx]
            total += float(np.sum(change if weights is None else change * weights[cov.pose_idx]))
            prob[cov.pose_idx] = new
        out[j] = total / N
    return np.clip(out, 0.0, 1.0)


def knee(curve: np.ndarray, points: float = KNEE_POINTS) -> int | None:
    """The knee of a recall curve R(0..K): the largest j >= 1 with ``R(j) - R(j-1) >= points/100``
    (every later tag adds less), or None when no tag adds ``points`` percentage points."""
    steps = np.diff(np.asarray(curve, dtype=float))
    big = np.flatnonzero(steps >= points / 100.0 - 1e-12)
    return int(big[-1]) + 1 if len(big) else None


def target_count(curve: np.ndarray, target: float) -> tuple[int, bool]:
    """How many of the plan's tags a recall target needs.

    Args:
        curve: (K + 1,) predicted recall R(0..K), K >= 1.
        target: share of poses in (0, 1].

    Returns:
        ``(j, True)``: the smallest j >= 1 with R(j) >= target; else ``(j, False)``: the smallest
        j >= 1 whose R(j) is the maximum of R(1..K) (within :data:`NEGLIGIBLE`): the tags after
        it add nothing.
    """
    r = np.asarray(curve, dtype=float)
    if len(r) < 2:
        raise ValueError("target_count: need a curve with at least one tag")
    hit = np.flatnonzero(r[1:] >= target - 1e-12)
    if len(hit):
        return int(hit[0]) + 1, True
    return int(np.flatnonzero(r[1:] >= r[1:].max() - NEGLIGIBLE)[0]) + 1, False
