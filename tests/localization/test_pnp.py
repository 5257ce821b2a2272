"""PnP (P3P RANSAC + LM), pose errors, AprilTag detection and tag poses."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from helpers.official_tags import official_square
from markerplace.geometry import Intrinsics, invert, project, so3_exp, world_from_cam_pose, world_from_marker_pose
from markerplace.localization.pnp import PnPConfig, estimate_pose, pose_errors
from markerplace.localization.tags import TagDetection, detect_tags, pose_from_tag
from markerplace.markers import Marker

INTR = Intrinsics()
K = INTR.K


def _random_pose(rng: np.random.Generator) -> np.ndarray:
    T = world_from_cam_pose(rng.uniform(-3, 3, size=3), rng.uniform(-np.pi, np.pi))
    T[:3, :3] = T[:3, :3] @ so3_exp(rng.normal(scale=0.2, size=3))
    return T


def _synthetic_correspondences(rng, T, n, outlier_frac, noise_px):
    """n world points seen by camera T: (points (n, 3), pixels (n, 2), is_inlier (n,))."""
    u = rng.uniform(0, INTR.width - 1, n)
    v = rng.uniform(0, INTR.height - 1, n)
    z = rng.uniform(2.0, 10.0, n)
    p_cam = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
    pts = p_cam @ T[:3, :3].T + T[:3, 3]
    px = np.stack([u, v], axis=1) + rng.normal(scale=noise_px, size=(n, 2))
    inl = np.ones(n, bool)
    n_out = int(round(outlier_frac * n))
    out = rng.choice(n, n_out, replace=False)
    px[out] = np.stack([rng.uniform(0, INTR.width, n_out), rng.uniform(0, INTR.height, n_out)], axis=1)
    inl[out] = False
    return pts, px, inl


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_pnp_recovers_pose_with_half_outliers(seed):
    rng = np.random.default_rng(seed)
    T = _random_pose(rng)
    pts, px, inl = _synthetic_correspondences(rng, T, 200, 0.5, 0.5)
    est = estimate_pose(pts, px, K, PnPConfig(), seed=seed)
    assert est.world_from_cam is not None
    dt, dr = pose_errors(est.world_from_cam, T)
    assert dt < 0.01 and dr < 0.1, (dt, dr)
    # the inlier set is (almost exactly) the true one; an outlier may land within 4 px by chance
    assert est.inliers[inl].mean() > 0.97
    assert est.inliers[~inl].mean() < 0.05
    assert est.num_inliers == int(est.inliers.sum())


def test_pnp_is_deterministic_given_seed():
    rng = np.random.default_rng(5)
    T = _random_pose(rng)
    pts, px, _ = _synthetic_correspondences(rng, T, 100, 0.6, 1.0)
    a = estimate_pose(pts, px, K, PnPConfig(), seed=3)
    b = estimate_pose(pts, px, K, PnPConfig(), seed=3)
    np.testing.assert_array_equal(a.world_from_cam, b.world_from_cam)
    np.testing.assert_array_equal(a.inliers, b.inliers)


def test_pnp_fails_on_pure_outliers():
    rng = np.random.default_rng(0)
    T = _random_pose(rng)
    pts, px, _ = _synthetic_correspondences(rng, T, 200, 1.0, 0.0)
    est = estimate_pose(pts, px, K, PnPConfig(), seed=0)
    assert est.world_from_cam is None
    assert not est.success
    assert est.num_inliers < PnPConfig().min_inliers


def test_pnp_fails_with_too_few_points():
    rng = np.random.default_rng(0)
    T = _random_pose(rng)
    pts, px, _ = _synthetic_correspondences(rng, T, 8, 0.0, 0.0)
    est = estimate_pose(pts, px, K, PnPConfig(min_inliers=12))
    assert est.world_from_cam is None and est.inliers.shape == (8,)
    # ... but the same points succeed when fewer inliers are demanded
    est = estimate_pose(pts, px, K, PnPConfig(min_inliers=6))
    assert est.world_from_cam is not None
    dt, dr = pose_errors(est.world_from_cam, T)
    assert dt < 1e-5 and dr < 1e-4


def test_pose_errors_formulas():
    T = world_from_cam_pose(np.array([1.0, 2.0, 1.5]), 0.3)
    U = T.copy()
    U[:3, 3] += np.array([0.03, -0.04, 0.0])  # 5 cm
    U[:3, :3] = T[:3, :3] @ so3_exp(np.radians(7.0) * np.array([0.0, 0.6, 0.8]))
    dt, dr = pose_errors(U, T)
    assert dt == pytest.approx(0.05, abs=1e-12)
    assert dr == pytest.approx(7.0, abs=1e-9)
    assert pose_errors(T, T) == pytest.approx((0.0, 0.0), abs=1e-6)
    # symmetric; a half-turn gives 180 degrees
    assert pose_errors(T, U) == pytest.approx((dt, dr))
    H = T.copy()
    H[:3, :3] = T[:3, :3] @ so3_exp(np.array([0.0, 0.0, np.pi]))
    assert pose_errors(H, T)[1] == pytest.approx(180.0, abs=1e-6)


# ---- tags -----------------------------------------------------------------------------------

def _tag_image(tag_id: int, size: int, pad: int) -> tuple[np.ndarray, np.ndarray]:
    """White-padded official tag image (apriltag-imgs) and its black-square corners in the
    detector's order as printed (BL, BR, TR, TL), OpenCV pixels."""
    img = cv2.copyMakeBorder(official_square(tag_id, size), pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)
    lo, hi = pad - 0.5, pad + size - 0.5  # outer edges of the black square
    return img, np.array([[lo, hi], [hi, hi], [hi, lo], [lo, lo]])


