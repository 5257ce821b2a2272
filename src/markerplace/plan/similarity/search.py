"""How the look-alike search finds and decides candidate pairs (used by :mod:`.stage`).

:class:`Pairs` holds the data every candidate pair is decided on and calls the compiled
decision (:mod:`.kernel`); :class:`Searcher` runs a FAISS range search in batches and
turns its candidates into counts; :func:`join_cells` searches the IVF cells one at a time, all
queries of a cell at once; :func:`expand_search` searches further cells by doubling rings. The
rules (the ``BAND`` around the threshold, why counts never exceed the exact ones) are in
:mod:`.stage`'s docstring.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Callable

import faiss
import numpy as np

from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.plan.similarity.kernel import count_candidates

__all__ = ["BAND", "Pairs", "Searcher", "expand_search", "faiss_threads", "join_cells", "resolve_threads"]

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

    def search(self, queries: np.ndarray, probes: tuple[np.ndarray, np.ndarray] | None = None,
               tick: Callable[[int], None] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Range-search ``queries`` (global row indices) in batches; count look-alikes exactly.

        Args:
            queries: (Q,) row indices.
            probes: for the IVF index, ((Q, k) int64 cells, (Q, k) float32 centroid distances):
                the cells each query searches, -1 = none (``range_search_preassigned``).
            tick: called with the number of queries done after each batch (progress).

        Returns:
            (Q,) int64 counts and (Q,) bool: whether the query had a look-alike among its
            candidates (at any 3D distance, itself excluded).
        """
        cfg = self.config
        cos_t, min_d2 = float(cfg.cos_threshold), float(cfg.min_distance) ** 2
        out = np.zeros(len(queries), dtype=np.int64)
        found = np.zeros(len(queries), dtype=bool)
        if probes is not None:
            self.index.nprobe = probes[0].shape[1]
        for s in range(0, len(queries), cfg.batch):
            q = queries[s:s + cfg.batch]
            contiguous = q[-1] - q[0] + 1 == len(q)
            xq = self.vectors[q[0]:q[-1] + 1] if contiguous else self.vectors[q]
            if probes is None:
                lims, sims, labels = self.index.range_search(xq, self.radius)
            else:
                lims, sims, labels = self.index.range_search_preassigned(
                    xq, self.radius, np.ascontiguousarray(probes[0][s:s + len(q)]),
                    np.ascontiguousarray(probes[1][s:s + len(q)]))
            out[s:s + len(q)], found[s:s + len(q)] = self.pairs.count(
                q, lims, sims if self.cosines else None, labels, cos_t, min_d2)
            if tick is not None:
                tick(len(q))
        return out, found


