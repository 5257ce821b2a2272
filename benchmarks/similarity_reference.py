"""The look-alike search before FAISS (markerplace <= the FAISS port): benchmark reference only.

This is the hand-written implementation that ``markerplace.plan.similarity.stage`` used until it moved
to FAISS, kept verbatim (renamed ``ReferenceConfig`` / ``count_similar_reference``) so that
``benchmarks/similarity.py`` can time "today's code" against the FAISS path on the same input.
It is not part of the package and nothing in ``src/`` imports it.

Methods (as documented then):
    * ``exact``: blocked all-pairs (BLAS), O(P^2).
    * ``approx``: PCA to ``pca_dims`` dimensions, hand-written k-means cells in the reduced space,
      near-coincident cells merged, each cell searches at most ``nprobe`` cells that the triangle
      inequality cannot rule out; candidates verified exactly in the full dimension (cosine and
      3D distance), so counts can only be too low.
    * ``auto``: ``exact`` below ``exact_max_points`` points, else ``approx``.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np

log = logging.getLogger(__name__)

__all__ = ["ReferenceConfig", "count_similar_reference", "count_similar_exact", "count_similar_approx"]


@dataclass(frozen=True)
class ReferenceConfig:
    """Settings of the similarity analysis.

    Attributes:
        cos_threshold: descriptors with cosine similarity above this are similar (paper: 0.9).
        min_distance: only points farther than this (metres, 3D) count (paper: 2.0).
        method: ``"auto"``, ``"exact"`` or ``"approx"`` (see module docstring).
        exact_max_points: ``auto`` uses ``exact`` up to this many points.
        pca_dims: dimensions of the reduced space used to generate candidates.
        num_cells: k-means cells of the inverted file; 0 = ``clip(sqrt(nprobe P), 16, 8192)``.
        nprobe: at most this many cells are searched per cell (those that can hold a partner,\n            nearest first by the triangle-inequality bound); more = higher recall, slower.
        kmeans_sample: points used to fit PCA and k-means.
        kmeans_iters: k-means iterations.
        merge_radius: cells whose centroids lie within this fraction of the look-alike radius of
            a leader cell are searched as one (k-means splits dense blobs of look-alikes into
            many small cells, which a per-cell probe limit would otherwise miss).
        max_merge: at most this many k-means cells form one merged cell (bounds the cost).
        block: maximum elements of one distance block (memory: 4 bytes each, a few at a time).
        seed: seed of the sampling and k-means initialisation.
    """

    cos_threshold: float = 0.9
    min_distance: float = 2.0
    method: str = "auto"
    exact_max_points: int = 30000
    pca_dims: int = 32
    num_cells: int = 0
    nprobe: int = 16
    kmeans_sample: int = 50000
    kmeans_iters: int = 8
    merge_radius: float = 0.7
    max_merge: int = 16
    block: int = 4_000_000
    seed: int = 0


def _normalise(descriptors: np.ndarray) -> np.ndarray:
    X = np.ascontiguousarray(descriptors, dtype=np.float32)
    n = np.linalg.norm(X, axis=1, keepdims=True)
    return X / np.maximum(n, 1e-12)


def _check(descriptors: np.ndarray, points_world: np.ndarray, config: ReferenceConfig) -> None:
    if descriptors.ndim != 2 or points_world.shape != (len(descriptors), 3):
        raise ValueError(f"descriptors (P, D) and points (P, 3) expected, got {descriptors.shape} and {points_world.shape}")
    if config.method not in ("auto", "exact", "approx"):
        raise ValueError(f"unknown similarity method {config.method!r}: use auto, exact or approx")


def count_similar_reference(descriptors: np.ndarray, points_world: np.ndarray,
                  config: ReferenceConfig = ReferenceConfig()) -> np.ndarray:
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
    log.info("reference similarity (%s): %d points, mean n_p %.2f, %.1f s", method, len(out),
             float(out.mean()) if len(out) else 0.0, time.perf_counter() - t0)
    return out


def _count_block(X, Pw, q: np.ndarray, m: np.ndarray, cos_t: float, min_d2: float, counts: np.ndarray,
                 qi: np.ndarray | None = None, mj: np.ndarray | None = None) -> None:
    """Add to ``counts[q]`` the exact look-alikes of rows ``q`` among rows ``m`` of X.

    Args:
        X: (P, D) unit descriptors; Pw: (P, 3) points; q, m: global row indices.
        qi, mj: optional candidate pairs (positions in q and m); only those are checked
            (exactly, in the full dimension). Without them all pairs are checked by one GEMM.
    """
    if qi is None:
        qi, mj = np.nonzero((X[q] @ X[m].T) > cos_t)
        gq, gm = q[qi], m[mj]
    else:
        gq, gm = q[qi], m[mj]
        keep = np.einsum("ij,ij->i", X[gq], X[gm]) > cos_t
        gq, gm = gq[keep], gm[keep]
    if len(gq) == 0:
        return
    d2 = np.sum((Pw[gq] - Pw[gm]) ** 2, axis=1)
    ok = (d2 > min_d2) & (gq != gm)
    np.add.at(counts, gq[ok], 1)


def count_similar_exact(descriptors: np.ndarray, points_world: np.ndarray,
                        config: ReferenceConfig = ReferenceConfig()) -> np.ndarray:
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
        _count_block(X, Pw, idx[s:s + rows], idx, config.cos_threshold, min_d2, counts)
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
                         config: ReferenceConfig = ReferenceConfig()) -> np.ndarray:
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
    mu = sample.mean(axis=0, dtype=np.float64)
    d = min(config.pca_dims, X.shape[1])
    cov = np.cov((sample - mu.astype(np.float32)).T.astype(np.float64))
    _, V = np.linalg.eigh(cov)
    B = np.ascontiguousarray(V[:, ::-1][:, :d], dtype=np.float32)  # (D, d) orthonormal columns
    Y = (X - mu.astype(np.float32)) @ B
    nprobe_req = max(1, config.nprobe)
    K = config.num_cells or int(np.clip(np.sqrt(nprobe_req * P), 16, 8192))
    K = min(K, len(sample))
    C = _kmeans(Y if P <= config.kmeans_sample else (sample - mu.astype(np.float32)) @ B, K, config.kmeans_iters, rng)
    thr = (2.0 - 2.0 * config.cos_threshold) * (1.0 + 1e-4) + 1e-6  # squared radius
    r = float(np.sqrt(thr))
    # k-means splits a dense blob of look-alikes into many cells; merge cells whose centroids lie
    # within r of a leader (no chaining: a merged cell spans at most 2 r around its leader)
    sub = _nearest(Y, C, 1)[:, 0]
    size = np.bincount(sub, minlength=K)
    cc = np.sum(C * C, axis=1)
    merged = np.full(K, -1, dtype=np.int64)
    leaders: list[int] = []
    nsub = np.ones(K, dtype=np.int64)  # sub-cells per merged cell (indexed by merged id)
    for k in np.argsort(-size, kind="stable"):
        if size[k] == 0:
            continue
        if leaders:
            L = np.asarray(leaders)
            dl = cc[L] + cc[k] - 2.0 * (C[L] @ C[k])
            dl[nsub[:len(L)] >= config.max_merge] = np.inf
            j = int(np.argmin(dl))
            if dl[j] < (config.merge_radius * r) ** 2:
                merged[k] = j
                nsub[j] += 1
                continue
        merged[k] = len(leaders)
        leaders.append(int(k))
    cell = merged[sub]
    M = len(leaders)
    order = np.argsort(cell, kind="stable")
    starts = np.searchsorted(cell[order], np.arange(M + 1))
    gid = order
    X, Y, Pw = X[order], Y[order], Pw[order]
    cell = cell[order]
    sub = sub[order]
    # per merged cell: radius around each sub-centroid, for the triangle-inequality bound
    rad = np.zeros(K, dtype=np.float32)
    np.maximum.at(rad, sub, np.linalg.norm(Y - C[sub], axis=1))
    # ||a - b||^2 < thr  <=>  2 a.b - |a|^2 - |b|^2 > -thr: one GEMM with augmented rows
    yy = np.sum(Y * Y, axis=1)
    Yq_aug = np.hstack([2.0 * Y, -yy[:, None], -np.ones((P, 1), np.float32)])
    Ym_aug = np.hstack([Y, np.ones((P, 1), np.float32), yy[:, None]])
    min_d2 = float(config.min_distance) ** 2
    local = np.zeros(P, dtype=np.int64)
    used = size > 0
    for c in range(M):
        q0, q1 = starts[c], starts[c + 1]
        subs = np.unique(sub[q0:q1])
        # lower bound of partner distance per target sub-cell, over this cell's sub-cells
        dcs = np.sqrt(np.maximum(cc[subs][:, None] + cc[None] - 2.0 * (C[subs] @ C.T), 0.0))
        gap_sub = np.min(dcs - rad[subs][:, None], axis=0) - rad
        gap_sub[~used] = np.inf
        gap = np.full(M, np.inf)
        np.minimum.at(gap, merged[used], gap_sub[used])
        targets = np.flatnonzero(gap < r)
        # at most nprobe merged cells, nearest first by the bound (the only approximation)
        if len(targets) > nprobe_req:
            targets = targets[np.argsort(gap[targets], kind="stable")[:nprobe_req]]
        midx = np.concatenate([np.arange(starts[t], starts[t + 1]) for t in targets])
        rows = max(1, config.block // len(midx))
        Ym = Ym_aug[midx]
        for s0 in range(q0, q1, rows):
            qidx = np.arange(s0, min(q1, s0 + rows))
            qi, mj = np.nonzero((Yq_aug[qidx] @ Ym.T) > -thr)
            if len(qi) == 0:
                continue
            if len(qi) > 0.05 * len(qidx) * len(midx):  # dense: verify the block by GEMM
                _count_block(X, Pw, qidx, midx, config.cos_threshold, min_d2, local)
            else:
                _count_block(X, Pw, qidx, midx, config.cos_threshold, min_d2, local, qi, mj)
    counts[gid] = local
    return counts.astype(np.int32)
