"""Built-in ``corridor`` (a hotel floor that is hard to localize in): ten guest rooms
identical up to a translation, over 200 m^2 at the default size, every room reachable from the
corridor through a doorway, a room count that sizes it, builds that are deterministic in the seed
and cheap; ``corridor-small`` (the demo's scene) is the same floor with four rooms."""

from __future__ import annotations

import hashlib
import time

import numpy as np
import pytest

from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
from markerplace.scene import load_scene
from markerplace.scene.builtin.catalogue import get_layout, list_scenes
from markerplace.scene.builtin.corridor import CELL, MIN_ROOMS, ROOM_DEPTH, ROOMS, SMALL_NAME, SMALL_ROOMS, build_corridor, corridor_plan, room_name
from markerplace.scene.builtin.walls import door_span

CORRIDOR_XY = (5.0, ROOM_DEPTH + 0.9)  # a point in the corridor


@pytest.fixture(scope="module")
def scene():
    return load_scene("corridor")


def _digest(scene) -> str:
    """Hash of every array of the scene's parts, and their names."""
    h = hashlib.sha256()
    for p in scene.parts:
        h.update(p.name.encode())
        for a in (p.vertices, p.faces, p.uv, p.texture, p.normals):
            if a is not None:
                h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def _inside(v: np.ndarray, b, m: float = 0.055) -> np.ndarray:
    """Vertices strictly inside room bounds ``b`` less ``m`` (the walls' half thickness and a bit)."""
    return (v[:, 0] > b[0] + m) & (v[:, 0] < b[2] - m) & (v[:, 1] > b[1] + m) & (v[:, 1] < b[3] - m)


def test_catalogue_row_default_size_and_description(scene):
    row = next(r for r in list_scenes() if r["name"] == "corridor")
    assert row["area_m2"] >= 200.0
    assert sum(r.area for r in scene.rooms) == pytest.approx(row["area_m2"])
    assert row["rooms"] == len(scene.rooms) == ROOMS + 2  # guest rooms, the corridor, the lobby
    assert f"{ROOMS} identical guest rooms" in row["description"]
    assert scene.meta["guest_rooms"] == [room_name(i) for i in range(ROOMS)]


def test_guest_rooms_are_identical_up_to_a_translation(scene):
    rooms = {r.name: r for r in scene.rooms}
    first = rooms[room_name(0)].bounds
    assert len(scene.meta["twins"]) == ROOMS - 1 >= MIN_ROOMS - 1
    compared = 0
    for a, b in scene.meta["twins"]:
        ra, rb = rooms[a].bounds, rooms[b].bounds
        assert a == room_name(0)
        np.testing.assert_allclose(np.subtract(rb, ra), [rb[0] - ra[0], 0.0, rb[0] - ra[0], 0.0], atol=1e-9)
        offset = np.array([rb[0] - ra[0], 0.0, 0.0])
        for p in scene.parts:
            v = p.vertices.astype(float)
            va, vb = v[_inside(v, ra)] + offset, v[_inside(v, rb)]
            assert len(va) == len(vb), (b, p.name)
            if len(va):
                np.testing.assert_allclose(va[np.lexsort(va.T)], vb[np.lexsort(vb.T)], atol=1e-4)
        compared += 1
    assert compared >= MIN_ROOMS - 1
    # furniture, the print, the light: the same parts (so the same textures) in every room
    kinds = {p.name.split("/")[-1].split(":")[0] for p in scene.parts if _inside(p.vertices.astype(float), first).any()}
    assert len(kinds) >= 5, kinds


def test_doorways_connect_every_room_alike():
    plan = get_layout("corridor")
    spans = {}
    for d in plan.doors:
        if d.b == "corridor" and d.a.startswith("room_"):
            x0 = next(r for r in plan.rooms if r.name == d.a).bounds[0]
            orient, line, g0, g1 = door_span(plan, d)
            spans[d.a] = (orient, line, round(g0 - x0, 6), round(g1 - x0, 6))
    assert sorted(spans) == [room_name(i) for i in range(ROOMS)]
    assert len(set(spans.values())) == 1  # the same doorway, room-locally, in every room
    orient, line, g0, g1 = next(iter(spans.values()))
    assert orient == "h" and line == pytest.approx(ROOM_DEPTH) and g1 - g0 >= 0.85
    assert any({d.a, d.b} == {"lobby", "corridor"} for d in plan.doors)


