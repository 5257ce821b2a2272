"""Feature-similarity analysis (paper, Methods: "Analysis of feature similarity of 3D points").

For every observed 3D point p, ``n_p`` counts the OTHER points whose descriptor is similar
(cosine similarity > ``cos_threshold``) and whose 3D location is farther than ``min_distance``:
look-alikes far away, which would make a wrong place recognition costly. The score stage scales
the point's prior sigma by ``sqrt(1 + n_p)``.

Descriptors are L2-normalised here, so ``cos > t`` <=> ``||a - b||^2 < 2 - 2 t`` (0.2 for 0.9).

Methods:
    * ``exact``: blocked all-pairs (BLAS), O(P^2); for tests and small inputs.
    * ``approx``: an inverted-file search. PCA to ``pca_dims`` dimensions (an orthogonal
      projection never lengthens a difference, so the reduced-space radius test keeps every true
      pair), k-means cells in the reduced space, and for each point only the ``nprobe`` cells
      with the nearest centroids are searched; candidates are then verified exactly in 128-D
      (cosine and 3D distance). The only approximation is the probe limit: a look-alike in a
      cell that is not among the point's ``nprobe`` nearest is missed, so counts can only be
      too low. :func:`measure_error` reports the error against ``exact``.
    * ``auto``: ``exact`` below ``exact_max_points`` points, else ``approx``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

__all__ = ["SimilarityConfig", "count_similar", "count_similar_exact", "count_similar_approx",
           "measure_error", "benchmark_similarity", "synthetic_descriptors"]


@dataclass(frozen=True)
class SimilarityConfig:
    """Settings of the similarity analysis.

    Attributes:
        cos_threshold: descriptors with cosine similarity above this are similar (paper: 0.9).
        min_distance: only points farther than this (metres, 3D) count (paper: 2.0).
        method: ``"auto"``, ``"exact"`` or ``"approx"`` (see module docstring).
        exact_max_points: ``auto`` uses ``exact`` up to this many points.
        pca_dims: dimensions of the reduced space used to generate candidates.
        num_cells: k-means cells of the inverted file; 0 = ``clip(P / 400, 16, 4096)``.
        nprobe: cells searched per point (more = higher recall, slower).
        kmeans_sample: points used to fit PCA and k-means.
        kmeans_iters: k-means iterations.
        block: maximum elements of one distance block (memory: 4 bytes each, a few at a time).
        seed: seed of the sampling and k-means initialisation.
    """

    cos_threshold: float = 0.9
    min_distance: float = 2.0
    method: str = "auto"
    exact_max_points: int = 30000
    pca_dims: int = 32
    num_cells: int = 0
    nprobe: int = 12
    kmeans_sample: int = 100000
    kmeans_iters: int = 12
    block: int = 4_000_000
    seed: int = 0


def _normalise(descriptors: np.ndarray) -> np.ndarray:
    X = np.ascontiguousarray(descriptors, dtype=np.float32)
    n = np.linalg.norm(X, axis=1, keepdims=True)
    return X / np.maximum(n, 1e-12)


def _check(descriptors: np.ndarray, points_world: np.ndarray, config: SimilarityConfig) -> None:
    if descriptors.ndim != 2 or points_world.shape != (len(descriptors), 3):
        raise ValueError(f"descriptors (P, D) and points (P, 3) expected, got {descriptors.shape} and {points_world.shape}")
    if config.method not in ("auto", "exact", "approx"):
        raise ValueError(f"unknown similarity method {config.method!r}: use auto, exact or approx")


def count_similar(descriptors: np.ndarray, points_world: np.ndarray,
                  config: SimilarityConfig = SimilarityConfig()) -> np.ndarray:
    """n_p for every point: look-alikes (cos > threshold) farther than ``min_distance``.

    Args:
        descriptors: (P, D) descriptors (e.g. OpenCV SIFT, D = 128, any positive scale).
        points_world: (P, 3) 3D points, world metres.
        config: settings; ``method`` picks the algorithm.

    Returns:
        (P,) int32 counts (excluding the point itself).
    """
    descriptors = np.asarray(descriptors)
    points_world = np.asarray(points_world, dtype=np.float64)
    _check(descriptors, points_world, config)
    method = config.method
    if method == "auto":
        method = "exact" if len(descriptors) <= config.exact_max_points else "approx"
    t0 = time.perf_counter()
    if method == "exact":
        out = count_similar_exact(descriptors, points_world, config)
    else:
        out = count_similar_approx(descriptors, points_world, config)
    log.info("similarity (%s): %d points, mean n_p %.2f, %.1f s", method, len(out),
             float(out.mean()) if len(out) else 0.0, time.perf_counter() - t0)
    return out


def _count_block(Xq, Pq, gq, Xm, Pm, gm, cos_t: float, min_d2: float, counts: np.ndarray,
                 cand: np.ndarray | None = None) -> None:
    """Add to ``counts[gq]`` the exact matches of query rows against member rows.

    ``cand`` (optional (Q, M) bool) restricts the pairs checked; dense blocks use GEMM.
    """
    if cand is not None:
        nc = int(cand.sum())
        if nc == 0:
            return
        if nc < 0.05 * cand.size:
            qi, mj = np.nonzero(cand)
            dots = np.einsum("ij,ij->i", Xq[qi], Xm[mj])
            d2 = np.sum((Pq[qi] - Pm[mj]) ** 2, axis=1)
            ok = (dots > cos_t) & (d2 > min_d2) & (gq[qi] != gm[mj])
            np.add.at(counts, gq[qi[ok]], 1)
            return
    sim = (Xq @ Xm.T) > cos_t
    if cand is not None:
        sim &= cand
    d2 = (np.sum(Pq * Pq, axis=1)[:, None] + np.sum(Pm * Pm, axis=1)[None] - 2.0 * (Pq @ Pm.T))
    ok = sim & (d2 > min_d2) & (gq[:, None] != gm[None, :])
    counts[gq] += ok.sum(axis=1)


def count_similar_exact(descriptors: np.ndarray, points_world: np.ndarray,
                        config: SimilarityConfig = SimilarityConfig()) -> np.ndarray:
    """Exact n_p by blocked all-pairs dot products (O(P^2) time, O(block) memory).

    Args and returns as :func:`count_similar`.
    """
    X = _normalise(descriptors)
    Pw = np.asarray(points_world, dtype=np.float64)
    P = len(X)
    counts = np.zeros(P, dtype=np.int64)
    idx = np.arange(P)
    rows = max(1, config.block // max(P, 1))
    min_d2 = float(config.min_distance) ** 2
    for s in range(0, P, rows):
        e = min(P, s + rows)
        _count_block(X[s:e], Pw[s:e], idx[s:e], X, Pw, idx, config.cos_threshold, min_d2, counts)
    return counts.astype(np.int32)


def _kmeans(Y: np.ndarray, k: int, iters: int, rng: np.random.Generator) -> np.ndarray:
    """Plain Lloyd k-means (k-means++-lite init: random distinct points). Returns (k, d) centroids."""
    C = Y[rng.choice(len(Y), size=k, replace=False)].copy()
    for _ in range(iters):
        a = _nearest(Y, C, 1)[:, 0]
        sums = np.zeros_like(C, dtype=np.float64)
        np.add.at(sums, a, Y)
        cnt = np.bincount(a, minlength=k)
        empty = cnt == 0
        C[~empty] = (sums[~empty] / cnt[~empty, None]).astype(np.float32)
        if empty.any():  # re-seed empty cells at random points
            C[empty] = Y[rng.choice(len(Y), size=int(empty.sum()), replace=False)]
    return C


def _nearest(Y: np.ndarray, C: np.ndarray, n: int, chunk: int = 65536) -> np.ndarray:
    """(P, n) indices of the n nearest centroids of each row of Y (nearest first)."""
    out = np.empty((len(Y), n), dtype=np.int64)
    cc = np.sum(C * C, axis=1)
    for s in range(0, len(Y), chunk):
        d = cc[None] - 2.0 * (Y[s:s + chunk] @ C.T)
        if n == 1:
            out[s:s + chunk, 0] = np.argmin(d, axis=1)
        else:
            part = np.argpartition(d, n - 1, axis=1)[:, :n]
            order = np.argsort(np.take_along_axis(d, part, axis=1), axis=1)
            out[s:s + chunk] = np.take_along_axis(part, order, axis=1)
    return out


def count_similar_approx(descriptors: np.ndarray, points_world: np.ndarray,
                         config: SimilarityConfig = SimilarityConfig()) -> np.ndarray:
    """n_p by the inverted-file search (see module docstring); never over-counts.

    Args and returns as :func:`count_similar`.
    """
    X = _normalise(descriptors)
    Pw = np.asarray(points_world, dtype=np.float64)
    P = len(X)
    counts = np.zeros(P, dtype=np.int64)
    if P < 2:
        return counts.astype(np.int32)
    rng = np.random.default_rng(config.seed)
    sample = X if P <= config.kmeans_sample else X[np.sort(rng.choice(P, config.kmeans_sample, replace=False))]
    mu = sample.mean(axis=0)
    d = min(config.pca_dims, X.shape[1])
    _, _, Vt = np.linalg.svd(sample - mu, full_matrices=False)
    B = np.ascontiguousarray(Vt[:d].T, dtype=np.float32)  # (D, d) orthonormal columns
    Y = (X - mu) @ B
    K = config.num_cells or int(np.clip(P // 400, 16, 4096))
    K = min(K, len(sample))
    nprobe = min(config.nprobe, K)
    C = _kmeans(sample @ B - mu @ B, K, config.kmeans_iters, rng)
    probes = _nearest(Y, C, nprobe)  # (P, nprobe)
    cell = probes[:, 0]  # a point's own cell is its nearest centroid
    order = np.argsort(cell, kind="stable")
    starts = np.searchsorted(cell[order], np.arange(K + 1))
    # queries grouped by probed cell
    q_pt = np.repeat(np.arange(P), nprobe)
    q_cell = probes.reshape(-1)
    q_order = np.argsort(q_cell, kind="stable")
    q_pt = q_pt[q_order]
    q_starts = np.searchsorted(q_cell[q_order], np.arange(K + 1))
    thr = (2.0 - 2.0 * config.cos_threshold) * (1.0 + 1e-4) + 1e-6
    min_d2 = float(config.min_distance) ** 2
    yy = np.sum(Y * Y, axis=1)
    for c in range(K):
        members = order[starts[c]:starts[c + 1]]
        queries = q_pt[q_starts[c]:q_starts[c + 1]]
        if len(members) == 0 or len(queries) == 0:
            continue
        Ym, Xm, Pm = Y[members], X[members], Pw[members]
        rows = max(1, config.block // len(members))
        for s in range(0, len(queries), rows):
            qs = queries[s:s + rows]
            d2 = yy[qs][:, None] + yy[members][None] - 2.0 * (Y[qs] @ Ym.T)
            _count_block(X[qs], Pw[qs], qs, Xm, Pm, members, config.cos_threshold, min_d2, counts, cand=d2 < thr)
    return counts.astype(np.int32)


# ----------------------------------------------------------------------------------------------
# measurement and benchmark


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


def measure_error(descriptors: np.ndarray, points_world: np.ndarray,
                  config: SimilarityConfig = SimilarityConfig()) -> dict:
    """Approximate vs exact counts on the same input.

    Returns a dict: ``points``, ``mean_abs_error`` (mean |n_approx - n_exact|), ``max_abs_error``,
    ``recall`` (found / true look-alike pairs, i.e. sum n_approx / sum n_exact), ``exact_mean``
    (mean n_exact), ``frac_points_exact`` (points whose count is exact), and both timings (s).
    """
    t0 = time.perf_counter()
    ex = count_similar_exact(descriptors, points_world, config)
    t1 = time.perf_counter()
    ap = count_similar_approx(descriptors, points_world, config)
    t2 = time.perf_counter()
    err = np.abs(ap.astype(np.int64) - ex)
    total = int(ex.sum())
    return {
        "points": int(len(ex)),
        "mean_abs_error": float(err.mean()),
        "max_abs_error": int(err.max()) if len(err) else 0,
        "recall": float(ap.sum() / total) if total else 1.0,
        "over_counts": int(np.sum(ap > ex)),
        "exact_mean": float(ex.mean()),
        "frac_points_exact": float(np.mean(err == 0)),
        "exact_seconds": t1 - t0,
        "approx_seconds": t2 - t1,
    }


def benchmark_similarity(n_points: int = 200000, seed: int = 0,
                         config: SimilarityConfig = SimilarityConfig(), check_points: int = 20000) -> dict:
    """Time :func:`count_similar_approx` on ``n_points`` synthetic SIFT-like descriptors.

    Also measures the approximation error on a ``check_points`` subset (exact is O(P^2)).
    Returns a dict with ``n_points``, ``approx_seconds``, ``points_per_second``, ``mean_n_p`` and
    the :func:`measure_error` figures of the subset under ``check_*`` keys.
    """
    D, pts = synthetic_descriptors(n_points, seed)
    t0 = time.perf_counter()
    ap = count_similar_approx(D, pts, config)
    dt = time.perf_counter() - t0
    out = {"n_points": int(n_points), "approx_seconds": dt, "points_per_second": n_points / max(dt, 1e-9),
           "mean_n_p": float(ap.mean())}
    if check_points:
        Ds, ps = synthetic_descriptors(min(check_points, n_points), seed + 1)
        out.update({f"check_{k}": v for k, v in measure_error(Ds, ps, config).items()})
    return out
