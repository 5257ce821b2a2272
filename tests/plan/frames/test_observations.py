"""One frame's observation from its own images (plan/frames/observations.py): SIFT lifted by the
real depth, and which tags the depth hides."""

from __future__ import annotations

import numpy as np

from markerplace.geometry import Intrinsics, project
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.visibility import marker_points
from markerplace.plan.frames.candidates import marker_poses
from markerplace.plan.frames.observations import frame_features

INTR = Intrinsics(320, 240, 262.5, 262.5, 159.5, 119.5)


def _wall_image():
    rng = np.random.default_rng(0)
    tex = rng.integers(0, 255, (30, 40), dtype=np.uint8)
    rgb = np.repeat(np.kron(tex, np.ones((8, 8), np.uint8))[..., None], 3, axis=2)
    return rgb


def test_keypoints_without_depth_are_dropped_and_points_lie_on_the_wall():
    cfg = ImagingConfig(camera=INTR)
    depth = np.full((240, 320), 2.0, np.float32)
    depth[:, :160] = 0.0  # no reading on the left half
    f = frame_features(_wall_image(), depth, np.eye(4), np.zeros((0, 5, 3)), cfg)
    assert len(f.keypoints) > 10
    assert np.all(f.keypoints[:, 0] >= 158)
    assert np.allclose(f.points_world[:, 2], 2.0, atol=1e-4)
    assert f.extras["candidate_unoccluded"].shape == (0,)


def test_a_real_cameras_off_centre_principal_point_lifts_the_right_pixel():
    """TUM's freiburg1 camera (cx 318.6, cy 255.3 at 640x480): the depth pixel under a keypoint is
    the keypoint's own pixel, not one scaled by 2 cx / width (the renders' assumption)."""
    intr = Intrinsics(640, 480, 517.3, 516.5, 318.6, 255.3)
    rgb = np.kron(_wall_image(), np.ones((2, 2, 1), np.uint8))
    depth = np.zeros((480, 640), np.float32)
    depth[:240] = 2.0  # top half at 2 m, bottom half no reading
    f = frame_features(rgb, depth, np.eye(4), np.zeros((0, 5, 3)), ImagingConfig(camera=intr))
    assert len(f.keypoints) > 10
    assert np.all(f.keypoints[:, 1] <= 239.5)  # lifted only where its own pixel has depth (2 cy / 480 = 1.06)
    back = f.points_world[:, 1] / f.points_world[:, 2] * intr.fy + intr.cy  # reprojects onto itself
    assert np.allclose(back, f.keypoints[:, 1], atol=0.01)


def test_a_tag_is_hidden_only_by_depth_nearer_than_it():
    cfg = ImagingConfig(camera=INTR)
    # a level camera at the origin looking along world +x at the wall x = 2 (world z up)
    cam = np.eye(4)
    cam[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    centres = np.array([[2.0, 0.5, 0.0], [2.0, -0.5, 0.0], [2.0, 0.0, 0.6], [2.0, 5.0, 0.0]])
    T = marker_poses(centres, np.tile([-1.0, 0.0, 0.0], (4, 1)))
    samples = marker_points(T, 0.16)
    depth = np.full((240, 320), 2.0, np.float32)
    uv, _ = project(INTR.K, cam, centres)
    u, v = np.round(uv[1]).astype(int)
    depth[v - 30:v + 30, u - 30:u + 30] = 1.0  # something in front of tag 1
    u, v = np.round(uv[2]).astype(int)
    depth[v - 30:v + 30, u - 30:u + 30] = 0.0  # a depth hole over tag 2: not hidden
    seen = frame_features(_wall_image(), depth, cam, samples, cfg).extras["candidate_unoccluded"]
    assert seen.tolist() == [True, False, True, False]  # tag 3 is outside the image