def test_camera_grid_reaches_every_room_from_the_corridor(scene):
    # only the free region holding the corridor point is kept: a room with cameras is reachable
    disc = discretize(scene, DiscretizeConfig(grid_spacing=1.0, start=CORRIDOR_XY))
    for room in scene.rooms:
        x0, y0, x1, y1 = room.bounds
        inside = ((disc.locations[:, 0] > x0) & (disc.locations[:, 0] < x1)
                  & (disc.locations[:, 1] > y0) & (disc.locations[:, 1] < y1))
        assert inside.sum() >= 3, room.name
    assert len(disc.candidate_position) > 50


def test_seed_changes_the_scene_and_the_same_seed_repeats_it(scene):
    a, b, c = build_corridor(0), build_corridor(0), build_corridor(1)
    assert _digest(a) == _digest(b) == _digest(scene)
    assert _digest(c) != _digest(a)
    assert [r.bounds for r in c.rooms] == [r.bounds for r in a.rooms]  # the seed never moves walls


def test_room_count_sizes_the_floor():
    small, large = corridor_plan(MIN_ROOMS), corridor_plan(14)
    guests = lambda p: [r for r in p.rooms if r.name.startswith("room_")]  # noqa: E731
    assert len(guests(small)) == MIN_ROOMS and len(guests(large)) == 14
    assert large.floor_area - small.floor_area == pytest.approx((14 - MIN_ROOMS) * CELL * (ROOM_DEPTH + 1.8))
    built = build_corridor(0, rooms=12)
    assert len(built.meta["guest_rooms"]) == 12 and len(built.meta["twins"]) == 11
    for bad in (MIN_ROOMS - 1, 0, 9.5, True):
        with pytest.raises(UserError, match="guest rooms"):
            corridor_plan(bad)


def test_build_is_fast():
    t0 = time.perf_counter()
    build_corridor(3)
    assert time.perf_counter() - t0 < 5.0


def test_lobby_carries_the_texture_the_rest_lacks():
    plan = get_layout("corridor")
    rooms = {r.name: r for r in plan.rooms}
    assert not rooms["corridor"].pictures and not rooms["corridor"].items
    assert len(rooms["lobby"].pictures) >= 4 and len(rooms["lobby"].items) >= 8
    assert all(len(rooms[room_name(i)].pictures) <= 1 for i in range(ROOMS))


def test_cli_scene_export(tmp_path):
    out = tmp_path / "corridor.glb"
    assert main(["scene", "export", "corridor", str(out)]) == 0
    back = load_scene(str(out))
    np.testing.assert_allclose(back.bounds, load_scene("corridor").bounds, atol=1e-4)


def test_corridor_small_is_the_floor_with_fewer_rooms():
    small = load_scene(SMALL_NAME)
    assert (small.name, small.source) == (SMALL_NAME, f"builtin:{SMALL_NAME}")
    assert small.meta["guest_rooms"] == [room_name(i) for i in range(SMALL_ROOMS)] and SMALL_ROOMS < ROOMS
    assert len(small.meta["twins"]) == SMALL_ROOMS - 1
    row = next(r for r in list_scenes() if r["name"] == SMALL_NAME)
    assert row["rooms"] == SMALL_ROOMS + 2 and f"{SMALL_ROOMS} identical guest rooms" in row["description"]
    assert row["area_m2"] == pytest.approx(corridor_plan(SMALL_ROOMS).floor_area)
    # the same geometry and textures as the hotel floor built with that many rooms, up to the names
    same = build_corridor(0, rooms=SMALL_ROOMS)
    assert [p.name.replace(SMALL_NAME, "corridor", 1) for p in small.parts] == [p.name for p in same.parts]
    assert _digest(small) != _digest(same)  # the names differ
    for p, q in zip(small.parts, same.parts):
        for a, b in ((p.vertices, q.vertices), (p.faces, q.faces), (p.texture, q.texture)):
            assert (a is None and b is None) or np.array_equal(a, b)
    assert [r.bounds for r in small.rooms] == [r.bounds for r in same.rooms]


def test_corridor_small_reaches_every_room_on_the_demo_grid():
    # the demo plans corridor-small on a 1 m camera grid (scripts/demo.sh): every room has cameras
    scene = load_scene(SMALL_NAME)
    disc = discretize(scene, DiscretizeConfig(grid_spacing=1.0, start=CORRIDOR_XY))
    for room in scene.rooms:
        x0, y0, x1, y1 = room.bounds
        inside = ((disc.locations[:, 0] > x0) & (disc.locations[:, 0] < x1)
                  & (disc.locations[:, 1] > y0) & (disc.locations[:, 1] < y1))
        assert inside.sum() >= 3, room.name
