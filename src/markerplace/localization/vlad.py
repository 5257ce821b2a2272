"""VLAD global descriptors (Jegou et al. 2011) for image retrieval.

Local descriptors are RootSIFT-normalised (L1, then element-wise sqrt), assigned to the nearest
of ``C`` k-means centres, and the residuals are summed per centre. The (C, 128) result is
intra-normalised (L2 per centre), power-normalised (signed sqrt) and L2-normalised, giving a
unit (C * 128,) float32 vector; similarity is the dot product.

The codebook is trained with seeded k-means++ + Lloyd iterations in numpy (no global RNG).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplace.runtime.atomic_io import write_npz

log = logging.getLogger(__name__)


def root_sift(descriptors: np.ndarray) -> np.ndarray:
    """(N, 128) SIFT -> (N, 128) float32 RootSIFT (L1-normalise, sqrt; unit L2 norm)."""
    d = np.asarray(descriptors, dtype=np.float32).reshape(-1, 128)
    d = np.maximum(d, 0.0)
    d = d / np.maximum(d.sum(axis=1, keepdims=True), 1e-12)
    return np.sqrt(d)


def _sq_dists(x: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(N, D), (C, D) -> (N, C) squared Euclidean distances."""
    return np.maximum((x * x).sum(1)[:, None] - 2.0 * x @ c.T + (c * c).sum(1)[None, :], 0.0)


def _assign(x: np.ndarray, c: np.ndarray, chunk: int = 65536) -> np.ndarray:
    """Nearest centre index (N,) for (N, D) points, in chunks to bound memory."""
    out = np.empty(len(x), dtype=np.int64)
    cc = (c * c).sum(1)[None, :]
    for s in range(0, len(x), chunk):
        out[s : s + chunk] = np.argmin(cc - 2.0 * x[s : s + chunk] @ c.T, axis=1)
    return out


def _cluster_sums(x: np.ndarray, labels: np.ndarray, k: int) -> np.ndarray:
    """(k, D) per-cluster sums of the rows of (N, D) ``x`` (sort + reduceat)."""
    out = np.zeros((k, x.shape[1]), dtype=x.dtype)
    if len(x) == 0:
        return out
    order = np.argsort(labels, kind="stable")
    sl = labels[order]
    starts = np.flatnonzero(np.r_[True, sl[1:] != sl[:-1]])
    out[sl[starts]] = np.add.reduceat(x[order], starts, axis=0)
    return out


def kmeans(x: np.ndarray, k: int, seed: int = 0, iterations: int = 25) -> np.ndarray:
    """Seeded k-means (k-means++ init, Lloyd). (N, D) float32 -> (k, D) float32 centres.

    Empty clusters are re-seeded with the point farthest from its centre.
    """
    x = np.asarray(x, dtype=np.float32)
    n = len(x)
    if n < k:
        raise ValueError(f"k-means needs at least k={k} points, got {n}")
    rng = np.random.default_rng(seed)
    centres = np.empty((k, x.shape[1]), np.float32)
    centres[0] = x[rng.integers(n)]
    d2 = _sq_dists(x, centres[:1])[:, 0]
    for i in range(1, k):
        p = d2 / d2.sum() if d2.sum() > 0 else np.full(n, 1.0 / n)
        centres[i] = x[rng.choice(n, p=p)]
        d2 = np.minimum(d2, _sq_dists(x, centres[i : i + 1])[:, 0])
    for _ in range(iterations):
        labels = _assign(x, centres)
        counts = np.bincount(labels, minlength=k)
        sums = _cluster_sums(x, labels, k)
        new = centres.copy()
        nz = counts > 0
        new[nz] = sums[nz] / counts[nz, None]
        if np.any(~nz):
            dist = ((x - new[labels]) ** 2).sum(1)
            far = np.argsort(-dist)[: int((~nz).sum())]
            new[~nz] = x[far]
        shift = float(np.abs(new - centres).max())
        centres = new
        if shift < 1e-6:
            break
    return centres


@dataclass(frozen=True, eq=False)
class VladCodebook:
    """k-means centres for VLAD.

    Attributes:
        centres: (C, 128) float32 centres in RootSIFT space.
    """

    centres: np.ndarray

    @property
    def num_clusters(self) -> int:
        return int(self.centres.shape[0])

    @property
    def dim(self) -> int:
        """Length D = C * 128 of a VLAD vector."""
        return int(self.centres.size)

    @classmethod
    def train(
        cls,
        descriptors: np.ndarray,
        num_clusters: int = 64,
        seed: int = 0,
        max_samples: int = 100_000,
        iterations: int = 25,
    ) -> "VladCodebook":
        """Train on (N, 128) SIFT descriptors (a seeded sample of at most ``max_samples``)."""
        d = np.asarray(descriptors, dtype=np.float32).reshape(-1, 128)
        rng = np.random.default_rng(seed)
        if len(d) > max_samples:
            d = d[np.sort(rng.choice(len(d), max_samples, replace=False))]
        log.info("training VLAD codebook: %d clusters on %d descriptors", num_clusters, len(d))
        return cls(kmeans(root_sift(d), num_clusters, seed=seed, iterations=iterations))

    def vlad(self, descriptors: np.ndarray) -> np.ndarray:
        """(N, 128) SIFT descriptors -> (C * 128,) float32 unit VLAD (zeros if N == 0)."""
        c = self.centres
        v = np.zeros_like(c)
        d = root_sift(descriptors)
        if len(d):
            labels = _assign(d, c)
            v = _cluster_sums(d - c[labels], labels, len(c))
        norms = np.linalg.norm(v, axis=1, keepdims=True)
        v = v / np.maximum(norms, 1e-12)
        v = np.sign(v) * np.sqrt(np.abs(v))
        v = v.reshape(-1)
        n = float(np.linalg.norm(v))
        return (v / n if n > 0 else v).astype(np.float32)

    def save(self, path: str | Path) -> None:
        """Write the centres to ``.npz`` (atomic, no pickle)."""
        write_npz(path, centres=self.centres)

    @classmethod
    def load(cls, path: str | Path) -> "VladCodebook":
        with np.load(path, allow_pickle=False) as f:
            return cls(np.asarray(f["centres"], dtype=np.float32))


def nearest_by_similarity(sims: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Top-k of (M,) similarities ``sims``: (k',) indices and similarities, best first
    (k' = min(k, M)); ties keep the lower index first (as :func:`nearest`)."""
    sims = np.asarray(sims)
    if len(sims) == 0 or k <= 0:
        return np.zeros(0, np.int64), np.zeros(0, np.float32)
    order = np.argsort(-sims, kind="stable")[:min(int(k), len(sims))]
    return order.astype(np.int64), sims[order].astype(np.float32)


def nearest(db: np.ndarray, query: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Top-k rows of (M, D) unit vectors ``db`` by dot product with (D,) ``query``.

    Returns (k',) indices and (k',) similarities, best first (k' = min(k, M)); ties keep the
    lower index first.
    """
    db = np.asarray(db)
    if len(db) == 0 or k <= 0:
        return np.zeros(0, np.int64), np.zeros(0, np.float32)
    return nearest_by_similarity(db @ np.asarray(query, dtype=db.dtype), k)
