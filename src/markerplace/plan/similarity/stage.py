"""Feature-similarity analysis (paper, Methods: "Analysis of feature similarity of 3D points").

For every observed 3D point p, ``n_p`` counts the OTHER points whose descriptor is similar
(cosine similarity > ``cos_threshold``) and whose 3D location is farther than ``min_distance``:
look-alikes far away, which would make a wrong place recognition costly. The score stage scales
the point's prior sigma by ``sqrt(1 + n_p)``.

Why FAISS: the search is a self-join of up to millions of 128-D descriptors, and FAISS
(``faiss-cpu``) gives a tuned, multi-threaded exact index and inverted-file index with range
search, so the project keeps no hand-written nearest-neighbour code. Descriptors are
L2-normalised (float32), so the cosine is an inner product; both methods range-search with
the threshold lowered by ``BAND`` and then decide every candidate pair exactly:

    * the 3D condition ``||p_i - p_j|| > min_distance`` in float64, on every candidate;
    * the cosine: ``exact``'s ``IndexFlatIP`` returns the float32 cosine of the normalised
      descriptors; ``ivf`` searches PCA-reduced vectors (an orthonormal projection, so a
      reduced distance never exceeds the full one and no look-alike falls outside the radius)
      and its candidates' float32 cosines are computed from the full normalised descriptors.
      Either is within about 1e-5 of the float64 value (normalising and a 128-term float32 dot
      product each err by at most ~D * 2^-24 relative). A pair more than ``BAND = 1e-4`` above
      the threshold is therefore a look-alike, one more than ``BAND`` below is not, and the
      pairs in between are recomputed in float64 from the original descriptors. The decision is
      the float64 brute-force decision for every pair found.

Methods:
    * ``exact``: ``IndexFlatIP`` range search (BLAS, O(P^2 D)); finds every pair, so its counts
      equal float64 brute force. Used up to ``exact_max_points`` points (the measured crossover
      with ``ivf``, see ``benchmarks/similarity.py``).
    * ``ivf``: ``IndexIVFFlat`` (L2, on the ``pca_dims``-D projection) with ``nlist`` cells from
      FAISS's k-means, trained on a seeded sample; each point is filed in its nearest cell and
      searches its ``nprobe`` nearest (one quantizer pass). The search runs cell by cell, all
      queries probing a cell against its members at once (a small matrix product, see
      :func:`.join.join_probes`). A point whose farther half of the ``nprobe`` cells held a
      look-alike (a dense group of look-alikes that k-means split over many cells: repeated
      texture, common in real SIFT) then searches further cells in rings of ``2 nprobe``
      (:func:`.join.expand_search`), again cell by cell for all such points at once. The only
      approximation is the probe limit: a look-alike in a cell that was not searched is missed,
      so counts can only be too low, never too high. :func:`~markerplace.plan.similarity.quality.measure_error` reports how much.
    * ``auto``: ``exact`` up to ``exact_max_points`` points, else ``ivf``.

Determinism: the training sample and FAISS's k-means are seeded from ``seed``; FAISS runs on
``threads`` OpenMP threads (restored afterwards; the cell joins on as many Python threads of one
OpenMP thread each). Every stage the result depends on is
thread-count independent (k-means centroids are summed per centroid in point order, cells are
filled in point order, each query's search and ranking of cells is independent), which the
tests check.
"""

from __future__ import annotations

import logging
import threading
import time
from pathlib import Path

import faiss
import numpy as np

from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.plan.similarity.join import Cells, expand_search, join_cells
from markerplace.plan.similarity.search import BAND, Pairs, Searcher, faiss_threads
from markerplace.progress import progress_bar
from markerplace.runtime import cache
from markerplace.runtime.atomic_io import write_npz
from markerplace.runtime.stages import cached

log = logging.getLogger(__name__)

__all__ = ["count_similar", "count_similar_exact", "count_similar_ivf", "run_similarity"]

def _check(descriptors: np.ndarray, points_world: np.ndarray, config: SimilarityConfig) -> None:
    if descriptors.ndim != 2 or points_world.shape != (len(descriptors), 3):
        raise ValueError(f"descriptors (P, D) and points (P, 3) expected, got {descriptors.shape} and {points_world.shape}")
    if config.method not in ("auto", "exact", "ivf"):
        raise ValueError(f"unknown similarity method {config.method!r}: use auto, exact or ivf")
    if not (-1.0 + BAND < config.cos_threshold < 1.0 - BAND):
        raise ValueError(f"cos_threshold must lie in (-1, 1), got {config.cos_threshold}")
    if config.min_distance < 0:
        raise ValueError(f"min_distance must be >= 0, got {config.min_distance}")
    if config.nprobe < 1 or config.batch < 1 or config.nlist < 0:
        raise ValueError("nprobe and batch must be >= 1, nlist >= 0")


