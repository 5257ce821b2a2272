"""Look-alike counts: exact vs brute force, the distance rule, approximate vs exact error."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from markerplace.plan.similarity import (SimilarityConfig, count_similar, count_similar_approx, count_similar_exact,
                                    measure_error, synthetic_descriptors)

log = logging.getLogger(__name__)


def brute_force(D: np.ndarray, P: np.ndarray, cos_t: float = 0.9, min_d: float = 2.0) -> np.ndarray:
    X = D.astype(np.float64)
    X /= np.linalg.norm(X, axis=1, keepdims=True)
    sim = X @ X.T > cos_t
    far = np.linalg.norm(P[:, None] - P[None], axis=-1) > min_d
    ok = sim & far
    np.fill_diagonal(ok, False)
    return ok.sum(axis=1)


def test_exact_matches_brute_force_on_tiny_input():
    D, P = synthetic_descriptors(600, seed=3, dup_fraction=0.5, extent=6.0)
    want = brute_force(D, P)
    assert want.sum() > 50  # the planted look-alikes produce pairs, near and far
    got = count_similar_exact(D, P, SimilarityConfig(block=5000))  # several blocks
    assert got.dtype == np.int32
    assert np.array_equal(got, want)
    assert np.array_equal(count_similar(D, P, SimilarityConfig(method="auto")), want)


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
    assert np.array_equal(count_similar_approx(D, P, SimilarityConfig(num_cells=2)), got)
    # a larger minimum distance keeps only the 3.9 m pair
    assert count_similar_exact(D, P, SimilarityConfig(min_distance=3.5)).tolist() == [0, 0, 1, 0, 1]
    # the cosine threshold is strict
    a = np.zeros(128, np.float32)
    a[0] = 1.0
    b = np.zeros(128, np.float32)
    b[0], b[1] = 0.9, np.sqrt(1 - 0.81) + 1e-3  # cos just below 0.9
    P2 = np.array([[0, 0, 0], [5, 0, 0]], float)
    assert count_similar_exact(np.stack([a, b]), P2).tolist() == [0, 0]


def test_approx_error_against_exact():
    D, P = synthetic_descriptors(12000, seed=7)
    cfg = SimilarityConfig(seed=1)
    m = measure_error(D, P, cfg)
    log.info("approx vs exact on %d synthetic SIFT-like points: %s", m["points"], m)
    assert m["exact_mean"] > 1.0  # the planted look-alikes are there
    assert m["over_counts"] == 0  # candidates are verified exactly: never too many
    assert m["recall"] >= 0.95
    assert m["mean_abs_error"] <= 0.1
    assert m["frac_points_exact"] >= 0.95


def test_approx_on_dense_blobs():
    """A blob of many mutual look-alikes (repeated texture) among sparse points."""
    rng = np.random.default_rng(5)
    D, P = synthetic_descriptors(6000, seed=11, dup_fraction=0.1)
    blob = np.abs(D[0] + 0.05 * D[0].std() * rng.standard_normal((800, 128))).astype(np.float32)
    Pb = rng.uniform(0, 20, (800, 3))
    D2, P2 = np.vstack([D, blob]), np.vstack([P, Pb])
    m = measure_error(D2, P2, SimilarityConfig())
    log.info("approx vs exact with an 800-point blob: %s", m)
    assert m["exact_mean"] > 50
    assert m["over_counts"] == 0
    assert m["recall"] >= 0.95


def test_config_checks():
    D, P = synthetic_descriptors(10, seed=0)
    with pytest.raises(ValueError, match="unknown similarity method"):
        count_similar(D, P, SimilarityConfig(method="fast"))
    with pytest.raises(ValueError):
        count_similar(D, P[:5], SimilarityConfig())
    assert count_similar(D[:1], P[:1]).tolist() == [0]
    assert count_similar_approx(D[:1], P[:1]).tolist() == [0]
