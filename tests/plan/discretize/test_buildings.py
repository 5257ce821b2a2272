"""Discretization of buildings that are not tidy boxes: storeys, a sunken room, glass, furniture
tops, narrow doorways (the built-in ``house``), and scan defects (holes in walls, missing
ceilings, flipped normals, a model without ground) on hand-built scenes."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from helpers.box_scenes import H, T, box, quad, two_rooms
from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
from markerplace.scene.raycast import RayCaster
from markerplace.scene.types import MeshPart, Scene


@pytest.fixture(scope="module")
def house_disc(house):
    return discretize(house, DiscretizeConfig())


def _in(xy, bounds, margin=0.0):
    x0, y0, x1, y1 = bounds
    return (xy[:, 0] > x0 + margin) & (xy[:, 0] < x1 - margin) & (xy[:, 1] > y0 + margin) & (xy[:, 1] < y1 - margin)


def test_house_finds_both_storeys_and_plans_them_together(house, house_disc):
    d = house_disc
    assert list(d.storeys) == pytest.approx(house.meta["storeys"], abs=0.01)
    assert list(d.planned_storeys) == [0, 1] and d.occupancy.shape[0] == 2
    for s in (0, 1):
        assert (d.location_storey == s).sum() > 60
        assert (d.candidate_storey == s).sum() > 10
    # every room of both storeys has camera locations (the stair room is all stair)
    for room in (r for r in house.rooms if r.name != "stairs"):
        s = int(np.argmin(np.abs(np.asarray(house.meta["storeys"]) - room.floor_z)))
        on = (d.location_storey == s) & _in(d.locations, room.bounds, 0.1)
        assert on.sum() >= 2, room.name
    # one level at a time gives the same poses as the storey's part of --level all
    upper = discretize(house, DiscretizeConfig(level=1))
    assert np.array_equal(upper.locations, d.locations[d.location_storey == 1])
    assert np.array_equal(upper.candidate_position, d.candidate_position[d.candidate_storey == 1])


def test_sunken_room_belongs_to_its_storey_at_eye_level_above_its_own_floor(house, house_disc):
    d = house_disc
    living = next(r for r in house.rooms if r.name == house.meta["sunken_room"])
    sunk = house.meta["sunken_floor_z"]
    on = (d.location_storey == 0) & _in(d.locations, living.bounds, 0.35)
    assert on.sum() >= 20
    assert np.allclose(d.location_z[on], sunk + 1.5)
    kitchen = next(r for r in house.rooms if r.name == "kitchen")
    on_k = (d.location_storey == 0) & _in(d.locations, kitchen.bounds, 0.35)
    assert on_k.sum() >= 10 and np.allclose(d.location_z[on_k], 1.5)
    cand = (d.candidate_storey == 0) & _in(d.candidate_position[:, :2], living.bounds, -0.2) & \
        (d.candidate_position[:, 1] < living.bounds[3] - 0.3)
    assert cand.sum() >= 3 and np.allclose(d.candidate_position[cand, 2], sunk + 1.5)


def test_every_camera_stands_on_a_floor_not_on_furniture(house, house_disc):
    """Straight below each camera, at its eye height, is its own floor (not a table, bed or
    sofa top): height 1.5 m above the first surface below."""
    d = house_disc
    V, F = house.geometry()
    rc = RayCaster(V, F)
    o = np.column_stack([d.locations, d.location_z])
    t, _ = rc.first_hits(o, np.tile([0.0, 0.0, -1.0], (len(o), 1)), 3.0)
    assert np.allclose(t, 1.5, atol=0.01)
    # and large furniture tops exist in the house (the test would catch a camera on them)
    tops = []
    for p in house.parts:
        v = np.asarray(p.vertices)
        if any(k in p.name for k in ("table", "bed", "island", "desk", "sofa")):
            tops.append(v[:, 2].max() - v[:, 2].min())
    assert len(tops) >= 4


def test_narrow_doorway_room_is_reached(house, house_disc):
    d = house_disc
    room = next(r for r in house.rooms if r.name == house.meta["narrow_door_room"])
    assert house.meta["narrow_door"]["width"] == pytest.approx(0.7)
    on = (d.location_storey == 1) & _in(d.locations, room.bounds, 0.3)
    assert on.sum() >= 8


def test_no_candidate_on_glass_and_the_rule_is_counted(house, house_disc):
    d = house_disc
    g = house.meta["glass_wall"]
    assert g["orient"] == "v"
    p = d.candidate_position
    on_glass = (np.abs(p[:, 0] - g["line"]) < 0.2) & (p[:, 1] > g["span"][0] - 0.1) & (p[:, 1] < g["span"][1] + 0.1) \
        & (d.candidate_storey == 0)
    assert not on_glass.any()
    assert d.summary["candidates_removed"]["glass"] >= 1
    assert d.summary["candidates_removed"]["does not fit"] >= 1
    # ... while cameras see through it: free space on both sides
    for side in (-1, 1):
        near = (d.location_storey == 0) & (np.abs(d.locations[:, 0] - (g["line"] + side * 1.0)) < 0.3)
        assert near.sum() >= 3


def test_free_space_stays_inside_the_house(house, house_disc):
    d = house_disc
    assert np.all(_in(d.locations, (0, 0, 10.5, 7.5), 0.05))
    assert np.all(_in(d.candidate_position[:, :2], (0, 0, 10.5, 7.5), -0.01))


def _room_scene(parts, name="hand_built"):
    return Scene(name, tuple(parts))


def _holed_two_rooms(hole_width: float, z0: float = 0.0, ground: bool = False, ceiling: bool = True):
    """``two_rooms`` with a hole (scan dropout) hole_width wide and 0.6-2.2 m high in the outer
    east wall at x = 9, optionally a large ground plane around and no ceiling."""
    parts = [p for p in two_rooms(z0) if p.name not in ("wall3",) and (ceiling or p.name != "ceiling")]
    y0, y1 = 2.0 - hole_width / 2, 2.0 + hole_width / 2
    parts += [box("wall3a", (9 - T / 2, -T / 2, z0), (9 + T / 2, y0, z0 + H)),
              box("wall3b", (9 - T / 2, y1, z0), (9 + T / 2, 4 + T / 2, z0 + H)),
              box("wall3low", (9 - T / 2, y0, z0), (9 + T / 2, y1, z0 + 0.6)),
              box("wall3high", (9 - T / 2, y0, z0 + 2.2), (9 + T / 2, y1, z0 + H))]
    if ground:
        parts.append(quad("ground", [[-20, -20, z0 - 0.05], [30, -20, z0 - 0.05], [30, 25, z0 - 0.05], [-20, 25, z0 - 0.05]]))
    return _room_scene(parts)


@pytest.mark.parametrize("ground", [False, True])
def test_hole_in_an_outer_wall_does_not_leak_outside(ground):
    d = discretize(_holed_two_rooms(1.2, ground=ground), DiscretizeConfig())
    assert np.all(_in(d.locations, (0, 0, 9, 4)))
    assert len(d.locations) > 50
    occ = d.occupancy[0]
    r = int((2.0 - d.grid_origin[1]) / d.grid_resolution)
    c = int((11.0 - d.grid_origin[0]) / d.grid_resolution)
    if c < occ.shape[1]:
        assert occ[r, c] != 0  # outside, beyond the hole: not free


def test_gap_narrower_than_a_person_does_not_connect_rooms():
    """Room b reached only through a 0.25 m slit (a scan hole) is not free space, and the log's
    region list names it; through a real 0.8 m doorway it is."""
    def scene(door: float):
        parts = [p for p in two_rooms() if p.name not in ("wall4", "wall5", "lintel")]
        y0 = 2.0 - door / 2
        parts += [box("w4", (5 - T / 2, 0, 0), (5 + T / 2, y0, H)), box("w5", (5 - T / 2, y0 + door, 0), (5 + T / 2, 4, H))]
        return _room_scene(parts)

    slit = discretize(scene(0.25), DiscretizeConfig(start=(2.5, 3.0)))
    assert np.all(slit.locations[:, 0] < 5) and len(slit.locations) > 20
    unreached = slit.summary["per_storey"][0]["unreached"]
    assert any(u["area_m2"] > 10 and u["centre"][0] > 5 for u in unreached)
    door = discretize(scene(0.8), DiscretizeConfig(start=(2.5, 3.0)))
    assert (door.locations[:, 0] > 5).sum() > 20


def test_without_start_every_large_region_is_planned():
    """Two disjoint buildings: both get camera locations (never one silently)."""
    parts = two_rooms() + [MeshPart("far/" + p.name, np.asarray(p.vertices) + np.float32([30, 0, 0]), p.faces)
                           for p in two_rooms()]
    d = discretize(_room_scene(parts), DiscretizeConfig())
    assert (d.locations[:, 0] < 10).sum() > 50 and (d.locations[:, 0] > 30).sum() > 50


def test_flipped_normals_read_the_same():
    parts = two_rooms()
    flipped = [replace(p, faces=np.ascontiguousarray(np.asarray(p.faces)[:, ::-1])) for p in parts]
    a = discretize(_room_scene(parts), DiscretizeConfig())
    b = discretize(_room_scene(flipped), DiscretizeConfig())
    assert b.summary["normals"] == "flipped"
    assert np.array_equal(a.locations, b.locations)


def test_platform_and_step_heights():
    """A 0.2 m low step-down area belongs to the floor (cameras 1.5 m above it); a 0.45 m bed
    top in the same room does not."""
    z0 = 0.0
    parts = [quad("floor_a", [[0, 0, z0], [6, 0, z0], [6, 5, z0], [0, 5, z0]]),
             quad("floor_b", [[6, 0, z0 - 0.2], [10, 0, z0 - 0.2], [10, 5, z0 - 0.2], [6, 5, z0 - 0.2]]),
             box("step", (5.99, 0, z0 - 0.2), (6.0, 5, z0)),
             quad("ceiling", [[0, 0, H], [0, 5, H], [10, 5, H], [10, 0, H]]),
             box("bed", (1.0, 1.0, z0), (3.0, 2.6, z0 + 0.45))]
    for i, (x0, y0, x1, y1) in enumerate([(-T, -T, 10 + T, 0), (-T, 5, 10 + T, 5 + T), (-T, 0, 0, 5), (10, 0, 10 + T, 5)]):
        parts.append(box(f"wall{i}", (x0, y0, z0 - 0.2), (x1, y1, H)))
    d = discretize(_room_scene(parts), DiscretizeConfig())
    low = d.locations[:, 0] > 6.0
    assert low.sum() > 20 and np.allclose(d.location_z[low], 1.3)
    assert np.allclose(d.location_z[~low], 1.5)
    on_bed = _in(d.locations, (1.0, 1.0, 3.0, 2.6))
    assert not on_bed.any()
    assert list(d.storeys) == pytest.approx([0.0])


def _porch_house(depth: float = 1.5):
    """``two_rooms`` on a large ground plane, its roof running ``depth`` metres past the south
    wall (y = 0) over a porch: floor below and a ceiling above, but outdoors."""
    parts = [p for p in two_rooms() if p.name != "ceiling"]
    parts.append(quad("roof", [[-0.5, -depth, H], [-0.5, 4.5, H], [9.5, 4.5, H], [9.5, -depth, H]]))
    parts.append(quad("ground", [[-20, -20, -0.02], [30, -20, -0.02], [30, 25, -0.02], [-20, 25, -0.02]]))
    return _room_scene(parts)


def test_covered_porch_outside_the_walls_gets_no_camera_nor_tag(caplog):
    """The strip under the eaves has floor and ceiling like a room, but half its eye-level
    views leave the model: outdoors, left out and logged; ``start`` inside it keeps it."""
    with caplog.at_level("INFO", logger="markerplace.plan.discretize.stage"):
        d = discretize(_porch_house(), DiscretizeConfig())
    assert np.all(d.locations[:, 1] > 0) and len(d.locations) > 50
    assert np.all(d.candidate_position[:, 1] > 0)  # no tag on the outside of the south wall
    assert any("is outdoors" in r.getMessage() for r in caplog.records)
    kept = discretize(_porch_house(), DiscretizeConfig(start=(4.5, -0.8)))
    assert (kept.locations[:, 1] < 0).sum() > 5
    everything = discretize(_porch_house(), DiscretizeConfig(max_open_fraction=1.0))
    assert (everything.locations[:, 1] < 0).sum() > 5 and (everything.locations[:, 1] > 0).sum() > 50


def test_room_with_wide_glassless_windows_stays_planned():
    """A scan drops glass: 1.2 m holes (0.6-2.2 m high) in both long walls of room a let a few
    eye-level views out, far fewer than a porch; the room keeps its cameras."""
    parts = [p for p in two_rooms() if p.name not in ("wall0", "wall1")]
    for i, y in enumerate((0.0, 4.0)):
        for x0, x1 in ((0.0, 0.8), (2.0, 2.8), (4.0, 9.0 + T / 2)):  # solid between and after the windows
            parts.append(box(f"w{i}_{x0}", (x0 - T / 2, y - T / 2, 0), (x1, y + T / 2, H)))
        for x0, x1 in ((0.8, 2.0), (2.8, 4.0)):
            parts += [box(f"sill{i}_{x0}", (x0, y - T / 2, 0), (x1, y + T / 2, 0.6)),
                      box(f"head{i}_{x0}", (x0, y - T / 2, 2.2), (x1, y + T / 2, H))]
    d = discretize(_room_scene(parts), DiscretizeConfig())
    room_a = _in(d.locations, (0, 0, 5, 4))
    assert room_a.sum() > 20 and (~room_a).sum() > 20
