"""Small random planning problems with a fitted-looking success model (recall curve, bounds,
predicted recall of evaluated placements)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from markerplace.geometry import world_from_marker_pose
from markerplace.plan.place.predicted_recall import RECALL_MODEL
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.success_model import SuccessModel
from markerplace.plan.types import MarkerCoverage, PlanData

__all__ = ["plan_data", "problem", "success_model"]


def problem(seed: int = 0, N: int = 40, C: int = 10, E: int = 0):
    """Random SPD base information and sparse PSD coverages (C candidates then E existing)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N, 6, 6))
    base = 100.0 * np.eye(6) + np.matmul(A, np.swapaxes(A, 1, 2))
    covs = []
    for _ in range(C + E):
        idx = np.sort(rng.choice(N, size=int(rng.integers(3, N // 2)), replace=False))
        B = rng.normal(size=(len(idx), 6, 2)) * rng.uniform(1, 30)
        covs.append(MarkerCoverage(idx, np.matmul(B, np.swapaxes(B, 1, 2))))
    return base, covs


def success_model(base: np.ndarray, slope: float = 1.5, above: float = 1.5) -> SuccessModel:
    """A logistic whose midpoint sits ``above`` nats over the median base score (most poses
    start in its convex part)."""
    s0 = float(np.median(-entropy(base)))
    return SuccessModel(-slope * (s0 + above), slope, 100, 50, 0.8, s0 - 10.0)


def plan_data(seed: int = 0, N: int = 40, C: int = 10, E: int = 0, above: float = 1.5) -> PlanData:
    base, covs = problem(seed, N, C, E)
    disc = SimpleNamespace(candidate_world_from_marker=np.stack(
        [world_from_marker_pose(np.array([i, 0.0, 1.5]), np.array([0.0, 1.0, 0.0])) for i in range(C)]))
    data = PlanData(disc, base, -entropy(base), covs, C, {})
    data.calibration[RECALL_MODEL] = {"model": success_model(base, above=above), "coverages": covs}
    return data
