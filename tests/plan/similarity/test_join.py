"""The IVF search as cell joins: the ranking of further cells and the ring-by-ring expansion."""

from __future__ import annotations

import numpy as np

from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.plan.similarity.join import rank_cells
from markerplace.plan.similarity.quality import measure_error, synthetic_descriptors
from markerplace.plan.similarity.search import Pairs, Searcher
from markerplace.plan.similarity.stage import count_similar_exact, count_similar_ivf


def test_rank_cells_leaves_out_searched_cells_and_ranks_by_distance():
    rng = np.random.default_rng(0)
    nlist, d = 40, 8
    centroids = rng.standard_normal((nlist, d)).astype(np.float32)
    Y = rng.standard_normal((300, d)).astype(np.float32)
    dist = ((Y[:, None, :] - centroids[None]) ** 2).sum(-1)
    nearest = np.argsort(dist, axis=1, kind="stable")
    searched = nearest[:, :3].copy()
    searched[::7, 1:] = searched[::7, 1:][:, ::-1]  # the searched cells in another order
    searched[::5, 2] = nearest[::5, 20]  # a far cell among the searched: it must not come back
    searcher = Searcher(None, None, Y, 0.0, False, SimilarityConfig(threads=2))
    q = np.arange(len(Y))
    got = rank_cells(searcher, centroids, q, searched, 12)
    assert got.shape == (300, 12) and got.dtype == np.int32
    assert np.array_equal(rank_cells(searcher, centroids, q, searched, 12), got)  # deterministic
    for i in range(len(Y)):
        row = got[i][got[i] >= 0]
        assert len(set(row.tolist())) == len(row)  # no cell twice
        assert not set(row.tolist()) & set(searched[i].tolist())  # no searched cell again
        assert np.all(np.diff(dist[i, row]) >= 0)  # nearest first
    # 1.5 (width + 3) candidates cover all 40 cells: the ranking is the exact one
    full = rank_cells(searcher, centroids, q, searched, 24)
    exact = np.array([[c for c in nearest[i] if c not in searched[i]][:24] for i in range(len(Y))])
    assert np.mean(np.all(full == exact, axis=1)) > 0.98  # (float32 near-ties aside)
    # width past the cells there are: -1 at the end
    wide = rank_cells(searcher, centroids, q, searched, nlist)
    assert np.all(wide[:, -3:] == -1)


def test_expansion_reaches_every_cell_of_a_dense_group_without_double_counting():
    """A blob of mutual look-alikes that k-means splits into most cells: two probes miss most
    of its pairs, and the rings (every ring holds look-alikes) go on until every cell is
    searched, each once: the counts are then exact, on any thread count."""
    rng = np.random.default_rng(3)
    D, P = synthetic_descriptors(400, seed=12, dup_fraction=0.2)
    blob = np.abs(D[0] + 0.05 * D[0].std() * rng.standard_normal((1200, 128))).astype(np.float32)
    D2, P2 = np.vstack([D, blob]), np.vstack([P, rng.uniform(0, 20, (1200, 3))])
    exact = count_similar_exact(D2, P2)
    assert exact.mean() > 500
    cfg = SimilarityConfig(nlist=16, nprobe=2, nprobe_max=2, seed=1, threads=1)
    starved = measure_error(count_similar_ivf(D2, P2, cfg), exact)
    assert starved["over_counts"] == 0 and starved["recall"] < 0.8  # the blob spans many cells
    for threads in (1, 2, 3):
        got = count_similar_ivf(D2, P2, SimilarityConfig(nlist=16, nprobe=2, nprobe_max=16, seed=1,
                                                         threads=threads))
        assert np.array_equal(got, exact)


def test_block_kernel_decides_as_the_candidate_list_kernel():
    """count_block (pairs in range taken from the product of the search vectors) against
    count_candidates on FAISS's range-search list of the same block: same counts and found."""
    import faiss

    from markerplace.plan.similarity.kernel import count_block

    D, P = synthetic_descriptors(3000, seed=4, dup_fraction=0.5, extent=5.0)
    pairs = Pairs(D, P)
    Y = pairs.X[:, :48].copy()  # any projection: both kernels get the same search vectors
    q, m = np.arange(0, 3000, 2), np.arange(1, 3000, 3)
    radius = 0.6
    flat = faiss.IndexFlatL2(Y.shape[1])
    flat.add(Y[m])
    lims, _, labels = flat.range_search(Y[q], radius)
    want_c, want_f = pairs.count(q, lims, None, m[labels], 0.9, 4.0)
    assert want_c.sum() > 50 and 0 < want_f.sum() < len(q)
    sq = np.einsum("ij,ij->i", Y, Y)
    c, f = np.zeros(len(q), np.int64), np.zeros(len(q), bool)
    count_block(q, m, Y[q] @ Y[m].T, sq[q], sq[m], radius, np.ones(len(q), bool), pairs.points, pairs.X,
                pairs.raw, pairs.norm, 0.9, 1e-4, 4.0, c, f)
    assert np.array_equal(c, want_c) and np.array_equal(f, want_f)


def test_blas_threads_are_set_and_restored():
    from threadpoolctl import threadpool_info

    from markerplace.plan.similarity.search import blas_threads

    def blas():
        return [(i["filepath"], i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"]

    A = np.random.default_rng(0).random((300, 64), dtype=np.float32)
    want = A @ A.T  # numpy's BLAS is loaded
    before = blas()
    assert before
    with blas_threads(3):
        assert all(n == 3 for _, n in blas())
        with blas_threads(1):
            assert all(n == 1 for _, n in blas())
            got = A @ A.T
        assert all(n == 3 for _, n in blas())
    assert blas() == before
    assert np.allclose(got, want, rtol=1e-5, atol=1e-5)
