"""Compiled decision of the look-alike candidates of a FAISS range search (numba).

:func:`count_candidates` walks every (query, candidate) pair of a range-search result once and
decides it exactly, as :mod:`markerplace.plan.similarity.stage` describes: the 3D distance in float64,
the cosine in float32 outside a band around the threshold and in float64 from the original
descriptors inside it. Hand-written because no library fuses this per-pair filter with the
search result: in numpy it needs several arrays as long as the candidate list (hundreds of
millions of pairs at a few million points), which dominated the time and the memory of the
stage. The sum order is fixed per pair, so the counts do not depend on the thread count; it
releases the GIL, so threads can decide different queries at once.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["count_block", "count_candidates"]


@numba.njit(cache=True, nogil=True, boundscheck=False, fastmath={"reassoc", "nsz"})
def count_candidates(queries, lims, labels, sims, has_sims, points, X, raw, norm, cos_t, band, min_d2,
                     counts, found):  # pragma: no cover - compiled
    """Decide every candidate pair exactly (see the module docstring); fill counts and found.

    Per query k (row ``queries[k]``) and candidate j (``labels[lims[k]:lims[k+1]]``, itself
    skipped): count j when ``|p_q - p_j|^2 > min_d2`` (float64) and the cosine > ``cos_t``:
    the float32 cosine (``sims`` or the dot of the unit rows of X) decides outside
    ``cos_t +- band``, the float64 cosine of the ``raw`` descriptors inside. ``found[k]``: some
    candidate is a look-alike at any distance (far ones first; near ones only until one is).
    """
    D = X.shape[1]
    for k in range(len(queries)):
        q = queries[k]
        px, py, pz = points[q, 0], points[q, 1], points[q, 2]
        c = 0
        near = False
        for e in range(lims[k], lims[k + 1]):
            j = labels[e]
            if j == q:
                continue
            dx, dy, dz = points[j, 0] - px, points[j, 1] - py, points[j, 2] - pz
            if not (dx * dx + dy * dy + dz * dz > min_d2):  # NaN points never count
                near = True
                continue
            s = sims[e] if has_sims else _cosine32(X, q, j, D)
            if _similar(q, j, s, raw, norm, cos_t, band, D):
                c += 1
        counts[k] = c
        f = c > 0
        if not f and near:
            for e in range(lims[k], lims[k + 1]):
                j = labels[e]
                if j != q:
                    s = sims[e] if has_sims else _cosine32(X, q, j, D)
                    if _similar(q, j, s, raw, norm, cos_t, band, D):
                        f = True
                        break
        found[k] = f


@numba.njit(cache=True, nogil=True, boundscheck=False, fastmath={"reassoc", "nsz"})
def count_block(queries, members, G, q_sq, m_sq, radius, need, points, X, raw, norm, cos_t, band, min_d2,
                counts, found):  # pragma: no cover - compiled
    """:func:`count_candidates` on a dense block, without a candidate list: the candidates of
    query ``queries[k]`` are the ``members[b]`` whose search vectors are nearer than ``radius``
    (squared): ``q_sq[k] + m_sq[b] - 2 G[k, b] < radius``, ``G`` the (Q, M) inner products of
    the search vectors and ``q_sq``, ``m_sq`` their squared norms. ``found[k]`` is computed only
    where ``need[k]`` (else it is: a far look-alike was counted).
    """
    D = X.shape[1]
    for k in range(len(queries)):
        q = queries[k]
        px, py, pz = points[q, 0], points[q, 1], points[q, 2]
        c = 0
        near = False
        for b in range(len(members)):
            if not (q_sq[k] + m_sq[b] - 2.0 * G[k, b] < radius):
                continue
            j = members[b]
            if j == q:
                continue
            dx, dy, dz = points[j, 0] - px, points[j, 1] - py, points[j, 2] - pz
            if not (dx * dx + dy * dy + dz * dz > min_d2):  # NaN points never count
                near = True
                continue
            if _similar(q, j, _cosine32(X, q, j, D), raw, norm, cos_t, band, D):
                c += 1
        counts[k] = c
        f = c > 0
        if not f and near and need[k]:
            for b in range(len(members)):
                j = members[b]
                if (q_sq[k] + m_sq[b] - 2.0 * G[k, b] < radius and j != q
                        and _similar(q, j, _cosine32(X, q, j, D), raw, norm, cos_t, band, D)):
                    f = True
                    break
        found[k] = f


# The helpers take only what they use: the first version passed every array to one helper
# (inline="always") and the kernel ran 5-7x slower per candidate (measured, numba 0.68).
@numba.njit(cache=True, nogil=True, boundscheck=False, fastmath={"reassoc", "nsz"})
def _cosine32(X, q, j, D):  # pragma: no cover - compiled
    """float32 dot of the unit rows q and j of X."""
    s = np.float32(0.0)
    for t in range(D):
        s += X[q, t] * X[j, t]
    return s


@numba.njit(cache=True, nogil=True, boundscheck=False, fastmath={"reassoc", "nsz"})
def _similar(q, j, s, raw, norm, cos_t, band, D):  # pragma: no cover - compiled
    """Cosine of rows q and j > cos_t, given its float32 value ``s``: decided by ``s`` outside
    the band, else in float64 from the raw descriptors."""
    if s > cos_t + band:
        return True
    if not (s > cos_t - band):
        return False
    dot = 0.0
    for t in range(D):
        dot += np.float64(raw[q, t]) * np.float64(raw[j, t])
    return dot > cos_t * norm[q] * norm[j]
