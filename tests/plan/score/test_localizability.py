"""Entropy, information gain, batched pose information and marker visibility (marker models:
tests/plan/score/test_marker_models.py)."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.poses import facing_marker
from markerplace.geometry import Intrinsics, so3_exp, world_from_cam_pose, world_from_cam_poses
from markerplace.plan.score.localizability import ENTROPY_CONST, NoiseConfig, entropy, information_gain, marker_visibility, pose_information, score

INTR = Intrinsics()
K = INTR.K
SIZE = (INTR.width, INTR.height)


def random_spd(rng, n, scale=1.0, rank=8):
    A = rng.normal(size=(n, 6, rank))
    return scale * A @ A.transpose(0, 2, 1) + 1e-3 * np.eye(6)


def test_entropy_formula() -> None:
    rng = np.random.default_rng(0)
    Lam = random_spd(rng, 5)
    expected = 0.5 * np.linalg.slogdet(np.linalg.inv(Lam))[1] + 3 * (1 + np.log(2 * np.pi))
    np.testing.assert_allclose(entropy(Lam), expected, rtol=1e-12)
    np.testing.assert_allclose(score(Lam), -expected, rtol=1e-12)
    assert ENTROPY_CONST == pytest.approx(3 * (1 + np.log(2 * np.pi)))
    # Identity information: entropy is the constant alone; scaling info by s lowers it by 3 ln s.
    assert entropy(np.eye(6)) == pytest.approx(ENTROPY_CONST)
    assert entropy(4.0 * np.eye(6)) == pytest.approx(ENTROPY_CONST - 3 * np.log(4.0))


def test_information_gain_values_and_monotonicity() -> None:
    rng = np.random.default_rng(1)
    Lam = random_spd(rng, 50, scale=100.0)
    M = random_spd(rng, 50, scale=10.0 ** rng.uniform(-3, 6, (50, 1, 1)), rank=3)
    g = information_gain(Lam, M)
    ref = 0.5 * (np.linalg.slogdet(Lam + M)[1] - np.linalg.slogdet(Lam)[1])
    np.testing.assert_allclose(g, ref, rtol=1e-8, atol=1e-10)
    assert np.all(g >= 0)
    assert np.all(information_gain(Lam, np.zeros_like(M)) == 0)
    # More information already present -> smaller gain of the same marker.
    M2 = random_spd(rng, 50, scale=50.0, rank=2)
    g2 = information_gain(Lam + M2, M)
    assert np.all(g2 <= g + 1e-12)
    # Huge marker information (paper model scale) stays finite and accurate.
    big = 1e6 * np.eye(6)[None].repeat(3, 0)
    lam = 100.0 * np.eye(6)[None].repeat(3, 0)
    np.testing.assert_allclose(information_gain(lam, big), 3 * np.log(1 + 1e4), rtol=1e-12)


def _scene(rng, n_poses=6, per_pose=40):
    T = world_from_cam_poses(np.c_[rng.uniform(0, 5, (n_poses, 2)), np.full(n_poses, 1.5)],
                             rng.uniform(0, 2 * np.pi, n_poses))
    pts, idx = [], []
    for n in range(n_poses):
        m = int(rng.integers(0, per_pose))
        pc = np.stack([rng.uniform(-1, 1, m), rng.uniform(-0.7, 0.7, m), np.ones(m)], 1) * rng.uniform(0.5, 6, (m, 1))
        pts.append(pc @ T[n, :3, :3].T + T[n, :3, 3])
        idx.append(np.full(m, n))
    return T, np.concatenate(pts), np.concatenate(idx)


def test_pose_information_batching_and_order_invariance() -> None:
    rng = np.random.default_rng(2)
    T, pts, idx = _scene(rng, n_poses=30, per_pose=60)
    ns = rng.integers(0, 10, len(pts))
    Lam = pose_information(T, K, pts, idx, ns)
    perm = rng.permutation(len(pts))
    np.testing.assert_allclose(pose_information(T, K, pts[perm], idx[perm], ns[perm]), Lam,
                               rtol=1e-10, atol=1e-10 * np.abs(Lam).max())
    for n in [0, 7, 29]:  # one pose at a time gives the same
        sel = idx == n
        single = pose_information(T[n:n + 1], K, pts[sel], np.zeros(sel.sum(), int), ns[sel])[0]
        np.testing.assert_allclose(single, Lam[n], rtol=1e-12, atol=1e-9)
    # Symmetric, at least the prior, and more look-alikes -> less information.
    np.testing.assert_allclose(Lam, Lam.transpose(0, 2, 1), atol=1e-9)
    assert np.all(np.linalg.eigvalsh(Lam - 100.0 * np.eye(6)) > -1e-8)
    assert np.all(entropy(pose_information(T, K, pts, idx, ns + 5)) >= entropy(Lam) - 1e-12)
    # No landmarks: the prior alone.
    np.testing.assert_allclose(pose_information(T, K, np.zeros((0, 3)), np.zeros(0, int), None),
                               np.broadcast_to(100.0 * np.eye(6), (30, 6, 6)))


def test_compiled_kernel_matches_numpy_whitening() -> None:
    """The compiled per-pose sum equals the numpy whitened-Jacobian Gram (two implementations)."""
    from markerplace.plan.score.localizability import gram, whitened_jacobians

    rng = np.random.default_rng(5)
    T, pts, idx = _scene(rng, n_poses=12, per_pose=80)
    ns = rng.integers(0, 30, len(pts))
    noise = NoiseConfig(max_range=4.0, pixel_sigma=1.7)
    K2 = np.array([[410.0, 0.0, 300.0], [0.0, 270.0, 225.0], [0.0, 0.0, 1.0]])  # fx != fy
    Lam = pose_information(T, K2, pts, idx, ns, noise) - np.eye(6) / noise.prior_sigma**2
    for n in range(len(T)):
        sel = idx == n
        p_c = (pts[sel] - T[n, :3, 3]) @ T[n, :3, :3]
        x, y, z = p_c.T[:, None]
        valid = (z > 1e-6) & (np.sum(p_c**2, 1)[None] <= noise.max_range**2)
        var = noise.landmark_sigma**2 * (1.0 + ns[sel][None])
        ref = gram(whitened_jacobians(x, y, z, var, valid, K2, noise.pixel_sigma))[0]
        np.testing.assert_allclose(Lam[n], ref, rtol=1e-9, atol=1e-9 * max(1.0, np.abs(ref).max()))
    assert np.any(np.sum((pts - T[idx, :3, 3]) ** 2, 1) > noise.max_range**2)  # range cut exercised
    # a non-finite point is dropped, not spread as NaN over its pose
    bad = pts.copy()
    bad[0] = np.nan
    with_nan = pose_information(T, K2, bad, idx, ns, noise) - np.eye(6) / noise.prior_sigma**2
    np.testing.assert_allclose(with_nan, pose_information(T, K2, pts[1:], idx[1:], ns[1:], noise)
                               - np.eye(6) / noise.prior_sigma**2, rtol=1e-12, atol=1e-9)


def test_pose_information_single_landmark_closed_form() -> None:
    """One landmark: J^T S^-1 J built by finite differences of the projection."""
    rng = np.random.default_rng(3)
    T = world_from_cam_pose(np.array([1.0, 2.0, 1.5]), 0.4)
    T[:3, :3] = T[:3, :3] @ so3_exp(np.array([0.1, -0.2, 0.05]))
    p = T[:3, :3] @ np.array([0.7, -0.4, 3.0]) + T[:3, 3]
    noise = NoiseConfig()
    n_p = 4

    def proj(Tc, pw):
        pc = Tc[:3, :3].T @ (pw - Tc[:3, 3])
        return K[:2, :2] @ (pc[:2] / pc[2]) + K[:2, 2]

    def exp_se3(xi):
        E = np.eye(4)
        E[:3, :3] = so3_exp(xi[:3])
        E[:3, 3] = xi[3:]  # first order is enough for central differences
        return E

    h = 1e-6
    J = np.stack([(proj(T @ exp_se3(h * e), p) - proj(T @ exp_se3(-h * e), p)) / (2 * h) for e in np.eye(6)], 1)
    Pm = np.stack([(proj(T, p + h * e) - proj(T, p - h * e)) / (2 * h) for e in np.eye(3)], 1)
    S = noise.pixel_sigma**2 * np.eye(2) + noise.landmark_sigma**2 * (1 + n_p) * Pm @ Pm.T
    expected = np.eye(6) / noise.prior_sigma**2 + J.T @ np.linalg.solve(S, J)
    got = pose_information(T[None], K, p[None], np.zeros(1, int), np.array([n_p]), noise)[0]
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-6 * np.abs(expected).max())
    del rng


def test_pose_information_drops_behind_and_far() -> None:
    T = world_from_cam_pose(np.zeros(3), 0.0)
    pc = np.array([[0.1, 0.0, 2.0], [0.0, 0.0, -2.0], [0.0, 0.1, 10.5], [0.2, 0.1, 4.0]])
    pw = pc @ T[:3, :3].T + T[:3, 3]
    all_ = pose_information(T[None], K, pw, np.zeros(4, int), None)
    kept = pose_information(T[None], K, pw[[0, 3]], np.zeros(2, int), None)
    np.testing.assert_allclose(all_, kept)


def test_visibility_rules() -> None:
    T = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    Tm = facing_marker(T, 3.0)
    assert marker_visibility(T[None], Tm, K, SIZE)[0]
    # Range.
    assert not marker_visibility(T[None], facing_marker(T, 10.5), K, SIZE)[0]
    assert marker_visibility(T[None], facing_marker(T, 9.5), K, SIZE)[0]
    assert not marker_visibility(T[None], facing_marker(T, 5.0), K, SIZE, max_range=4.0)[0]
    # Bearing: lateral offset at 2 m -> atan(l / 2).
    assert marker_visibility(T[None], facing_marker(T, 2.0, lateral=1.9), K, SIZE)[0]  # 43.5 deg
    assert not marker_visibility(T[None], facing_marker(T, 2.0, lateral=2.2), K, SIZE)[0]  # 47.7 deg
    assert not marker_visibility(T[None], facing_marker(T, 2.0, lateral=1.5), K, SIZE, max_bearing_deg=30.0)[0]
    # View angle between the marker normal and the direction to the camera.
    assert marker_visibility(T[None], facing_marker(T, 3.0, yaw_offset_deg=75.0), K, SIZE)[0]
    assert not marker_visibility(T[None], facing_marker(T, 3.0, yaw_offset_deg=85.0), K, SIZE)[0]
    assert not marker_visibility(T[None], facing_marker(T, 3.0, yaw_offset_deg=180.0), K, SIZE)[0]
    # Behind the camera.
    T_back = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), np.pi)
    assert not marker_visibility(T_back[None], Tm, K, SIZE)[0]
    # Batched + occlusion mask.
    Ts = np.stack([T, T_back, T])
    vis = marker_visibility(Ts, Tm, K, SIZE, occluded=np.array([False, False, True]))
    assert vis.tolist() == [True, False, False]


def test_noise_config_validation() -> None:
    with pytest.raises(ValueError):
        NoiseConfig(pixel_sigma=0.0)


def test_compiled_kernel_gives_the_same_bits_fresh_and_from_numba_cache(tmp_path):
    """The first run after install compiles the kernel, later runs load it from numba's cache:
    both must give identical information matrices (FMA contraction was not allowed for this)."""
    import subprocess
    import sys

    script = tmp_path / "run.py"
    script.write_text(
        "import sys, numpy as np\n"
        "from markerplace.geometry import Intrinsics, world_from_cam_poses\n"
        "from markerplace.plan.score.localizability import NoiseConfig, pose_information\n"
        "rng = np.random.default_rng(0)\n"
        "T = world_from_cam_poses(np.c_[rng.uniform(0, 5, (40, 2)), np.full(40, 1.5)], rng.uniform(0, 6.28, 40))\n"
        "pts = rng.uniform(-5, 10, (3000, 3)); idx = np.sort(rng.integers(0, 40, 3000))\n"
        "np.save(sys.argv[1], pose_information(T, Intrinsics().K, pts, idx, rng.integers(0, 5, 3000), NoiseConfig()))\n")
    env = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    for name in ("fresh", "cached"):
        subprocess.run([sys.executable, str(script), str(tmp_path / f"{name}.npy")], env=env, check=True)
    assert any((tmp_path / "numba_cache").rglob("*.nbi"))
    assert np.array_equal(np.load(tmp_path / "fresh.npy"), np.load(tmp_path / "cached.npy"))
