"""Metrics of the testbed: pose errors and recall.

``recall = #{queries with t_err <= t_max and r_err <= r_max} / #queries``. Thresholds are
INCLUSIVE (an error exactly at the threshold counts as a hit). A query that failed to localize
has errors ``inf`` (or NaN) and always counts as a miss; it stays in the denominator.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

#: Recall thresholds (translation metres, rotation degrees); the paper's main one is (0.05, 5).
THRESHOLDS: tuple[tuple[float, float], ...] = ((0.01, 1.0), (0.05, 5.0), (0.10, 10.0), (1.0, 30.0))
MAIN_THRESHOLD: tuple[float, float] = (0.05, 5.0)


def main_threshold(thresholds: Sequence[tuple[float, float]]) -> tuple[float, float]:
    """The threshold tables and diagnostics report: :data:`MAIN_THRESHOLD` when it is one of
    ``thresholds`` ((metres, degrees) pairs), else the first of them."""
    return MAIN_THRESHOLD if MAIN_THRESHOLD in thresholds else tuple(thresholds[0])


def pose_errors_batch(est_world_from_cam: np.ndarray, true_world_from_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Translation (metres) and rotation (degrees) errors, the paper's delta_t and delta_R.

    Args:
        est_world_from_cam: (N, 4, 4) estimates; a failed query is all-NaN.
        true_world_from_cam: (N, 4, 4) ground truth.

    Returns:
        (N,) ``||t_est - t_true||`` and (N,) ``arccos((tr(R_est^T R_true) - 1) / 2)`` in degrees;
        ``inf`` for failed queries.
    """
    est = np.asarray(est_world_from_cam, dtype=float)
    true = np.asarray(true_world_from_cam, dtype=float)
    failed = ~np.isfinite(est).all(axis=(1, 2))
    t_err = np.linalg.norm(est[:, :3, 3] - true[:, :3, 3], axis=1)
    tr = np.einsum("nij,nij->n", est[:, :3, :3], true[:, :3, :3])  # trace(R_est^T R_true)
    r_err = np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))
    t_err[failed] = np.inf
    r_err[failed] = np.inf
    return t_err, r_err


def hit_mask(t_err: np.ndarray, r_err: np.ndarray, t_max: float, r_max: float) -> np.ndarray:
    """(n,) bool: queries with ``t_err <= t_max`` (metres) AND ``r_err <= r_max`` (degrees).

    Failures (``inf`` or NaN errors) are misses.
    """
    t_err = np.asarray(t_err, dtype=float)
    r_err = np.asarray(r_err, dtype=float)
    if t_err.shape != r_err.shape:
        raise ValueError("t_err and r_err must have the same shape")
    with np.errstate(invalid="ignore"):
        return (t_err <= t_max) & (r_err <= r_max)  # NaN compares False -> miss


def recall(t_err: np.ndarray, r_err: np.ndarray, t_max: float, r_max: float) -> float:
    """Fraction in [0, 1] of queries with ``t_err <= t_max`` AND ``r_err <= r_max`` (inclusive).

    Failures (``inf`` or NaN errors) count as misses. Empty input gives NaN.
    """
    hit = hit_mask(t_err, r_err, t_max, r_max)
    return float(hit.mean()) if hit.size else float("nan")


def recalls(t_err: np.ndarray, r_err: np.ndarray,
            thresholds: Sequence[tuple[float, float]] = THRESHOLDS) -> list[float]:
    """:func:`recall` at each (t_max metres, r_max degrees) threshold."""
    return [recall(t_err, r_err, t, r) for t, r in thresholds]


def threshold_label(threshold: tuple[float, float]) -> str:
    """Human label like ``5cm/5deg`` or ``1m/30deg`` for a (metres, degrees) threshold."""
    t, r = threshold
    dist = f"{t * 100:g}cm" if t < 1.0 else f"{t:g}m"
    return f"{dist}/{r:g}deg"