def count_similar(descriptors: np.ndarray, points_world: np.ndarray,
                  config: SimilarityConfig = SimilarityConfig(), progress: bool = False) -> np.ndarray:
    """n_p for every point: look-alikes (cos > threshold) farther than ``min_distance``.

    Args:
        descriptors: (P, D) descriptors (e.g. OpenCV SIFT, D = 128, uint8 or float, any scale).
        points_world: (P, 3) 3D points, world metres.
        config: settings; ``method`` picks the algorithm.
        progress: show progress (a bar on a terminal, log lines otherwise; see
            :func:`markerplace.progress.progress_bar`).

    Returns:
        (P,) int32 counts (excluding the point itself).
    """
    descriptors = np.asarray(descriptors)
    points_world = np.asarray(points_world, dtype=np.float64)
    _check(descriptors, points_world, config)
    method = config.method
    if method == "auto":
        method = "exact" if len(descriptors) <= config.exact_max_points else "ivf"
    log.info("similarity (%s): counting look-alikes of %d points", method, len(descriptors))
    t0 = time.perf_counter()
    if method == "exact":
        out = count_similar_exact(descriptors, points_world, config, progress=progress)
    else:
        out = count_similar_ivf(descriptors, points_world, config, progress=progress)
    log.info("similarity (%s): %d points, mean n_p %.2f, %.1f s", method, len(out),
             float(out.mean()) if len(out) else 0.0, time.perf_counter() - t0)
    return out


def count_similar_exact(descriptors: np.ndarray, points_world: np.ndarray,
                        config: SimilarityConfig = SimilarityConfig(),
                        queries: np.ndarray | None = None, progress: bool = False) -> np.ndarray:
    """Exact n_p: ``IndexFlatIP`` range search over all points (O(P^2 D) time).

    Args:
        descriptors, points_world, config: as :func:`count_similar`.
        queries: optional (Q,) row indices: count only these points (against all P points),
            e.g. a sample to measure the error of :func:`count_similar_ivf` on a large input.
        progress: show progress over the points searched.

    Returns:
        (P,) int32 counts, or (Q,) for ``queries``; equal to float64 brute force.
    """
    descriptors = np.asarray(descriptors)
    _check(descriptors, np.asarray(points_world), config)
    pairs = Pairs(descriptors, points_world)
    q = np.arange(len(descriptors)) if queries is None else np.asarray(queries, dtype=np.int64)
    with faiss_threads(config.threads), progress_bar(len(q), "look-alikes (exact)", "pt", progress) as bar:
        index = faiss.IndexFlatIP(descriptors.shape[1])
        index.add(pairs.X)
        out, _ = Searcher(index, pairs, pairs.X, config.cos_threshold - BAND, True, config).search(q, tick=bar.update)
    return out.astype(np.int32)


def _nlist(P: int, config: SimilarityConfig) -> int:
    n = config.nlist or int(np.clip(round(config.nlist_factor * np.sqrt(P)), 16, 65536))
    return max(1, min(n, P))


