"""How the look-alike search finds and decides candidate pairs (used by :mod:`.stage`).

:class:`Pairs` holds the data every candidate pair is decided on and calls the compiled
decision (:mod:`.kernel`); :class:`Searcher` runs a FAISS range search in batches and
turns its candidates into counts (the exact search; the IVF search is in :mod:`.join`). The
rules (the ``BAND`` around the threshold, why counts never exceed the exact ones) are in
:mod:`.stage`'s docstring.
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Callable

import faiss
import numpy as np
from threadpoolctl import threadpool_limits

from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.plan.similarity.kernel import count_candidates

__all__ = ["BAND", "Pairs", "Searcher", "blas_threads", "faiss_threads", "resolve_threads"]

# half-width of the band around the cosine threshold in which a pair's float32 cosine (from
# FAISS) is not trusted and the cosine is recomputed in float64 (10x the float32 error bound)
BAND = 1e-4


def resolve_threads(n: int) -> int:
    """``n``, or for 0 the CPUs this process may run on."""
    if n > 0:
        return int(n)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


@contextmanager
def faiss_threads(n: int):
    """Run FAISS (and its OpenBLAS) on ``n`` OpenMP threads (0: the CPUs we may use)."""
    n = resolve_threads(n)
    old = faiss.omp_get_max_threads()
    faiss.omp_set_num_threads(n)
    try:
        yield
    finally:
        faiss.omp_set_num_threads(old)


@contextmanager
def blas_threads(n: int):
    """Run the BLAS libraries of this process (numpy's OpenBLAS, FAISS's) on ``n`` threads,
    restored afterwards (threadpoolctl).

    The cell joins multiply small matrices with numpy on several Python threads at once; each
    product must stay on its own thread (an OpenBLAS thread pool per call, or two callers
    waiting on one pool, cost 4x on a busy 2-core machine, measured).
    """
    with threadpool_limits(limits=int(n), user_api="blas"):
        yield


class Pairs:
    """The data every candidate pair is decided on.

    Attributes:
        X: (P, D) float32 unit descriptors (normalised in float64, zero rows stay zero).
        raw: (P, D) the original descriptors (any numeric dtype), for float64 recomputation.
        norm: (P,) float64 norms of ``raw``.
        points: (P, 3) float64 world points, metres.
    """

    def __init__(self, descriptors: np.ndarray, points_world: np.ndarray, chunk: int = 65536):
        self.raw = descriptors
        self.points = np.asarray(points_world, dtype=np.float64)
        P, D = descriptors.shape
        self.X = np.empty((P, D), dtype=np.float32)
        self.norm = np.empty(P, dtype=np.float64)
        for s in range(0, P, chunk):
            d = descriptors[s:s + chunk].astype(np.float64)
            n = np.sqrt(np.einsum("ij,ij->i", d, d))
            self.norm[s:s + chunk] = n
            self.X[s:s + chunk] = d / np.maximum(n, 1e-300)[:, None]

    def count(self, queries: np.ndarray, lims: np.ndarray, sims: np.ndarray | None, labels: np.ndarray,
              cos_t: float, min_d2: float) -> tuple[np.ndarray, np.ndarray]:
        """Exact look-alike counts of ``queries`` from their range-search candidates.

        Args:
            queries: (nq,) global row indices of the queries.
            lims, sims, labels: a FAISS range-search result (candidates of query k are
                ``labels[lims[k]:lims[k+1]]``); ``sims``: their float32 cosines, or None to
                compute them from ``X`` (when the search measured something else).
            cos_t: cosine threshold (strict); min_d2: squared minimum distance (strict).

        Returns:
            (nq,) int64 counts, and (nq,) bool: the query has a look-alike among the candidates
            (cosine > ``cos_t``, at any 3D distance, itself excluded).
        """
        nq = len(queries)
        counts = np.zeros(nq, dtype=np.int64)
        found = np.zeros(nq, dtype=np.bool_)
        has_sims = sims is not None
        count_candidates(np.asarray(queries, dtype=np.int64), lims.astype(np.int64, copy=False),
                         labels.astype(np.int64, copy=False), sims if has_sims else np.zeros(0, np.float32),
                         has_sims, self.points, self.X, self.raw, self.norm, float(cos_t), BAND, float(min_d2),
                         counts, found)
        return counts, found


class Searcher:
    """A FAISS index over ``vectors`` and how to turn its range-search results into counts.

    Attributes:
        index: the FAISS index (``IndexFlatIP`` over ``pairs.X``, or ``IndexIVFFlat``, L2, over
            the reduced vectors).
        vectors: (P, d) float32 vectors the index holds and the queries are taken from.
        radius: the range-search radius (an inner product for IP, a squared distance for L2).
        cosines: whether the index returns the float32 cosines (else they are computed from
            ``pairs.X`` for the candidates).
    """

    def __init__(self, index, pairs: Pairs, vectors: np.ndarray, radius: float, cosines: bool,
                 config: SimilarityConfig):
        self.index, self.pairs, self.vectors = index, pairs, vectors
        self.radius, self.cosines, self.config = radius, cosines, config

    def search(self, queries: np.ndarray,
               tick: Callable[[int], None] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Range-search ``queries`` (global row indices) in batches; count look-alikes exactly.

        Args:
            queries: (Q,) row indices.
            tick: called with the number of queries done after each batch (progress).

        Returns:
            (Q,) int64 counts and (Q,) bool: whether the query had a look-alike among its
            candidates (at any 3D distance, itself excluded).
        """
        cfg = self.config
        cos_t, min_d2 = float(cfg.cos_threshold), float(cfg.min_distance) ** 2
        out = np.zeros(len(queries), dtype=np.int64)
        found = np.zeros(len(queries), dtype=bool)
        for s in range(0, len(queries), cfg.batch):
            q = queries[s:s + cfg.batch]
            contiguous = q[-1] - q[0] + 1 == len(q)
            xq = self.vectors[q[0]:q[-1] + 1] if contiguous else self.vectors[q]
            lims, sims, labels = self.index.range_search(xq, self.radius)
            out[s:s + len(q)], found[s:s + len(q)] = self.pairs.count(
                q, lims, sims if self.cosines else None, labels, cos_t, min_d2)
            if tick is not None:
                tick(len(q))
        return out, found
