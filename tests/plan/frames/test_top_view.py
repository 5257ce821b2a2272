"""Floor, top-down grid and the Discretization of a frames plan (plan/frames/top_view.py)."""

from __future__ import annotations

import numpy as np

from helpers.frames import tiny_poses
from markerplace.plan.frames.top_view import floor_height, occupancy_grid
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster


def _walls_only() -> RayCaster:
    """Four 3 m walls of a 4 m square, nothing horizontal."""
    V, F = [], []
    corners = [(0, 0), (4, 0), (4, 4), (0, 4)]
    for (x0, y0), (x1, y1) in zip(corners, corners[1:] + corners[:1]):
        b = len(V)
        V += [(x0, y0, 0), (x1, y1, 0), (x1, y1, 3), (x0, y0, 3)]
        F += [(b, b + 1, b + 2), (b, b + 2, b + 3)]
    return RayCaster(np.array(V, float), np.array(F))


def test_floor_is_the_lowest_large_horizontal_surface():
    rc = RayCaster(*load_scene("tiny").geometry())
    z, found = floor_height(rc, tiny_poses(8)[:, 2, 3], 1.5)
    assert found and abs(z) < 1e-6  # tiny's floor is z = 0 (the desk top at 1 m is higher)


def test_without_a_floor_it_is_eye_height_below_the_lowest_camera():
    z, found = floor_height(_walls_only(), np.array([1.4, 1.7]), 1.5)
    assert not found and abs(z - (-0.1)) < 1e-9


def test_grid_free_where_the_cameras_went_obstacles_on_the_surface():
    rc = _walls_only()
    cams = np.array([[2.0, 2.0], [2.5, 2.0]])
    occ, origin = occupancy_grid(rc, cams, np.array([[0.0, 2.0]]), 0.0, 1.6, 0.05)

    def at(xy):
        c, r = np.floor((np.asarray(xy) - origin) / 0.05).astype(int)
        return occ[r, c]

    assert at([2.0, 2.0]) == 0 and at([2.25, 2.2]) == 0
    assert at([1.0, 1.0]) == -1  # never visited
    assert (occ == 1).sum() > 0
