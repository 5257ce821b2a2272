"""Look-alike counts (FAISS): exact vs float64 brute force, the distance rule, IVF vs exact."""

from __future__ import annotations

import logging
from dataclasses import replace

import faiss
import numpy as np
import pytest

from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.plan.similarity.quality import measure_error, synthetic_descriptors
from markerplace.plan.similarity.stage import count_similar, count_similar_exact, count_similar_ivf

log = logging.getLogger(__name__)


def brute_force(D: np.ndarray, P: np.ndarray, cos_t: float = 0.9, min_d: float = 2.0) -> np.ndarray:
    """All pairs in float64: the definition of n_p."""
    X = D.astype(np.float64)
    n = np.linalg.norm(X, axis=1)
    sim = X @ X.T > cos_t * n[:, None] * n[None]
    far = np.linalg.norm(P[:, None] - P[None], axis=-1) > min_d
    ok = sim & far
    np.fill_diagonal(ok, False)
    return ok.sum(axis=1)


def test_exact_matches_brute_force_on_planted_look_alikes():
    D, P = synthetic_descriptors(1500, seed=3, dup_fraction=0.5, extent=6.0)
    want = brute_force(D, P)
    assert want.sum() > 500 and (want == 0).sum() > 100  # planted pairs, near and far, and loners
    got = count_similar_exact(D, P, SimilarityConfig(batch=333))  # several range-search calls
    assert got.dtype == np.int32 and got.shape == (1500,)
    assert np.array_equal(got, want)
    assert np.array_equal(count_similar(D, P), want)  # auto -> exact at this size
    # uint8 descriptors, as OpenCV SIFT stores them
    D8 = np.clip(np.round(D / 2.0), 0, 255).astype(np.uint8)
    assert np.array_equal(count_similar_exact(D8, P), brute_force(D8, P))
    # a subset of queries against all points
    q = np.array([0, 7, 8, 1499])
    assert np.array_equal(count_similar_exact(D, P, queries=q), want[q])


def test_cosine_on_the_threshold_is_decided_in_float64():
    """Pairs whose cosine is within float32 error of 0.9 (the band recomputed in float64)."""
    eps = np.array([-3e-7, 3e-7, -2e-5, 2e-5, -5e-4, 5e-4])
    rows, pts = [], []
    for k, e in enumerate(eps):
        c = 0.9 + e
        a = np.zeros(128)
        a[2 * k] = 1.0
        b = np.zeros(128)
        b[2 * k], b[2 * k + 1] = c, np.sqrt(1 - c * c)
        rows += [a * 300, b * 7]
        pts += [[10.0 * k, 0, 0], [10.0 * k, 5.0, 0]]
    D, P = np.array(rows), np.array(pts)
    want = brute_force(D, P)
    assert want.tolist() == [0, 0, 1, 1, 0, 0, 1, 1, 0, 0, 1, 1]
    assert count_similar_exact(D, P).tolist() == want.tolist()
    assert count_similar_ivf(D, P, SimilarityConfig(nlist=2, nprobe=2)).tolist() == want.tolist()


def test_distance_rule_and_threshold():
    rng = np.random.default_rng(0)
    base = rng.gamma(0.5, 1.0, 128)
    other = rng.gamma(0.5, 1.0, 128)
    # 0, 1: identical descriptor 1 m apart (too close); 0, 2: identical 3 m apart (counts);
    # 1, 2: exactly 2 m apart (not farther: no); 3: unrelated descriptor far away;
    # 4: scaled copy of 0, 2.5-3.9 m from 0, 1, 2 (scale must not matter)
    D = np.stack([base, base, base, other, 7.0 * base]).astype(np.float32) * 100
    P = np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0], [10, 0, 0], [0, 0, 2.5]], float)
    got = count_similar_exact(D, P)
    assert got.tolist() == [2, 1, 2, 0, 3]
    assert count_similar_ivf(D, P, SimilarityConfig(nlist=2, nprobe=2)).tolist() == [2, 1, 2, 0, 3]
    # a larger minimum distance keeps only the 3.9 m pair; zero keeps every look-alike
    assert count_similar_exact(D, P, SimilarityConfig(min_distance=3.5)).tolist() == [0, 0, 1, 0, 1]
    assert count_similar_exact(D, P, SimilarityConfig(min_distance=0.0)).tolist() == [3, 3, 3, 0, 3]
    # a zero descriptor is like nothing (cosine 0)
    Dz = np.vstack([D, np.zeros((1, 128), np.float32)])
    Pz = np.vstack([P, [[50.0, 0, 0]]])
    assert count_similar_exact(Dz, Pz).tolist() == [2, 1, 2, 0, 3, 0]


