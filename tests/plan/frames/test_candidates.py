"""Candidate tag spots seen from a handheld path (plan/frames/candidates.py), on the true ``tiny``
room so that right and wrong are known exactly."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.frames import TINY_WALLS, tiny_poses
from markerplace.geometry import Intrinsics
from markerplace.plan.discretize.candidate_rules import CandidateConfig
from markerplace.plan.frames.candidates import BELOW, frame_candidates, marker_poses
from markerplace.scan.simulate import distance_to_scene
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster


def rc_normals(faces):
    return RayCaster(*load_scene("tiny").geometry()).face_normal[faces]

INTR = Intrinsics(320, 240, 262.5, 262.5, 159.5, 119.5)


@pytest.fixture(scope="module")
def found():
    rc = RayCaster(*load_scene("tiny").geometry())
    T = tiny_poses(40)
    return T, frame_candidates(rc, T, INTR, CandidateConfig(), 0.16, floor_z=0.0)


def test_spots_are_on_walls_facing_the_cameras_spaced_out(found):
    T, cand = found
    p, n = cand.position, cand.normal
    assert len(p) >= 6
    assert np.all(distance_to_scene(p, load_scene("tiny")) < 0.005)
    t, f = RayCaster(*load_scene("tiny").geometry()).first_hits(p + 0.05 * n, -n, 0.1)
    assert np.all(f >= 0) and np.all(np.abs(np.einsum("ij,ij->i", rc_normals(f), n)) > np.cos(np.radians(2)))
    on_wall = np.min(np.abs(p[:, :2, None] - np.array(TINY_WALLS)[None, None]), axis=(1, 2)) < 0.01
    assert on_wall.mean() >= 0.9, p[~on_wall]  # the rest on furniture the off-wall rule cannot tell (a plant)
    assert np.all(np.abs(n[:, 2]) < 0.05) and np.allclose(np.linalg.norm(n, axis=1), 1.0)
    centre = T[:, :3, 3].mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", n, centre - p) > 0)  # towards the room
    assert np.all(p[:, 2] >= T[:, 2, 3].min() - BELOW - 1e-9)
    d = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(len(p)) * 9
    similar = n @ n.T >= np.cos(np.radians(CandidateConfig().normal_diff_deg))
    assert np.all(d[similar] >= CandidateConfig().marker_spacing - 1e-9)


def test_spots_go_round_the_camera_path_as_a_loop(found):
    _, cand = found
    assert np.all(np.diff(cand.arclength) >= 0) and cand.arclength[-1] < cand.loop_length
    assert cand.loop_length > 6.0  # most of the 14.4 m perimeter


def test_marker_pose_axes():
    n = np.array([[0.99, 0.0, 0.14], [0.0, -1.0, 0.0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    T = marker_poses(np.zeros((2, 3)), n)
    R = T[:, :3, :3]
    assert np.allclose(np.einsum("nij,nkj->nik", R, R), np.eye(3), atol=1e-12)
    assert np.allclose(R[:, :, 2], n) and np.all(R[:, 2, 1] > 0.98)  # z = normal, y = up on the wall
    assert np.allclose(np.linalg.det(R), 1.0)
    assert np.allclose(T[1, :3, 0], [1.0, 0.0, 0.0])  # x = y x z: the viewer's right


def test_furniture_standing_off_the_wall_is_no_spot_unless_allowed():
    """tiny's bookshelf and cabinet fronts are seen from the path; the off-wall rule removes
    them (as the mesh plan's does), ``allow`` lets them back."""
    rc = RayCaster(*load_scene("tiny").geometry())
    T = tiny_poses(40)
    allowed = frame_candidates(rc, T, INTR, CandidateConfig(allow=("off-wall",)), 0.16, floor_z=0.0)
    off = np.min(np.abs(allowed.position[:, :2, None] - np.array(TINY_WALLS)[None, None]), axis=(1, 2)) > 0.1
    assert off.sum() >= 2
    assert allowed.counts["removed"]["off-wall"] == 0
