"""How good a look-alike count is: synthetic SIFT-like inputs with planted look-alikes
(:func:`synthetic_descriptors`) and the error of approximate counts against exact ones
(:func:`measure_error`), for the tests and ``benchmarks/similarity.py``."""

from __future__ import annotations

import numpy as np

__all__ = ["measure_error", "synthetic_descriptors"]


def synthetic_descriptors(n_points: int, seed: int = 0, dup_fraction: float = 0.3,
                          extent: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """SIFT-like test data: (P, 128) float32 descriptors (L2 norm 512) and (P, 3) points.

    Base descriptors are non-negative, sparse 4x4x8 gradient histograms (gamma-distributed bins
    with per-cell magnitudes, clipped at 0.2 and renormalised, as SIFT does). A fraction
    ``dup_fraction`` are planted look-alikes: noisy copies of another descriptor (cosine mostly
    0.85-0.99), in groups of 2-30, half of them placed far from the original (> 2 m) and half
    near it (the same point seen from another pose).
    """
    rng = np.random.default_rng(seed)
    n_base = max(1, int(round(n_points * (1 - dup_fraction))))
    cell = rng.gamma(1.0, 1.0, size=(n_base, 16, 1))
    D = (cell * rng.gamma(0.4, 1.0, size=(n_base, 16, 8))).reshape(n_base, 128)
    pts = rng.uniform(0, extent, size=(n_base, 3)) * np.array([1.0, 1.0, 0.15])
    out_d, out_p = [D], [pts]
    left = n_points - n_base
    while left > 0:
        g = int(min(left, rng.integers(2, 31)))
        src = int(rng.integers(n_base))
        noise = rng.uniform(0.05, 0.45)
        copies = np.abs(D[src] + noise * D[src].std() * rng.standard_normal((g, 128)))
        far = rng.random(g) < 0.5
        p = np.where(far[:, None], rng.uniform(0, extent, (g, 3)) * np.array([1.0, 1.0, 0.15]),
                     pts[src] + rng.normal(0, 0.3, (g, 3)))
        out_d.append(copies)
        out_p.append(p)
        left -= g
    D = np.vstack(out_d)[:n_points]
    pts = np.vstack(out_p)[:n_points]
    D = D / np.linalg.norm(D, axis=1, keepdims=True)
    D = np.minimum(D, 0.2)
    D = D / np.linalg.norm(D, axis=1, keepdims=True) * 512.0
    perm = rng.permutation(n_points)
    return D[perm].astype(np.float32), pts[perm]


def measure_error(approx: np.ndarray, exact: np.ndarray) -> dict:
    """Error of approximate counts against exact counts of the same points.

    Args:
        approx, exact: (Q,) counts of the same Q points.

    Returns:
        dict: ``points``; ``recall`` (found / true look-alike pairs = sum approx / sum exact, 1.0
        when there are none); ``mean_abs_error`` and ``max_abs_error`` of the counts;
        ``frac_points_exact`` (points whose count is exact); ``over_counts`` (points counted too
        high: must be 0); ``exact_mean`` (mean exact count).
    """
    approx = np.asarray(approx, dtype=np.int64)
    exact = np.asarray(exact, dtype=np.int64)
    err = approx - exact
    total = int(exact.sum())
    return {
        "points": int(len(exact)),
        "recall": float(approx.sum() / total) if total else 1.0,
        "mean_abs_error": float(np.abs(err).mean()) if len(err) else 0.0,
        "max_abs_error": int(np.abs(err).max()) if len(err) else 0,
        "frac_points_exact": float(np.mean(err == 0)) if len(err) else 1.0,
        "over_counts": int(np.sum(err > 0)),
        "exact_mean": float(exact.mean()) if len(exact) else 0.0,
    }
