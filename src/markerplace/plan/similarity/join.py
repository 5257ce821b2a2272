"""The IVF look-alike search as cell-by-cell joins (used by :mod:`.stage`).

:func:`join_probes` searches a list of (query, cell) probes grouped by cell: all queries that
probe cell ``b`` are compared at once with ``b``'s members by one matrix product of their search
vectors (BLAS, instead of one inverted-list scan per query), and the pairs within the search
radius are decided exactly in the same pass (:func:`.kernel.count_block`, no candidate list).
(A flat FAISS index's range search per cell did the same at 2-3x the time per pair: it builds
a result list of every pair in range, and real SIFT points have hundreds per query.) :func:`join_cells` runs it on every point's
``nprobe`` nearest cells; :func:`expand_search` on further cells, ring by ring, for the points
in dense groups of look-alikes. The rules (the ``BAND`` around the threshold, why counts never
exceed the exact ones) are in :mod:`.stage`'s docstring.

Threads: ``config.threads`` Python threads, each with single-threaded FAISS and BLAS (a thread
pool per call costs more than it gains on calls this small, most of all on a busy machine) and
its own counts, summed at the end (integers, any order); each thread takes every ``T``-th cell,
so no result depends on the thread count.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import faiss
import numpy as np

from markerplace.plan.similarity.kernel import count_block
from markerplace.plan.similarity.search import BAND, Searcher, blas_threads, resolve_threads

__all__ = ["Cells", "expand_search", "join_cells", "join_probes", "rank_cells"]


class Cells:
    """The points filed in each IVF cell.

    Attributes:
        members: (P,) point indices ordered by cell (ascending within a cell).
        lims: (nlist + 1,) cell ``b`` holds ``members[lims[b]:lims[b + 1]]``.
    """

    def __init__(self, first: np.ndarray, nlist: int):
        self.members = np.argsort(first, kind="stable")
        self.lims = np.searchsorted(first[self.members], np.arange(nlist + 1))
        self.nlist = nlist


def _in_threads(n_threads: int, work: Callable[[int, threading.Event], object]) -> list:
    """``work(t, stop)`` for t in 0..n_threads-1 on as many threads (each with one OpenMP
    thread); ``stop`` is set when the caller is interrupted."""
    stop = threading.Event()  # set when the caller is interrupted: the threads end after their cell

    def run(t: int):
        faiss.omp_set_num_threads(1)  # this thread's OpenMP setting (FAISS and its OpenBLAS)
        return work(t, stop)

    with ThreadPoolExecutor(n_threads) as pool:  # FAISS, BLAS and the kernel release the GIL
        try:
            return list(pool.map(run, range(n_threads)))
        except BaseException:  # Ctrl-C: do not wait for every thread to finish its share
            stop.set()
            raise


def join_probes(searcher: Searcher, cells: Cells, probe_q: np.ndarray, probe_cell: np.ndarray,
                report: np.ndarray | None, counts: np.ndarray,
                tick: Callable[[int], None] | None = None, block: int = 4096) -> np.ndarray:
    """Range-search every probe (query ``probe_q[i]`` in cell ``probe_cell[i]``); add to ``counts``.

    The same pairs as ``range_search_preassigned`` with these probes, but grouped by cell. Only
    which pairs near the radius are in range can differ between the two (float rounding of the
    distance), and those are never look-alikes (the radius has the ``BAND`` margin), so the
    counts are the same. A query must probe a cell at most once (else a pair counts twice).

    Args:
        searcher: the IVF searcher (its ``vectors``, ``radius``, ``pairs`` and ``config``).
        cells: the members of each cell.
        probe_q, probe_cell: (N,) int64 query rows and the cells they search (no -1).
        report: (N,) bool, or None for all: the probes whose look-alikes set the result.
        counts: (P,) int64, incremented by each query's look-alike count.
        tick: called with 1 after each cell, from the worker threads (progress; thread-safe).

    Returns:
        (P,) bool: the point had a look-alike candidate (any 3D distance) in a reported probe.
    """
    cfg, Y = searcher.config, searcher.vectors
    cos_t, min_d2 = float(cfg.cos_threshold), float(cfg.min_distance) ** 2
    P, nlist = len(counts), cells.nlist
    order = np.argsort(probe_cell, kind="stable")  # probes by cell, in their given order within one
    probe_lims = np.searchsorted(probe_cell[order], np.arange(nlist + 1))
    n_threads = min(resolve_threads(cfg.threads), nlist)

    pairs, sq = searcher.pairs, np.einsum("ij,ij->i", Y, Y)
    need_all = np.ones(block, dtype=bool)

    def part(t: int, stop: threading.Event) -> tuple[np.ndarray, np.ndarray]:
        part_counts, part_found = np.zeros(P, dtype=np.int64), np.zeros(P, dtype=bool)
        for b in range(t, nlist, n_threads):
            if stop.is_set():
                break
            if tick is not None:
                tick(1)
            m = cells.members[cells.lims[b]:cells.lims[b + 1]]
            prs = order[probe_lims[b]:probe_lims[b + 1]]
            if len(m) == 0 or len(prs) == 0:
                continue
            ym, m_sq = Y[m], sq[m]
            for s in range(0, len(prs), block):  # bounds the (queries, members) block in memory
                pr = prs[s:s + block]
                q = probe_q[pr]
                G = Y[q] @ ym.T  # BLAS; rounding only moves pairs at the radius, never look-alikes
                c, f = np.zeros(len(q), dtype=np.int64), np.zeros(len(q), dtype=bool)
                need = need_all[:len(q)] if report is None else report[pr]
                count_block(q, m, G, sq[q], m_sq, searcher.radius, need, pairs.points, pairs.X, pairs.raw,
                            pairs.norm, cos_t, BAND, min_d2, c, f)
                part_counts[q] += c  # a query probes a cell once: no repeated indices
                part_found[q[need]] |= f[need]
        return part_counts, part_found

    found = np.zeros(P, dtype=bool)
    with blas_threads(1):
        for part_counts, part_found in _in_threads(n_threads, part):
            counts += part_counts
            found |= part_found
    return found


def join_cells(searcher: Searcher, cells: Cells, probed: np.ndarray, h: int, counts: np.ndarray,
               tick: Callable[[int], None] | None = None) -> np.ndarray:
    """Search every point in its probed cells (:func:`join_probes`); add to ``counts``.

    Args:
        probed: (P, n) int64 cells of every point, nearest first (no -1).
        h: probe ranks ``>= h`` are the farther cells whose look-alike candidates are reported.
        searcher, cells, counts, tick: as :func:`join_probes` (``tick`` once per cell).

    Returns:
        (P,) bool: the point had a look-alike candidate (any 3D distance) in a cell of rank >= h.
    """
    P, n = probed.shape
    report = np.tile(np.arange(n) >= h, P)
    return join_probes(searcher, cells, np.repeat(np.arange(P), n), probed.ravel(), report, counts, tick)


def rank_cells(searcher: Searcher, centroids: np.ndarray, queries: np.ndarray, searched: np.ndarray,
               width: int) -> np.ndarray:
    """The ``width`` cells nearest each query after those it ``searched`` (-1 past the last).

    A query's candidates are the ``1.5 (width + n)`` cells nearest the centroid of its own cell
    (``searched[:, 0]``; n = ``searched.shape[1]``), ranked by their distance to the query:
    ranking all ``nlist`` cells for every query costs more than the search it steers, and the
    cells nearest a query lie around its own. Deterministic (each distance and sort is per
    query); a cell ranked elsewhere than by the quantizer can only be searched earlier or
    later, never twice (the ``searched`` cells are left out by number).

    Returns:
        (Q, width) int32 cells, nearest first.
    """
    Q, n = searched.shape
    nlist = len(centroids)
    M = min(nlist, (3 * (width + n) + 1) // 2)
    _, near = faiss.knn(centroids, centroids, M)  # each cell's M nearest cells (itself first)
    groups = Cells(searched[:, 0], nlist)
    out = np.full((Q, width), -1, dtype=np.int32)
    Y = searcher.vectors
    n_threads = min(resolve_threads(searcher.config.threads), nlist)

    def part(t: int, stop: threading.Event) -> None:
        for b in range(t, nlist, n_threads):
            g = groups.members[groups.lims[b]:groups.lims[b + 1]]
            if stop.is_set():
                break
            if len(g) == 0:
                continue
            cand = near[b]
            dist = faiss.pairwise_distances(Y[queries[g]], centroids[cand])  # (G, M)
            ranked = cand[np.argsort(dist, axis=1)]
            mark = np.zeros((len(g), nlist), dtype=bool)
            mark[np.arange(len(g))[:, None], searched[g]] = True
            done = np.take_along_axis(mark, ranked, axis=1)
            keep = np.argsort(done, axis=1, kind="stable")[:, :width]  # not searched first, in order
            r = np.take_along_axis(ranked, keep, axis=1)
            r[np.take_along_axis(done, keep, axis=1)] = -1
            out[g, :r.shape[1]] = r

    _in_threads(n_threads, part)
    return out


def expand_search(searcher: Searcher, centroids: np.ndarray, cells: Cells, queries: np.ndarray,
                  searched: np.ndarray, nprobe_max: int, counts: np.ndarray,
                  tick: Callable[[int], None] | None = None, chunk: int = 1 << 17) -> None:
    """Search ``queries`` in further cells, ring by ring, while the last ring held a look-alike.

    With n = ``searched.shape[1]`` cells searched, every ring is the next 2 n cells (by
    :func:`rank_cells`), up to ``nprobe_max`` cells in all; a query goes on to the next ring
    while its last ring held a look-alike candidate (any 3D distance). Every ring is one
    :func:`join_probes` over all queries still going; no cell is searched twice for a query.
    Adds to ``counts``; ``tick(k)`` when ``k`` queries are done.
    """
    n = searched.shape[1]
    width = nprobe_max - n
    if width <= 0:
        return
    for s in range(0, len(queries), chunk):  # bounds the (Q, width) ranks in memory
        q = queries[s:s + chunk]
        ranked = rank_cells(searcher, centroids, q, searched[s:s + chunk], width)
        active, lo = np.arange(len(q)), 0
        while len(active) and lo < width:
            hi = min(lo + 2 * n, width)
            cell = ranked[active, lo:hi].astype(np.int64)
            probe_q = np.repeat(q[active], hi - lo)
            ok = cell.ravel() >= 0
            found = join_probes(searcher, cells, probe_q[ok], cell.ravel()[ok], None, counts)
            go = found[q[active]]
            if tick is not None:
                tick(int(len(active) - go.sum()))
            active, lo = active[go], hi
        if tick is not None and len(active):
            tick(len(active))
