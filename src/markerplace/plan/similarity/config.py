"""Settings of the look-alike (similarity) stage."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["SimilarityConfig"]


@dataclass(frozen=True)
class SimilarityConfig:
    """Settings of the similarity analysis.

    Attributes:
        cos_threshold: descriptors with cosine similarity above this are similar (paper: 0.9).
        min_distance: only points farther than this (metres, 3D) count (paper: 2.0).
        method: ``"auto"``, ``"exact"`` or ``"ivf"`` (see module docstring). Default ``auto``.
        exact_max_points: ``auto`` uses ``exact`` up to this many points (default 50,000).
        nlist: IVF cells; 0 (default) = ``clip(round(nlist_factor * sqrt(P)), 16, 65536)``.
        nlist_factor: cells per sqrt(point) when ``nlist`` is 0 (default 4).
        nprobe: cells every point searches, nearest first (default 8: recall of look-alike pairs
            >= 0.99 at 437k and 1.8M synthetic points, ``benchmarks/similarity.py``); more =
            higher recall, slower.
        nprobe_max: a point whose farther half of the ``nprobe`` cells held a look-alike
            candidate (any 3D distance) searches the next ``2 nprobe`` cells, and the next
            ``2 nprobe`` again while the last ring still holds one, up to this many cells in all
            (default 128; ``nprobe_max <= nprobe`` turns this off). Dense groups of look-alikes
            (repeated texture) span many k-means cells; this finds them without raising
            ``nprobe`` for every point.
        pca_dims: dimensions of the orthonormal PCA projection the ``ivf`` index searches
            (default 64; 0 or >= D: the full descriptors). Shorter vectors scan faster; the
            projection can only add candidates, which are then decided on the full descriptors.
        train_points_per_cell: k-means training sample size per cell (default 40, FAISS's
            recommended minimum is 39).
        train_iters: k-means iterations (default 10).
        batch: points per FAISS range-search call (default 16,384); bounds the memory of one
            call's results (12 bytes per pair within the threshold, near pairs included).
        threads: FAISS OpenMP threads; 0 (default) = the CPUs this process may run on. Results
            do not depend on it.
        seed: seed of the training sample and of FAISS's k-means (default 0).
    """

    cos_threshold: float = 0.9
    min_distance: float = 2.0
    method: str = "auto"
    exact_max_points: int = 50000
    nlist: int = 0
    nlist_factor: float = 4.0
    nprobe: int = 8
    nprobe_max: int = 128
    pca_dims: int = 64
    train_points_per_cell: int = 40
    train_iters: int = 10
    batch: int = 16384
    threads: int = 0
    seed: int = 0
