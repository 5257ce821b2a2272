"""Discretization on hand-built box scenes: flood fill, clearance, furniture, candidates, errors."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from helpers.box_scenes import DOOR_Y, RECTS, TABLE, T, two_rooms
from markerplace import geometry
from markerplace.errors import UserError
from markerplace.plan.discretize.artifact import load, save
from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
from markerplace.scene.types import Room, Scene


def two_room_scene(rooms: bool = True) -> Scene:
    rm = (Room("a", (0, 0, 5, 4)), Room("b", (5, 0, 9, 4))) if rooms else ()
    return Scene("two_rooms", tuple(two_rooms()), rm, 0.0)


@pytest.fixture(scope="module")
def scene():
    return two_room_scene()


@pytest.fixture(scope="module")
def disc(scene):
    return discretize(scene, DiscretizeConfig())


def inside_any(xy: np.ndarray, rects=RECTS) -> np.ndarray:
    xy = np.atleast_2d(xy)
    out = np.zeros(len(xy), bool)
    for x0, y0, x1, y1 in rects:
        out |= (xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)
    return out


def dist_to_rects(xy: np.ndarray, rects=RECTS) -> np.ndarray:
    d = np.full(len(xy), np.inf)
    for x0, y0, x1, y1 in rects:
        dx = np.maximum.reduce([x0 - xy[:, 0], np.zeros(len(xy)), xy[:, 0] - x1])
        dy = np.maximum.reduce([y0 - xy[:, 1], np.zeros(len(xy)), xy[:, 1] - y1])
        d = np.minimum(d, np.hypot(dx, dy))
    return d


def test_flood_reaches_both_rooms_through_the_door(disc):
    x = disc.locations[:, 0]
    assert (x < 5).sum() > 20 and (x > 5).sum() > 20
    # free space in both rooms; the automatic start is in open floor
    occ = disc.occupancy_of(0)
    assert disc.occupancy.shape[0] == 1 and list(disc.planned_storeys) == [0]
    r = int((2.0 - disc.grid_origin[1]) / disc.grid_resolution)
    c = int((7.0 - disc.grid_origin[0]) / disc.grid_resolution)
    assert occ[r, c] == 0
    assert set(np.unique(occ)) <= {-1, 0, 1}
    assert not inside_any(disc.start) and dist_to_rects(disc.start[None])[0] > 0.5


def test_locations_keep_clearance_and_stay_inside(disc):
    d = dist_to_rects(disc.locations)
    assert np.all(d >= 0.3 - disc.grid_resolution)
    x, y = disc.locations.T
    assert np.all((x > 0) & (x < 9) & (y > 0) & (y < 4))
    # regular lattice: neighbours are grid_spacing apart
    dd = np.abs(disc.locations[:, None] - disc.locations[None]).sum(-1)
    np.fill_diagonal(dd, np.inf)
    assert np.allclose(dd.min(axis=1), 0.5)


def test_no_location_above_the_table(disc):
    x, y = disc.locations.T
    on_table = (x >= TABLE[0]) & (x <= TABLE[2]) & (y >= TABLE[1]) & (y <= TABLE[3])
    assert not on_table.any()
    # but the free floor right next to it is used
    assert np.any((np.abs(x - 1.6) < 0.3) & (np.abs(y - 2.5) < 0.3))


def test_poses(disc):
    L, N = len(disc.locations), len(disc.world_from_cam)
    assert N == 8 * L and disc.num_yaws == 8
    assert np.array_equal(disc.location_index, np.repeat(np.arange(L), 8))
    assert np.allclose(disc.yaw[:8], 2 * np.pi * np.arange(8) / 8)
    assert np.allclose(disc.world_from_cam[:, :3, 3], np.column_stack([disc.locations[disc.location_index], np.full(N, 1.5)]))
    for i in (0, 3, N - 1):
        assert np.isclose(geometry.yaw_of(disc.world_from_cam[i]), np.arctan2(np.sin(disc.yaw[i]), np.cos(disc.yaw[i])))
    assert np.all(disc.location_z == 1.5)
    assert disc.floor_z == 0.0 and np.all(disc.location_storey == 0)
    assert list(disc.storeys) == pytest.approx([0.0])


def test_candidates_on_walls_facing_the_room(disc):
    C = len(disc.candidate_position)
    assert C >= 15
    p, n = disc.candidate_position, disc.candidate_normal
    assert np.allclose(p[:, 2], 1.5)
    assert np.allclose(np.linalg.norm(n, axis=1), 1) and np.allclose(n[:, 2], 0)
    assert np.all(dist_to_rects(p[:, :2]) < 0.01)  # on a surface
    front = p[:, :2] + 0.2 * n[:, :2]
    assert not inside_any(front).any()  # normal points into free space
    assert np.all((front[:, 0] > 0) & (front[:, 0] < 9) & (front[:, 1] > 0) & (front[:, 1] < 4))
    T_ = disc.candidate_world_from_marker
    assert np.allclose(T_[:, :3, 2], n) and np.allclose(T_[:, :3, 3], p)
    # every stretch of wall gets candidates: each room's 4 walls
    for sel in (p[:, 0] < 5, p[:, 0] > 5):
        dirs = {tuple(np.round(v[:2]).astype(int)) for v in n[sel]}
        assert dirs == {(1, 0), (-1, 0), (0, 1), (0, -1)}


def test_no_candidate_straddles_corner_or_door(disc):
    half = 0.2
    for p, n in zip(disc.candidate_position[:, :2], disc.candidate_normal[:, :2]):
        t = np.array([-n[1], n[0]])
        for u in np.linspace(-half, half, 9):
            q = p + u * t
            assert inside_any(q - 0.02 * n)[0], (p, n, u)  # wall behind every part of the tag
            assert not inside_any(q + 0.02 * n)[0], (p, n, u)  # nothing in front (no corner)
    # nothing hangs in the door opening
    in_door = (np.abs(disc.candidate_position[:, 0] - 5) < 0.1) & \
              (disc.candidate_position[:, 1] > DOOR_Y[0] - 0.2) & (disc.candidate_position[:, 1] < DOOR_Y[1] + 0.2)
    assert not in_door.any()


def test_candidate_spacing(disc):
    p, n = disc.candidate_position, disc.candidate_normal
    d = np.linalg.norm(p[:, None] - p[None], axis=-1)
    same_dir = (n @ n.T) > np.cos(np.radians(30))
    np.fill_diagonal(d, np.inf)
    assert np.all(d[same_dir] >= 1.0 - 1e-9)
    # uniform downsampling: a 4 m wall carries at least 3 candidates
    west = np.abs(p[:, 0] - T / 2) < 1e-3
    assert west.sum() >= 3


def test_perimeter_arclength(disc):
    s = disc.perimeter_arclength
    assert len(s) == len(disc.candidate_position)
    assert np.all(np.diff(s) >= 0) and s[0] >= 0 and s[-1] <= disc.perimeter_length
    # free-space boundary: about the two rooms' perimeters (18 + 16 m, less door and shelf changes)
    assert 25 < disc.perimeter_length < 45


def test_save_load_roundtrip(disc, tmp_path):
    path = tmp_path / "d.npz"
    save(disc, path)
    d2 = load(path)
    for k in ("locations", "world_from_cam", "candidate_world_from_marker", "occupancy", "perimeter_arclength", "storeys"):
        assert np.array_equal(getattr(d2, k), getattr(disc, k))
    assert np.array_equal(d2.location_z, disc.location_z) and d2.perimeter_length == disc.perimeter_length
    assert d2.summary == disc.summary
    assert np.array_equal(d2.origin, disc.grid_origin) and d2.resolution == disc.grid_resolution


def test_deterministic_and_start_independent(disc):
    d2 = discretize(two_room_scene(rooms=False), DiscretizeConfig())
    assert np.array_equal(d2.locations, disc.locations)
    assert np.array_equal(d2.candidate_position, disc.candidate_position)  # deterministic
    d3 = discretize(two_room_scene(), DiscretizeConfig(start=(7.0, 1.0)))
    assert np.array_equal(d3.locations, disc.locations)  # same free space from the other room


def test_two_storeys():
    parts = two_rooms(0.0) + two_rooms(3.0, prefix="up/")
    sc = Scene("two_storeys", tuple(parts))
    d1 = discretize(sc, DiscretizeConfig(level=1))
    assert list(d1.storeys) == pytest.approx([0.0, 3.0])
    assert np.all(d1.location_z == 4.5) and np.all(d1.location_storey == 1)
    assert np.allclose(d1.candidate_position[:, 2], 4.5)
    with pytest.raises(UserError, match="found 2 storey"):
        discretize(sc, DiscretizeConfig(level=2))
    both = discretize(sc, DiscretizeConfig(level=None))
    assert list(both.planned_storeys) == [0, 1] and both.occupancy.shape[0] == 2
    for s, z in ((0, 1.5), (1, 4.5)):
        on = both.location_storey == s
        assert on.sum() == len(d1.locations) and np.all(both.location_z[on] == z)
        assert np.allclose(both.candidate_position[both.candidate_storey == s, 2], z)


@pytest.mark.parametrize("kw, message", [
    (dict(start=(5.0, 0.5)), r"--start 5,0.5 is inside an obstacle .*pick a point in open floor space"),
    (dict(start=(8.0, 3.7)), r"inside an obstacle"),
    (dict(start=(20.0, 20.0)), r"--start 20,20 is outside the model"),
    (dict(level=1), r"--level 1 is out of range: found 1 storey.*or --level all"),
    (dict(height=3.0), r"no walls cut the plane at z=3.00 m; check --height/--level/--up"),
    (dict(clearance=2.5), r"no feasible camera poses"),
    (dict(tag_size=6.0), r"no candidate marker poses"),
])
def test_errors(scene, kw, message):
    kw = dict(kw)
    tag_size = kw.pop("tag_size", 0.4)  # the placement's tag size, passed on its own
    with pytest.raises(UserError, match=message) as err:
        discretize(scene, replace(DiscretizeConfig(), **kw), tag_size)
    assert "\n" not in str(err.value)