def test_ivf_only_under_counts_and_finds_planted_look_alikes():
    D, P = synthetic_descriptors(12000, seed=7)
    exact = count_similar_exact(D, P)
    assert exact.mean() > 1.0  # the planted look-alikes are there
    m = measure_error(count_similar_ivf(D, P, SimilarityConfig(seed=1)), exact)
    log.info("ivf vs exact on %d synthetic SIFT-like points: %s", m["points"], m)
    assert m["over_counts"] == 0
    assert m["recall"] >= 0.99
    assert m["frac_points_exact"] >= 0.99
    # starved of probes the search misses pairs, but still never counts one too many
    starved = measure_error(count_similar_ivf(D, P, SimilarityConfig(nlist=256, nprobe=1)), exact)
    log.info("ivf with nprobe 1: %s", starved)
    assert starved["over_counts"] == 0
    assert starved["recall"] < m["recall"]


def test_ivf_on_a_dense_blob():
    """A blob of many mutual look-alikes (repeated texture) among sparse points."""
    rng = np.random.default_rng(5)
    D, P = synthetic_descriptors(6000, seed=11, dup_fraction=0.1)
    blob = np.abs(D[0] + 0.05 * D[0].std() * rng.standard_normal((800, 128))).astype(np.float32)
    D2, P2 = np.vstack([D, blob]), np.vstack([P, rng.uniform(0, 20, (800, 3))])
    m = measure_error(count_similar_ivf(D2, P2), count_similar_exact(D2, P2))
    log.info("ivf vs exact with an 800-point blob: %s", m)
    assert m["exact_mean"] > 50
    assert m["over_counts"] == 0
    assert m["recall"] >= 0.99


def test_ivf_probing_every_cell_is_exact():
    """nprobe = nlist: the cell-by-cell join sees every pair once, so the counts are exact
    (a pair lost or counted twice between cells, or a thread's counts dropped, would show)."""
    D, P = synthetic_descriptors(5000, seed=9, dup_fraction=0.4, extent=8.0)
    exact = count_similar_exact(D, P)
    assert exact.sum() > 1000
    for threads in (1, 2, 3):
        got = count_similar_ivf(D, P, SimilarityConfig(nlist=12, nprobe=12, nprobe_max=12, threads=threads))
        assert np.array_equal(got, exact)


def test_deterministic_and_thread_count_independent():
    D, P = synthetic_descriptors(8000, seed=2)
    exact = count_similar_exact(D, P)
    before = faiss.omp_get_max_threads()
    # one probe: the counts depend on the k-means cells; two probes then expansion to 8
    for cfg in (SimilarityConfig(nlist=256, nprobe=1, nprobe_max=1, seed=4),
                SimilarityConfig(nlist=256, nprobe=2, nprobe_max=8, seed=4)):
        one = count_similar_ivf(D, P, replace(cfg, threads=1))
        again = count_similar_ivf(D, P, replace(cfg, threads=1))
        two = count_similar_ivf(D, P, replace(cfg, threads=2))
        assert faiss.omp_get_max_threads() == before  # the thread setting is restored
        assert np.array_equal(one, two) and np.array_equal(two, again)
        assert np.all(one <= exact)
        if cfg.nprobe == 1:
            assert not np.array_equal(one, exact)  # the probe limit bites: the comparisons could fail
    assert np.all(count_similar_ivf(D, P, SimilarityConfig(nlist=256, nprobe=1, nprobe_max=1, seed=5, threads=1))
                  <= exact)


def test_empty_and_single_inputs_and_checks():
    D, P = synthetic_descriptors(10, seed=0)
    for method in ("auto", "exact", "ivf"):
        cfg = SimilarityConfig(method=method)
        empty = count_similar(D[:0], P[:0], cfg)
        assert empty.dtype == np.int32 and empty.shape == (0,)
        assert count_similar(D[:1], P[:1], cfg).tolist() == [0]
        assert count_similar(D[:2], P[:2], cfg).dtype == np.int32
    with pytest.raises(ValueError, match="unknown similarity method"):
        count_similar(D, P, SimilarityConfig(method="fast"))
    with pytest.raises(ValueError):
        count_similar(D, P[:5], SimilarityConfig())
    with pytest.raises(ValueError):
        count_similar(D, P, SimilarityConfig(min_distance=-1.0))