def test_detect_tag_plain_and_rotated():
    img, corners = _tag_image(3, 200, 100)
    dets = detect_tags(img)
    assert [d.tag_id for d in dets] == [3]
    np.testing.assert_allclose(dets[0].corners, corners, atol=1.0)
    np.testing.assert_allclose(dets[0].center, corners.mean(0), atol=1.0)
    # rotating the printed image by 90 degrees (counter-clockwise) rotates the tag's own corners:
    # the printed bottom-left corner moves to the image's bottom-right
    rot = np.ascontiguousarray(np.rot90(img))
    n = img.shape[0]
    rot_corners = np.stack([corners[:, 1], n - 1 - corners[:, 0]], axis=1)
    det = detect_tags(cv2.cvtColor(rot, cv2.COLOR_GRAY2RGB))[0]
    np.testing.assert_allclose(det.corners, rot_corners, atol=1.0)
    assert det.corners[0, 0] > 250 and det.corners[0, 1] > 250  # printed BL now bottom-right in the image


def test_detect_tag_perspective_warp():
    img, corners = _tag_image(101, 400, 200)
    dst = np.array([[170.9, 360.2], [400.6, 330.4], [420.2, 110.1], [150.3, 80.7]], np.float32)  # BL, BR, TR, TL
    H = cv2.getPerspectiveTransform(corners.astype(np.float32), dst)
    warped = cv2.warpPerspective(img, H, (INTR.width, INTR.height), flags=cv2.INTER_LINEAR, borderValue=255)
    dets = detect_tags(np.dstack([warped] * 3))
    assert [d.tag_id for d in dets] == [101]
    np.testing.assert_allclose(dets[0].corners, dst, atol=1.0)


def test_no_tags_in_noise():
    rng = np.random.default_rng(0)
    assert detect_tags(rng.integers(0, 256, (INTR.height, INTR.width, 3), dtype=np.uint8)) == []


@pytest.mark.parametrize("yaw_deg, normal", [(80.0, (0.0, -1.0, 0.0)), (90.0, (0.0, -1.0, 0.0)), (60.0, (-0.5, -1.0, 0.0)), (120.0, (0.3, -1.0, 0.0))])
def test_pose_from_tag_recovers_pose(yaw_deg, normal):
    marker = Marker(5, 0.4, world_from_marker_pose(np.array([2.0, 4.0, 1.5]), np.array(normal)))
    T = world_from_cam_pose(np.array([1.2, 1.0, 1.4]), np.radians(yaw_deg))
    T[:3, :3] = T[:3, :3] @ so3_exp(np.radians(np.array([5.0, -3.0, 4.0])))  # pitch/roll/yaw tilt
    uv, z = project(K, T, marker.corners_world())
    assert np.all(z > 0)
    est = pose_from_tag(TagDetection(5, uv, uv.mean(0)), marker, K)
    dt, dr = pose_errors(est, T)
    assert dt < 1e-6 and dr < 1e-6
    # world_from_cam maps the camera centre; the marker is in front of the estimated camera
    assert (invert(est) @ np.append(marker.position, 1.0))[2] > 0


def test_pose_from_tag_on_rendered_tag():
    """Render a tag on a wall by its exact homography, detect it and recover the camera pose."""
    size_px, pad = 400, 200
    img, corners_px = _tag_image(17, size_px, pad)
    marker = Marker(17, 0.4, world_from_marker_pose(np.array([0.0, 3.0, 1.5]), np.array([0.0, -1.0, 0.0])))
    T = world_from_cam_pose(np.array([0.5, 0.5, 1.3]), np.radians(100.0))
    uv, _ = project(K, T, marker.corners_world())
    H = cv2.getPerspectiveTransform(corners_px.astype(np.float32), uv.astype(np.float32))
    warped = cv2.warpPerspective(img, H, (INTR.width, INTR.height), flags=cv2.INTER_LINEAR, borderValue=255)
    dets = detect_tags(warped)
    assert [d.tag_id for d in dets] == [17]
    np.testing.assert_allclose(dets[0].corners, uv, atol=1.0)
    dt, dr = pose_errors(pose_from_tag(dets[0], marker, K), T)
    assert dt < 0.05 and dr < 2.0, (dt, dr)