def count_similar_ivf(descriptors: np.ndarray, points_world: np.ndarray,
                      config: SimilarityConfig = SimilarityConfig(), progress: bool = False) -> np.ndarray:
    """n_p by an inverted-file range search on PCA-reduced vectors (see module docstring);
    never over-counts.

    Args and returns as :func:`count_similar`; ``progress`` logs the training and shows the
    search cell by cell, then the points searched further.
    """
    descriptors = np.asarray(descriptors)
    _check(descriptors, np.asarray(points_world), config)
    P, D = descriptors.shape
    if P < 2:
        return np.zeros(P, dtype=np.int32)
    pairs = Pairs(descriptors, points_world)
    nlist = _nlist(P, config)
    nprobe = min(config.nprobe, nlist)
    nprobe_max = max(nprobe, min(config.nprobe_max, nlist))
    rng = np.random.default_rng(config.seed)
    n_train = min(P, max(nlist, config.train_points_per_cell * nlist, 4 * D))
    d = config.pca_dims if 0 < config.pca_dims < D and n_train >= 4 * D else D  # PCA needs a sample
    train = pairs.X if n_train == P else pairs.X[np.sort(rng.choice(P, n_train, replace=False))]
    t0, c0 = time.perf_counter(), time.process_time()
    if progress:
        log.info("look-alikes: training the index (k-means of %d of %d points into %d cells)", n_train, P, nlist)
    with faiss_threads(config.threads):
        if d < D:
            # orthonormal projection (no whitening): reduced distances never exceed full ones
            pca = faiss.PCAMatrix(D, d)
            pca.train(train)
            Y = pca.apply(pairs.X)
            train = pca.apply(train)
        else:
            Y = pairs.X
        quantizer = faiss.IndexFlatL2(d)
        index = faiss.IndexIVFFlat(quantizer, d, nlist, faiss.METRIC_L2)
        index.cp.seed = int(config.seed)
        index.cp.niter = int(config.train_iters)
        index.cp.max_points_per_centroid = n_train  # the sample is ours: FAISS must not resample
        index.cp.min_points_per_centroid = 1
        index.train(train)
        t1, c1 = time.perf_counter(), time.process_time()
        # one quantizer pass: the nearest cell files the point, the nprobe nearest are searched
        _, probed = quantizer.search(Y, nprobe)
        cells = Cells(probed[:, 0], nlist)
        t2, c2 = time.perf_counter(), time.process_time()
        # unit vectors: cos > t - band <=> |x - y|^2 < 2 - 2 (t - band); the projection keeps
        # every such pair inside the radius (the band also covers float32 rounding)
        searcher = Searcher(index, pairs, Y, 2.0 - 2.0 * (config.cos_threshold - BAND), False, config)
        counts = np.zeros(P, dtype=np.int64)
        # every point searches its nprobe nearest cells; a point whose farther half of them
        # still held a candidate searches on (a dense group of look-alikes that k-means split
        # over more than nprobe cells)
        with progress_bar(nlist, "look-alikes", "cell", progress) as bar:
            lock = threading.Lock()

            def tick(n: int) -> None:
                with lock:
                    bar.update(n)

            found_far = join_cells(searcher, cells, probed, (nprobe + 1) // 2, counts, tick)
        go_on = np.flatnonzero(found_far) if nprobe_max > nprobe else np.zeros(0, np.int64)
        t3, c3 = time.perf_counter(), time.process_time()
        if len(go_on):
            with progress_bar(len(go_on), "look-alikes (dense groups)", "pt", progress) as bar:
                expand_search(searcher, quantizer.reconstruct_n(0, nlist), cells, go_on, probed[go_on],
                              nprobe_max, counts, bar.update)
    log.debug("similarity ivf: %d points, PCA %d, %d cells, nprobe %d, %d points searched further (max %d); "
              "wall (CPU) seconds: train %.1f (%.1f), assign %.1f (%.1f), search %.1f (%.1f), further %.1f (%.1f)",
              P, d, nlist, nprobe, len(go_on), nprobe_max, t1 - t0, c1 - c0, t2 - t1, c2 - c1,
              t3 - t2, c3 - c2, time.perf_counter() - t3, time.process_time() - c3)
    return counts.astype(np.int32)



def run_similarity(descriptors: np.ndarray, points_world: np.ndarray, observe_key: str, run_dir: Path,
                   config: SimilarityConfig, enabled: bool, timings: dict, progress: bool = True) -> np.ndarray:
    """The look-alike stage of a run folder: ``run_dir/similarity.npz``, reused while the
    observations (their key and folder digest) and ``config`` are unchanged.

    Args:
        descriptors: (P, 128) SIFT descriptors of the observed points; ``points_world`` (P, 3) metres.
        enabled: False: every count is 0 (``--no-similarity``), nothing is computed or written.

    Returns:
        (P,) int32 look-alike count of each point (:func:`count_similar`).
    """
    if not enabled:
        timings["similarity"] = 0.0
        return np.zeros(len(points_world), dtype=np.int32)
    key = cache.hash_of("similarity-v4", observe_key, cache.content_digest(run_dir / "observations"), config)
    return cached("similarity", run_dir / "similarity.npz", key,
                  lambda: count_similar(descriptors, points_world, config, progress=progress),
                  lambda n, path: write_npz(path, n_similar=n),
                  lambda path: np.load(path, allow_pickle=False)["n_similar"], timings)
