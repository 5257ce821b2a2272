"""The closed-form information matrices against GTSAM factor graphs built as the paper does."""

from __future__ import annotations

import numpy as np
import pytest

gtsam = pytest.importorskip("gtsam")
from gtsam.symbol_shorthand import L, M, X  # noqa: E402

from markerplace.geometry import Intrinsics, so3_exp, world_from_cam_pose, world_from_marker_pose  # noqa: E402
from markerplace.plan.score.localizability import NoiseConfig, pose_information  # noqa: E402
from markerplace.plan.score.marker_models import get_marker_model  # noqa: E402

NOISE = NoiseConfig()
INTR = Intrinsics()
K = INTR.K
CAL = gtsam.Cal3_S2(K[0, 0], K[1, 1], 0.0, K[0, 2], K[1, 2])


def random_camera(rng: np.random.Generator, tilted: bool) -> np.ndarray:
    T = world_from_cam_pose(np.array([rng.uniform(-5, 5), rng.uniform(-5, 5), 1.5]), rng.uniform(0, 2 * np.pi))
    if tilted:
        T[:3, :3] = T[:3, :3] @ so3_exp(rng.normal(size=3) * 0.3)
    return T


def random_landmarks(rng: np.random.Generator, T: np.ndarray, n: int) -> np.ndarray:
    """n world points in front of camera T, inside the image, 0.5-9 m deep."""
    z = rng.uniform(0.5, 7.0, n)
    u = rng.uniform(0, INTR.width, n)
    v = rng.uniform(0, INTR.height, n)
    pc = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
    keep = np.linalg.norm(pc, axis=1) < NOISE.max_range
    pc = pc[keep]
    return pc @ T[:3, :3].T + T[:3, 3]


def random_marker(rng: np.random.Generator, T: np.ndarray) -> np.ndarray:
    """A marker 1.5-6 m in front of the camera, roughly facing it."""
    pc = np.array([rng.uniform(-1, 1), rng.uniform(-0.5, 0.5), rng.uniform(1.5, 6.0)])
    centre = T[:3, :3] @ pc + T[:3, 3]
    normal = -(T[:3, :3] @ np.array([rng.uniform(-0.5, 0.5), 0.0, 1.0]))
    return world_from_marker_pose(centre, normal)


def camera_graph(T: np.ndarray) -> tuple:
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    pose = gtsam.Pose3(T)
    values.insert(X(0), pose)
    graph.add(gtsam.PriorFactorPose3(X(0), pose, gtsam.noiseModel.Isotropic.Sigma(6, NOISE.prior_sigma)))
    return graph, values, pose


def add_landmarks(graph, values, pose, pts: np.ndarray, n_sim: np.ndarray, sigma=None, offset: int = 0):
    cam = gtsam.PinholeCameraCal3_S2(pose, CAL)
    pix = gtsam.noiseModel.Isotropic.Sigma(2, NOISE.pixel_sigma)
    for i, p in enumerate(pts):
        key = L(offset + i)
        graph.add(gtsam.GenericProjectionFactorCal3_S2(cam.project(p), pix, X(0), key, CAL))
        s = NOISE.landmark_sigma * np.sqrt(1.0 + n_sim[i]) if sigma is None else sigma
        graph.add(gtsam.PriorFactorPoint3(key, p, gtsam.noiseModel.Isotropic.Sigma(3, s)))
        values.insert(key, p)


def marginal_cov(graph, values) -> np.ndarray:
    assert graph.error(values) < 1e-12  # measurements exact at the true values
    return gtsam.Marginals(graph, values).marginalCovariance(X(0))


