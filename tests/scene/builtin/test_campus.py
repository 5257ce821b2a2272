"""Built-in ``campus`` (the scale-test building): over 2,000 m^2 on two storeys that the
discretization finds, every room reachable from the corridor on its storey, repeated rooms that
are identical up to a translation, a stair that joins the storeys under a slab opening, a face
count that keeps rendering cheap, and builds that are deterministic in the seed."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.cli.main import main
from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
from markerplace.scene import load_scene
from markerplace.scene.builtin.campus import HOLE, build_campus, campus_plan
from markerplace.scene.builtin.catalogue import get_layout, list_scenes
from markerplace.scene.raycast import RayCaster

CORRIDOR_XY = (24.0, 6.5)  # the corridor's middle, on both storeys


@pytest.fixture(scope="module")
def campus():
    return load_scene("campus")


@pytest.fixture(scope="module")
def disc(campus):
    # only the free region holding the corridor point is kept (on each storey): a room with
    # cameras is reachable from the corridor. A 1 m lattice keeps the test fast.
    return discretize(campus, DiscretizeConfig(grid_spacing=1.0, start=CORRIDOR_XY))


def _storey_index(storeys, z: float) -> int:
    return int(np.argmin(np.abs(np.asarray(storeys) - z)))


def test_catalogue_row_and_scene_list(campus, capsys):
    row = next(r for r in list_scenes() if r["name"] == "campus")
    assert row["area_m2"] >= 2000.0
    assert row["rooms"] == len(campus.rooms) == len(get_layout("campus").rooms) >= 40
    assert sum(r.area for r in campus.rooms) == pytest.approx(row["area_m2"])
    assert main(["scene", "list"]) == 0
    assert "campus" in capsys.readouterr().out


def test_two_storeys_each_over_1000_m2(campus):
    plan = campus_plan()
    assert [s.floor_z for s in plan.storeys] == campus.meta["storeys"] == [0.0, 3.0]
    for storey in plan.storeys:
        assert storey.floor_area >= 1000.0
    np.testing.assert_allclose(campus.bounds[:, 2], [0.0, 3.0 + campus.meta["ceiling_height"]], atol=1e-6)


def test_discretization_finds_both_storeys_and_cameras_in_every_room(campus, disc):
    np.testing.assert_allclose(disc.storeys, campus.meta["storeys"], atol=0.05)
    empty = []
    for room in campus.rooms:
        x0, y0, x1, y1 = room.bounds
        s = _storey_index(disc.storeys, room.floor_z)
        inside = ((disc.location_storey == s) & (disc.locations[:, 0] > x0) & (disc.locations[:, 0] < x1)
                  & (disc.locations[:, 1] > y0) & (disc.locations[:, 1] < y1))
        if not inside.any():
            empty.append(room.name)
    assert not empty, f"rooms without a camera location reachable from the corridor: {empty}"
    for info in disc.summary["per_storey"]:
        assert info["locations"] > 500 and info["candidates"] > 100, info
        assert info["unreached"] == [], info  # nothing on either storey is cut off from the corridor
    # eye level above each storey's own floor
    np.testing.assert_allclose(disc.location_z, np.asarray(disc.storeys)[disc.location_storey] + 1.5, atol=1e-6)


def test_repeated_rooms_are_identical_up_to_a_translation(campus):
    rooms = {r.name: r for r in campus.rooms}
    twins = campus.meta["twins"]
    templates = campus.meta["templates"]
    assert sum(t == "office" for t in templates.values()) >= 20
    assert len(twins) >= 20
    # twins across storeys and within one storey, offices and open-plan areas among them
    assert any(a.split("_")[0] != b.split("_")[0] for a, b in twins)
    assert {"office", "open_plan", "meeting"} <= {templates[a] for a, _ in twins}

    def inside(v, room, m=0.055):
        x0, y0, x1, y1 = room.bounds
        top = max(z for z in campus.meta["storeys"] if z <= room.floor_z + 0.5) + campus.meta["ceiling_height"]
        return ((v[:, 0] > x0 + m) & (v[:, 0] < x1 - m) & (v[:, 1] > y0 + m) & (v[:, 1] < y1 - m)
                & (v[:, 2] > room.floor_z - 1e-3) & (v[:, 2] < top - 1e-3))

    for a, b in twins:
        ra, rb = rooms[a], rooms[b]
        offset = np.array([rb.bounds[0] - ra.bounds[0], rb.bounds[1] - ra.bounds[1], rb.floor_z - ra.floor_z])
        shared = 0
        for p in campus.parts:
            v = p.vertices.astype(float)
            va, vb = v[inside(v, ra)] + offset, v[inside(v, rb)]
            assert len(va) == len(vb), (a, b, p.name)
            if len(va):
                shared += 1
                np.testing.assert_allclose(va[np.lexsort(va.T)], vb[np.lexsort(vb.T)], atol=1e-4, err_msg=f"{a} {b} {p.name}")
        assert shared >= 5, (a, b)


def test_stair_climbs_from_the_ground_floor_to_the_upper_floor_under_an_opening(campus):
    caster = RayCaster(*campus.geometry())
    st = campus.meta["stair"]
    x = 0.5 * (st["x"][0] + st["x"][1])
    # tread k (k = 1..14) lies between the foot riser and the top, one rise above the last
    ys = st["y"][1] - (np.arange(1, st["risers"]) - 0.5) * st["going"]
    origins = np.column_stack([np.full(len(ys), x), ys, np.full(len(ys), 2.95)])
    t, _ = caster.first_hits(origins, np.broadcast_to([0.0, 0.0, -1.0], origins.shape), 10.0)
    np.testing.assert_allclose(2.95 - t, np.arange(1, st["risers"]) * st["rise"], atol=1e-4)
    # above the flight nothing until the upper storey's ceiling: the slab and both floors are open
    up = np.column_stack([np.full(len(ys), x), ys, np.arange(1, st["risers"]) * st["rise"] + 0.05])
    t, _ = caster.first_hits(up, np.broadcast_to([0.0, 0.0, 1.0], up.shape), 10.0)
    np.testing.assert_allclose(up[:, 2] + t, st["top_z"] + campus.meta["ceiling_height"], atol=1e-4)
    assert campus.meta["slab_openings"] == [list(HOLE)]
    # beside the opening the slab is closed: ground ceiling at 2.7 under the upper floor at 3.0
    _, tt, _ = caster.all_hits(np.array([[HOLE[0] - 0.6, 0.5 * (HOLE[1] + HOLE[3]), 1.0]]), np.array([[0.0, 0.0, 1.0]]), max_t=3.0)
    z = np.sort(1.0 + tt)
    assert np.abs(z - 2.7).min() < 1e-3 and np.abs(z - 3.0).min() < 1e-3


def test_face_count_keeps_rendering_cheap(campus):
    # the renderer draws every part each frame: one part per (label, material) pair, under 20k faces
    assert campus.num_faces < 20000
    assert len(campus.parts) < 120


def test_builds_are_deterministic_in_the_seed(campus):
    a, b, c = build_campus(0), build_campus(0), build_campus(1)

    def arrays(s):
        return [x for p in s.parts for x in (p.vertices, p.faces, p.uv, p.texture, p.normals) if x is not None]

    assert [p.name for p in a.parts] == [p.name for p in b.parts] == [p.name for p in campus.parts]
    assert all(np.array_equal(x, y) for x, y in zip(arrays(a), arrays(b)))
    assert all(np.array_equal(x, y) for x, y in zip(arrays(a), arrays(campus)))
    assert a.meta == b.meta and a.meta["twins"] == c.meta["twins"]
    assert any(p.texture is not None and not np.array_equal(p.texture, q.texture) for p, q in zip(a.parts, c.parts))
