"""The user's frame and the internal one shifted by a whole-metre offset: every conversion and
its inverse."""

from __future__ import annotations

import numpy as np

from markerplace.markers import Marker
from markerplace.scene.worldframe import (
    markers_to_internal,
    markers_to_user,
    points_to_internal,
    points_to_user,
    poses_to_internal,
    poses_to_user,
    world_offset,
)

OFFSET = np.array([500000.0, 4000000.0, 12.0])


class _Scene:
    meta = {"world_offset": OFFSET.tolist()}


def test_offset_of_a_scene_and_of_one_without():
    np.testing.assert_array_equal(world_offset(_Scene()), OFFSET)
    assert world_offset(object()).tolist() == [0.0, 0.0, 0.0]


def test_points_and_poses_round_trip_and_rotations_stay():
    p = np.array([[500001.5, 4000002.25, 13.0]])
    np.testing.assert_array_equal(points_to_internal(p, OFFSET), [[1.5, 2.25, 1.0]])
    np.testing.assert_array_equal(points_to_internal(p[:, :2], OFFSET), [[1.5, 2.25]])  # xy uses the offset's xy
    np.testing.assert_array_equal(points_to_user(points_to_internal(p, OFFSET), OFFSET), p)
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]
    T[:3, 3] = p[0]
    Ti = poses_to_internal(T, OFFSET)
    np.testing.assert_array_equal(Ti[:3, 3], [1.5, 2.25, 1.0])
    np.testing.assert_array_equal(Ti[:3, :3], T[:3, :3])
    np.testing.assert_array_equal(poses_to_user(Ti, OFFSET), T)
    assert T[0, 3] == 500001.5  # the input is not changed


def test_markers_move_with_their_poses_and_not_at_zero_offset():
    T = np.eye(4)
    T[:3, 3] = [500002.0, 4000001.0, 13.5]
    m = Marker(3, 0.16, T, "tag36h11")
    (mi,) = markers_to_internal([m], OFFSET)
    np.testing.assert_array_equal(mi.world_from_marker[:3, 3], [2.0, 1.0, 1.5])
    assert mi.tag_id == 3 and mi.size == 0.16
    np.testing.assert_array_equal(markers_to_user([mi], OFFSET)[0].world_from_marker, T)
    assert markers_to_internal([m], np.zeros(3))[0] is m
