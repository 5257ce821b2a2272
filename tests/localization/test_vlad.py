"""VLAD codebook, global descriptors and retrieval; SIFT extraction and depth lifting."""

from __future__ import annotations

import numpy as np
import pytest
from skimage import data

from markerplace.geometry import Intrinsics, world_from_cam_pose
from markerplace.localization.sift import SIFT_DEFAULT, SIFT_SCORING, extract_sift, lift_to_3d
from markerplace.localization.vlad import VladCodebook, kmeans, nearest, root_sift


def _images() -> list[np.ndarray]:
    return [data.astronaut(), data.coffee(), data.chelsea(), data.rocket(), np.dstack([data.camera()] * 3)]


@pytest.fixture(scope="module")
def descriptors() -> list[np.ndarray]:
    return [extract_sift(im, SIFT_SCORING)[1] for im in _images()]


def test_extract_sift_shapes_and_presets():
    kp, desc = extract_sift(data.astronaut(), SIFT_DEFAULT)
    assert kp.dtype == np.float32 and desc.dtype == np.float32
    assert kp.shape[1] == 2 and desc.shape == (len(kp), 128) and len(kp) > 1000
    kp2, _ = extract_sift(data.astronaut(), SIFT_SCORING)
    assert 0 < len(kp2) <= 1000 < len(kp)
    h, w = data.astronaut().shape[:2]
    assert np.all((kp >= -0.5) & (kp <= np.array([w, h])))
    blank_kp, blank_desc = extract_sift(np.full((100, 100, 3), 128, np.uint8))
    assert blank_kp.shape == (0, 2) and blank_desc.shape == (0, 128)


def test_lift_to_3d_plane_edges_and_range():
    intr = Intrinsics()
    K = intr.K
    T = world_from_cam_pose(np.array([1.0, 2.0, 1.5]), 0.4)
    depth = np.full((intr.height, intr.width), 3.0)
    depth[:, 400:] = 6.0  # depth edge between columns 399 and 400
    depth[:50] = 0.0  # no hit
    depth[400:, :100] = 12.0  # beyond range
    kp = np.array([[100.0, 200.0], [250.3, 100.7], [399.5, 200.0], [500.0, 300.0], [300.0, 20.0], [50.0, 420.0]])
    pts, valid = lift_to_3d(kp, depth, K, T, max_depth=10.0)
    np.testing.assert_array_equal(valid, [True, True, False, True, False, False])
    assert np.all(np.isnan(pts[~valid]))
    p_cam = (pts[valid] - T[:3, 3]) @ T[:3, :3]
    np.testing.assert_allclose(p_cam[:, 2], [3.0, 3.0, 6.0])
    np.testing.assert_allclose(p_cam[:, 0] / p_cam[:, 2] * 300 + 300, kp[valid, 0])
    np.testing.assert_allclose(p_cam[:, 1] / p_cam[:, 2] * 300 + 225, kp[valid, 1])
    # half-resolution depth (the paper's 300x225): same points
    pts2, valid2 = lift_to_3d(kp, depth[::2, ::2], K, T)
    np.testing.assert_array_equal(valid2[[0, 1, 3]], True)
    np.testing.assert_allclose(pts2[[0, 1, 3]], pts[[0, 1, 3]], atol=1e-9)


def test_root_sift_unit_norm():
    rng = np.random.default_rng(0)
    d = root_sift(rng.uniform(0, 100, (10, 128)))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, rtol=1e-5)


def test_kmeans_recovers_separated_clusters():
    rng = np.random.default_rng(1)
    true = rng.normal(scale=10.0, size=(5, 8)).astype(np.float32)
    x = np.concatenate([c + rng.normal(scale=0.1, size=(200, 8)) for c in true]).astype(np.float32)
    cen = kmeans(x, 5, seed=0)
    d = np.linalg.norm(true[:, None] - cen[None], axis=2)
    assert np.all(d.min(axis=1) < 0.05)


def test_codebook_deterministic_and_vlad_normalised(descriptors):
    all_d = np.concatenate(descriptors)
    a = VladCodebook.train(all_d, num_clusters=16, seed=3, max_samples=3000)
    b = VladCodebook.train(all_d, num_clusters=16, seed=3, max_samples=3000)
    c = VladCodebook.train(all_d, num_clusters=16, seed=4, max_samples=3000)
    np.testing.assert_array_equal(a.centres, b.centres)
    assert not np.array_equal(a.centres, c.centres)
    assert a.centres.shape == (16, 128) and a.dim == 16 * 128
    v = a.vlad(descriptors[0])
    assert v.shape == (a.dim,) and v.dtype == np.float32
    assert np.linalg.norm(v) == pytest.approx(1.0, abs=1e-5)
    np.testing.assert_array_equal(a.vlad(np.zeros((0, 128), np.float32)), 0.0)


def test_vlad_retrieves_same_image_first(descriptors):
    cb = VladCodebook.train(np.concatenate(descriptors), num_clusters=16, seed=0)
    db = np.stack([cb.vlad(d) for d in descriptors])
    rng = np.random.default_rng(0)
    for i, d in enumerate(descriptors):
        # a query made of a random 60% subset of an image's descriptors retrieves that image
        sub = d[rng.random(len(d)) < 0.6]
        idx, sims = nearest(db, cb.vlad(sub), 3)
        assert idx[0] == i
        assert sims[0] > sims[1] and len(idx) == 3
        idx, sims = nearest(db, db[i], 10)
        assert idx[0] == i and sims[0] == pytest.approx(1.0, abs=1e-5) and len(idx) == len(db)


def test_codebook_save_load_round_trip(tmp_path, descriptors):
    cb = VladCodebook.train(np.concatenate(descriptors), num_clusters=8, seed=0)
    path = tmp_path / "codebook.npz"
    cb.save(path)
    cb2 = VladCodebook.load(path)
    np.testing.assert_array_equal(cb.centres, cb2.centres)
    np.testing.assert_array_equal(cb.vlad(descriptors[1]), cb2.vlad(descriptors[1]))