@pytest.mark.parametrize("seed", range(12))
def test_paper_graph_matches_gtsam(seed: int) -> None:
    rng = np.random.default_rng(seed)
    T = random_camera(rng, tilted=seed % 2 == 1)
    pts = random_landmarks(rng, T, int(rng.integers(70, 100)))
    assert len(pts) >= 50
    n_sim = rng.integers(0, 21, len(pts))
    n_markers = seed % 4
    graph, values, pose = camera_graph(T)
    add_landmarks(graph, values, pose, pts, n_sim)
    Lam = pose_information(T[None], K, pts, np.zeros(len(pts), int), n_sim, NOISE)[0]
    rel = gtsam.noiseModel.Isotropic.Sigma(6, NOISE.marker_rel_sigma)
    mprior = gtsam.noiseModel.Isotropic.Sigma(6, NOISE.marker_prior_sigma)
    for j in range(n_markers):
        Tm = random_marker(rng, T)
        mk = gtsam.Pose3(Tm)
        values.insert(M(j), mk)
        graph.add(gtsam.BetweenFactorPose3(X(0), M(j), pose.between(mk), rel))
        graph.add(gtsam.PriorFactorPose3(M(j), mk, mprior))
        Lam = Lam + get_marker_model("paper", noise=NOISE).information(T[None], Tm, 0.4, K)[0]
    cov = marginal_cov(graph, values)
    ld_gtsam = np.linalg.slogdet(cov)[1]
    ld_ours = -np.linalg.slogdet(Lam)[1]
    assert ld_ours == pytest.approx(ld_gtsam, rel=1e-6)
    if n_markers == 0:  # well conditioned: the whole matrix agrees
        np.testing.assert_allclose(np.linalg.inv(cov), Lam, rtol=1e-6, atol=1e-6 * np.abs(Lam).max())


@pytest.mark.parametrize("seed", range(4))
def test_corners_model_matches_gtsam(seed: int) -> None:
    """Corners as nearly-known points (prior sigma 1e-6 m) in GTSAM vs the exact-known model."""
    rng = np.random.default_rng(100 + seed)
    T = random_camera(rng, tilted=seed % 2 == 1)
    Tm = random_marker(rng, T)
    size = 0.4
    corners = (np.array([[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]]) * size / 2) @ Tm[:3, :3].T + Tm[:3, 3]
    Mc = get_marker_model("corners", noise=NOISE).information(T[None], Tm, size, K)[0]
    assert np.abs(Mc).max() > 0, "test marker should be detectable"
    pts = random_landmarks(rng, T, 60)
    n_sim = rng.integers(0, 21, len(pts))
    graph, values, pose = camera_graph(T)
    add_landmarks(graph, values, pose, pts, n_sim)
    add_landmarks(graph, values, pose, corners, np.zeros(4), sigma=1e-6, offset=1000)
    cov = marginal_cov(graph, values)
    Lam = pose_information(T[None], K, pts, np.zeros(len(pts), int), n_sim, NOISE)[0] + Mc
    assert -np.linalg.slogdet(Lam)[1] == pytest.approx(np.linalg.slogdet(cov)[1], rel=1e-6)


def test_paper_marker_model_alone_matches_gtsam() -> None:
    """Camera prior + one marker: M from the model equals GTSAM's marginal information."""
    rng = np.random.default_rng(7)
    T = random_camera(rng, tilted=True)
    Tm = random_marker(rng, T)
    graph, values, pose = camera_graph(T)
    mk = gtsam.Pose3(Tm)
    values.insert(M(0), mk)
    graph.add(gtsam.BetweenFactorPose3(X(0), M(0), pose.between(mk),
                                       gtsam.noiseModel.Isotropic.Sigma(6, NOISE.marker_rel_sigma)))
    graph.add(gtsam.PriorFactorPose3(M(0), mk, gtsam.noiseModel.Isotropic.Sigma(6, NOISE.marker_prior_sigma)))
    cov = marginal_cov(graph, values)
    Lam = np.eye(6) / NOISE.prior_sigma**2 + get_marker_model("paper", noise=NOISE).information(T[None], Tm, 0.4, K)[0]
    assert -np.linalg.slogdet(Lam)[1] == pytest.approx(np.linalg.slogdet(cov)[1], rel=1e-6)