def expand_search(searcher: Searcher, quantizer, queries: np.ndarray, searched: np.ndarray, nprobe_max: int,
                  counts: np.ndarray, tick: Callable[[int], None] | None = None) -> None:
    """Search ``queries`` in further cells, by doubling rings: the nearest 2 n cells, then 4 n, ...
    (n = ``searched.shape[1]``) up to ``nprobe_max``, while the last ring held a look-alike.

    ``searched``: (Q, n) cells already searched. A cell is searched at most once per query (a
    bitmap of visited cells, even if the quantizer ranks ties differently between calls), so no
    pair is counted twice. Adds to ``counts``; ``tick(n)`` after each chunk of ``n`` queries.
    """
    nlist = searcher.index.nlist
    chunk = max(1, (1 << 26) // nlist)  # visited bitmaps of at most 64 MB
    for s in range(0, len(queries), chunk):
        q = queries[s:s + chunk]
        visited = np.zeros((len(q), nlist), dtype=bool)
        visited[np.arange(len(q))[:, None], np.maximum(searched[s:s + chunk], 0)] = True
        active = np.arange(len(q))
        lo = searched.shape[1]
        while lo < nprobe_max and len(active):
            hi = min(2 * lo, nprobe_max)
            dist, cells = quantizer.search(searcher.vectors[q[active]], hi)
            rows, ok = active[:, None], cells >= 0
            cells[~ok | visited[rows, np.maximum(cells, 0)]] = -1  # FAISS skips cells numbered -1
            visited[rows, np.maximum(cells, 0)] |= cells >= 0
            c, found = searcher.search(q[active], (cells, dist))
            counts[q[active]] += c
            active = active[found]
            lo = hi
        if tick is not None:
            tick(len(q))


def join_cells(searcher: Searcher, cells: np.ndarray, first: np.ndarray, h: int,
               counts: np.ndarray, tick: Callable[[int], None] | None = None) -> np.ndarray:
    """Range-search every point in its probed cells, one cell at a time; add to ``counts``.

    The same pairs as ``range_search_preassigned`` with each point's ``cells``, but grouped by
    cell: all queries that probe cell ``b`` are searched at once against ``b``'s members with a
    flat FAISS index, whose range search is a matrix product (BLAS) instead of one list scan per
    query. Only which candidates near the radius are returned can differ between the two (float
    rounding of the distance), and those are never look-alikes (the radius has the ``BAND``
    margin), so the counts are the same. ``config.threads`` threads take every ``T``-th cell,
    each with single-threaded FAISS and its own counts (summed: integers, any order), so the
    result does not depend on the thread count.

    Args:
        searcher: the IVF searcher (its ``vectors``, ``radius``, ``pairs`` and ``config``).
        cells: (P, n) int64 cells of every point, nearest first (-1 = none).
        first: (P,) the cell each point is filed in (``cells[:, 0]``).
        h: probe ranks ``>= h`` are the farther cells whose look-alike candidates are reported.
        counts: (P,) int64, incremented by each point's look-alike count.
        tick: called with 1 after each cell, from the worker threads (progress; must be
            thread-safe).

    Returns:
        (P,) bool: the point had a look-alike candidate (any 3D distance) in a cell of rank >= h.
    """
    cfg, Y = searcher.config, searcher.vectors
    cos_t, min_d2 = float(cfg.cos_threshold), float(cfg.min_distance) ** 2
    P, n = cells.shape
    nlist = searcher.index.nlist
    members = np.argsort(first, kind="stable")
    member_lims = np.searchsorted(first[members], np.arange(nlist + 1))
    flat_cells = cells.ravel()
    probes = np.argsort(flat_cells, kind="stable")  # (point, rank) pairs by cell, points ascending
    probe_lims = np.searchsorted(flat_cells[probes], np.arange(nlist + 1))
    n_threads = min(resolve_threads(cfg.threads), nlist)

    stop = threading.Event()  # set when the caller is interrupted: the threads end after their cell

    def part(t: int) -> tuple[np.ndarray, np.ndarray]:
        faiss.omp_set_num_threads(1)  # this thread's OpenMP setting (FAISS and its OpenBLAS)
        part_counts, part_found = np.zeros(P, dtype=np.int64), np.zeros(P, dtype=bool)
        flat = faiss.IndexFlatL2(Y.shape[1])
        for b in range(t, nlist, n_threads):
            if stop.is_set():
                break
            m = members[member_lims[b]:member_lims[b + 1]]
            pr = probes[probe_lims[b]:probe_lims[b + 1]]
            if len(m) == 0 or len(pr) == 0:
                if tick is not None:
                    tick(1)
                continue
            if tick is not None:
                tick(1)
            q, rank = pr // n, pr % n
            flat.reset()
            flat.add(Y[m])
            lims, _, labels = flat.range_search(Y[q], searcher.radius)
            c, f = searcher.pairs.count(q, lims, None, m[labels], cos_t, min_d2)
            part_counts[q] += c  # a point probes a cell once: no repeated indices
            far = rank >= h
            part_found[q[far]] |= f[far]
        return part_counts, part_found

    found_far = np.zeros(P, dtype=bool)
    with ThreadPoolExecutor(n_threads) as pool:  # FAISS and the kernel release the GIL
        try:
            for part_counts, part_found in pool.map(part, range(n_threads)):
                counts += part_counts
                found_far |= part_found
        except BaseException:  # Ctrl-C: do not wait for every thread to finish its share
            stop.set()
            raise
    return found_far
