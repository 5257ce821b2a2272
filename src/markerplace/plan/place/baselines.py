"""The paper's baseline placements: k candidates drawn at random, and k spread evenly along the
free-space perimeter (:mod:`markerplace.plan.place.methods` registers them as ``random`` and
``uniform``)."""

from __future__ import annotations

import numpy as np

from markerplace.errors import UserError
from markerplace.plan.place.greedy import check_k

__all__ = ["random_placement", "uniform_placement"]


def random_placement(num_candidates: int, k: int, seed: int) -> list[int]:
    """k distinct candidate indices drawn uniformly (``numpy.random.default_rng(seed)``)."""
    k = check_k(k, num_candidates)
    rng = np.random.default_rng(seed)
    return [int(i) for i in rng.choice(num_candidates, size=k, replace=False)]


def uniform_placement(arclength: np.ndarray, perimeter_length: float, k: int,
                      seed: int) -> list[int]:
    """k candidates spread evenly along the free-space perimeter (the paper's 'uniform').

    As in Meyer-Delius et al. (2011), markers are distributed roughly uniformly along the
    perimeter: targets at arc positions ``o + i L / k`` (i = 0..k-1) with a random offset
    ``o ~ U[0, L/k)`` drawn from ``numpy.random.default_rng(seed)``; each target in turn takes
    the nearest unused candidate (distance measured around the closed perimeter, ties to the
    smallest index).

    Args:
        arclength: (C,) position of each candidate along the perimeter, metres in [0, L]
            (several perimeter loops may be concatenated into one parameterization).
        perimeter_length: total perimeter length L, metres.
        k: number of markers, 1 <= k <= C.
        seed: random seed of the offset.

    Returns:
        k distinct candidate indices, in the order of the targets.
    """
    s = np.asarray(arclength, dtype=float).reshape(-1)
    C = s.shape[0]
    k = check_k(k, C)
    L = float(perimeter_length)
    if not L > 0:
        raise UserError("perimeter length must be positive")
    rng = np.random.default_rng(seed)
    step = L / k
    targets = rng.uniform(0.0, step) + step * np.arange(k)
    used = np.zeros(C, dtype=bool)
    out: list[int] = []
    for t in targets:
        d = np.abs(np.mod(s - t + L / 2.0, L) - L / 2.0)
        d[used] = np.inf
        i = int(np.argmin(d))
        used[i] = True
        out.append(i)
    return out
