"""Conventions: camera frames, projection round trips, marker frames, adjoint."""

import numpy as np
import pytest

from markerplace import geometry as g


def test_default_intrinsics_match_paper():
    K = g.Intrinsics().K
    assert np.allclose(K, [[300, 0, 300], [0, 300, 225], [0, 0, 1]])
    assert np.isclose(np.degrees(g.Intrinsics().hfov_rad), 90.0)
    assert np.allclose(g.Intrinsics.from_fov(600, 450, 90.0).K, K)


@pytest.mark.parametrize("yaw_deg", [0, 45, 90, 180, -135])
def test_level_camera_frame(yaw_deg):
    yaw = np.radians(yaw_deg)
    R = g.rotation_from_yaw(yaw)
    assert np.allclose(R.T @ R, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(R[:, 2], [np.cos(yaw), np.sin(yaw), 0])  # looks along yaw
    assert np.allclose(R[:, 1], [0, 0, -1])  # image y is down
    T = g.world_from_cam_pose([1, 2, 1.5], yaw)
    assert np.isclose(g.yaw_of(T), np.arctan2(np.sin(yaw), np.cos(yaw)))
    batched = g.world_from_cam_poses(np.array([[1, 2, 1.5]]), np.array([yaw]))[0]
    assert np.allclose(batched, T)


def test_project_backproject_round_trip():
    rng = np.random.default_rng(0)
    K = g.Intrinsics().K
    T = g.world_from_cam_pose([0.3, -1.0, 1.5], 0.7)
    uv = rng.uniform([0, 0], [600, 450], size=(50, 2))
    depth = rng.uniform(0.5, 9.0, size=50)
    pts = g.backproject(K, T, uv, depth)
    uv2, z2 = g.project(K, T, pts)
    assert np.allclose(uv2, uv) and np.allclose(z2, depth)


def test_point_straight_ahead_projects_to_principal_point():
    K = g.Intrinsics().K
    T = g.world_from_cam_pose([0, 0, 1.5], 0.0)
    uv, z = g.project(K, T, np.array([[4.0, 0.0, 1.5], [4.0, -1.0, 1.5], [4.0, 0.0, 2.5]]))
    assert np.allclose(uv[0], [300, 225]) and np.isclose(z[0], 4.0)
    assert uv[1, 0] > 300  # -y is to the camera's right
    assert uv[2, 1] < 225  # up is towards image row 0


def test_marker_frame_right_handed_and_facing_normal():
    T = g.world_from_marker_pose([2, 0, 1.5], [-1, 0, 0.05])
    R = T[:3, :3]
    assert np.isclose(np.linalg.det(R), 1.0)
    assert np.allclose(R[:, 2], [-1, 0, 0]) and np.allclose(R[:, 1], [0, 0, 1])
    # a camera facing the marker sees marker +x on its right (image u grows)
    cam = g.world_from_cam_pose([0, 0, 1.5], 0.0)
    corners = g.transform_points(T, g.marker_corners_local(0.4))
    uv, _ = g.project(g.Intrinsics().K, cam, corners)
    bl, br, tr, tl = uv  # the detector's order (AprilTag library)
    assert tr[0] > tl[0] and br[0] > bl[0] and bl[1] > tl[1] and br[1] > tr[1]
    with pytest.raises(ValueError):
        g.world_from_marker_pose([0, 0, 0], [0, 0, 1])


def test_invert_and_adjoint():
    rng = np.random.default_rng(1)
    R = g.so3_exp(rng.normal(size=3))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, rng.normal(size=3)
    assert np.allclose(g.invert(T) @ T, np.eye(4))
    # Ad(T) xi maps a right-perturbation to a left one: T Exp(xi) = Exp(Ad xi) T (first order)
    xi = rng.normal(size=6) * 1e-6
    def hat(x):
        m = np.zeros((4, 4))
        m[:3, :3] = g.skew(x[:3])
        m[:3, 3] = x[3:]
        return m
    lhs = T @ (np.eye(4) + hat(xi))
    rhs = (np.eye(4) + hat(g.adjoint(T) @ xi)) @ T
    assert np.allclose(lhs, rhs, atol=1e-12)
    assert np.isclose(g.rotation_angle_deg(np.eye(3), g.so3_exp([0, 0, np.radians(30)])), 30.0)
