"""Uniform downsampling of candidate spots: keep a spot unless a kept spot facing a similar way is
too close. Shared by the mesh plan's wall candidates
(:mod:`markerplace.plan.discretize.wall_candidates`, 2D points along the free-space perimeter)
and the frames plan's (:mod:`markerplace.plan.frames.candidates`, 3D points on the fused surface).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["space_out"]


def space_out(xy: np.ndarray, n2: np.ndarray, spacing: float, cos_diff: float,
              accept: Callable[[np.ndarray], np.ndarray], batch: int = 32) -> list[int]:
    """Greedy uniform downsampling in the given order: keep a point unless a kept point with a
    similar normal is closer than ``spacing``; ``accept(indices) -> bool`` is asked in batches
    and a refused point does not block its neighbours.

    Args:
        xy: (P, D) points (D = 2 or 3), metres.
        n2: (P, E) unit normals (E = 2 or 3); similar: dot product >= ``cos_diff``.
    """
    kept: list[int] = []
    i, P = 0, len(xy)
    D, E = (xy.shape[1], n2.shape[1]) if P else (2, 2)
    while i < P:
        idx: list[int] = []
        KX, KN = xy[kept].reshape(-1, D), n2[kept].reshape(-1, E)
        while i < P and len(idx) < batch:
            if len(KX) and np.any((np.linalg.norm(KX - xy[i], axis=1) < spacing) & (KN @ n2[i] >= cos_diff)):
                i += 1
                continue
            if idx and np.any((np.linalg.norm(xy[idx] - xy[i], axis=1) < spacing) & (n2[idx] @ n2[i] >= cos_diff)):
                break  # decided after this batch is accepted or refused
            idx.append(i)
            i += 1
        if not idx:
            continue
        ok = accept(np.asarray(idx))
        for k, good in zip(idx, ok):
            if not good:
                continue
            if kept and np.any((np.linalg.norm(xy[kept] - xy[k], axis=1) < spacing) & (n2[kept] @ n2[k] >= cos_diff)):
                continue
            kept.append(k)
    return kept
