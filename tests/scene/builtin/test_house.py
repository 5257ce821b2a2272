"""Built-in ``house``: two storeys at the meta heights, a solid stair under a slab opening, a sunken
living room open to the kitchen over one step, a 0.7 m doorway as the only way into the bathroom,
glass parts that are transparent, survive a glTF round trip and render see-through."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.geometry import world_from_cam_pose
from markerplace.scene import load_scene
from markerplace.scene.builtin.catalogue import list_scenes
from markerplace.scene.export import export_glb
from markerplace.scene.raycast import RayCaster

DOWN, UP = np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0])


@pytest.fixture(scope="module")
def caster(house):
    return RayCaster(*house.geometry())


def _cast(caster, origins, direction, max_t=np.inf):
    """First-hit distances (inf: no hit) of rays from (M, 3) origins along one direction."""
    origins = np.atleast_2d(np.asarray(origins, dtype=float))
    t, _ = caster.first_hits(origins, np.broadcast_to(direction, origins.shape), max_t)
    return t


def _in_holes(xy, holes) -> np.ndarray:
    return np.any([(xy[:, 0] > h[0]) & (xy[:, 0] < h[2]) & (xy[:, 1] > h[1]) & (xy[:, 1] < h[3]) for h in holes], axis=0)


def test_catalogue_row(house):
    row = next(r for r in list_scenes() if r["name"] == "house")
    assert 120 <= row["area_m2"] <= 170 and row["rooms"] == len(house.rooms) >= 8
    assert sum(r.area for r in house.rooms) == pytest.approx(row["area_m2"])


def test_two_storeys_with_floors_at_the_meta_heights(house, caster):
    storeys = house.meta["storeys"]
    assert storeys == sorted(storeys) and len(storeys) == 2 and house.floor_z == storeys[0] == 0.0
    assert 2.8 <= storeys[1] - storeys[0] <= 3.2
    holes = house.meta["slab_openings"]
    per_storey = {z: 0 for z in storeys}
    for room in house.rooms:
        storey = max(z for z in storeys if z <= room.floor_z + 0.5)
        per_storey[storey] += 1
        x0, y0, x1, y1 = room.bounds
        gx, gy = np.meshgrid(np.arange(x0 + 0.25, x1 - 0.2, 0.3), np.arange(y0 + 0.25, y1 - 0.2, 0.3))
        xy = np.column_stack([gx.ravel(), gy.ravel()])
        xy = xy[~_in_holes(xy, holes)]
        start = storey + 2.5  # under the ceiling and its lights
        hit_z = start - _cast(caster, np.column_stack([xy, np.full(len(xy), start)]), DOWN)
        assert np.all(np.isfinite(hit_z)), room.name  # no hole in any floor
        assert hit_z.min() > room.floor_z - 1e-3, room.name  # nothing below the room's floor
        on_floor = np.abs(hit_z - room.floor_z) < 1e-3
        assert on_floor.mean() > 0.5, (room.name, on_floor.mean())  # mostly bare floor, the rest furniture
    assert min(per_storey.values()) >= 4  # several rooms per storey
    # the slab: the ground ceiling at 2.7 below the upper floor at 3.0 over every ground room,
    # nothing in between (on a vertical line up through the room's centre)
    ceiling = storeys[1] - house.meta["slab_thickness"]
    for room in house.rooms:
        if room.floor_z > 1.0 or room.name == "stairs":
            continue
        c = np.array([[(room.bounds[0] + room.bounds[2]) / 2 + 0.15, (room.bounds[1] + room.bounds[3]) / 2 + 0.4, 1.0]])
        _, t, _ = caster.all_hits(c, UP[None], max_t=3.5)
        z = 1.0 + t
        assert np.abs(z - ceiling).min() < 1e-3 and np.abs(z - storeys[1]).min() < 1e-3, room.name
        assert not np.any((z > ceiling + 1e-3) & (z < storeys[1] - 1e-3)), room.name


def test_stair_is_solid_under_a_slab_opening_with_walls_beside_it(house, caster):
    st = house.meta["stair"]
    x0, x1 = st["x"]
    y0, y1 = st["y"]
    assert st["risers"] * st["rise"] == pytest.approx(st["top_z"] - st["bottom_z"])
    assert 0.15 <= st["rise"] <= 0.21 and 0.22 <= st["going"] <= 0.32
    yc = (y0 + y1) / 2
    # looking down from the upper storey through the opening: every tread, climbing towards -x
    xs = x1 - (np.arange(1, st["risers"]) - 0.5) * st["going"]
    tread = 5.5 - _cast(caster, np.column_stack([xs, np.full_like(xs, yc), np.full_like(xs, 5.5)]), DOWN)
    np.testing.assert_allclose(tread, st["bottom_z"] + st["rise"] * np.arange(1, st["risers"]), atol=1e-3)
    # solid: a horizontal ray just above the floor under the stair meets the first riser
    assert _cast(caster, [[x1 + 0.5, yc, 0.1]], np.array([-1.0, 0, 0]))[0] == pytest.approx(0.5, abs=1e-3)
    # the upper floor next to the opening is there; the opening is where the stair is
    assert 5.5 - _cast(caster, [[x0 - 0.3, yc, 5.5]], DOWN)[0] == pytest.approx(st["top_z"], abs=1e-3)
    # a wall (ground) and a balustrade (upper floor) beside the stair, seen from the hall/landing
    for z in (1.0, 3.5):
        d = _cast(caster, [[(x0 + x1) / 2, y0 - 1.0, z]], np.array([0, 1.0, 0]))[0]
        assert d == pytest.approx(1.0 - 0.1, abs=1e-3)  # 0.1 m thick, flush with the opening
    assert _cast(caster, [[(x0 + x1) / 2, y0 - 1.0, 4.3]], np.array([0, 1.0, 0]))[0] > 1.5  # 1 m balustrade
    # the stair's foot is reachable from the hall: an opening in the wall beside the stair
    assert _cast(caster, [[x1 + 0.5, y0 - 1.0, 1.0]], np.array([0, 1.0, 0]))[0] > y1 - y0 + 0.9


def test_sunken_living_room_one_step_down_without_a_wall(house, caster):
    rooms = {r.name: r for r in house.rooms}
    living = rooms[house.meta["sunken_room"]]
    assert living.floor_z == pytest.approx(house.floor_z - 0.25) == house.meta["sunken_floor_z"]
    op = house.meta["sunken_opening"]
    assert op["orient"] == "h" and op["span"][1] - op["span"][0] >= 2.0
    (other,) = set(op["rooms"]) - {living.name}
    assert rooms[other].floor_z == house.floor_z
    y = op["line"]
    xs = np.linspace(op["span"][0] + 0.05, op["span"][1] - 0.05, 25)
    inside = 1.0 if rooms[other].bounds[1] >= y else -1.0  # +1: the other room lies at larger y
    # open at every height from just above the upper floor to the ceiling: nothing on the line
    for z in (0.05, 1.0, 2.0, 2.6):
        o = np.column_stack([xs, np.full_like(xs, y + 0.3 * inside), np.full_like(xs, z)])
        assert np.all(_cast(caster, o, np.array([0, -inside, 0]), max_t=0.6) == np.inf), z
    # one step: a riser from the sunken floor to the upper floor, flush with the wall face
    o = np.column_stack([xs, np.full_like(xs, y - 0.5 * inside), np.full_like(xs, -0.15)])
    np.testing.assert_allclose(_cast(caster, o, np.array([0, inside, 0])), 0.45, atol=1e-3)
    for side, z in ((-0.1, living.floor_z), (0.1, house.floor_z)):
        o = np.column_stack([xs, np.full_like(xs, y + side * inside), np.full_like(xs, 1.0)])
        np.testing.assert_allclose(1.0 - _cast(caster, o, DOWN), z, atol=1e-3)


def test_narrow_doorway_is_the_only_way_into_its_room(house, caster):
    rooms = {r.name: r for r in house.rooms}
    room = rooms[house.meta["narrow_door_room"]]
    door = house.meta["narrow_door"]
    assert door["width"] == pytest.approx(0.7) and door["span"][1] - door["span"][0] == pytest.approx(0.7)
    x0, y0, x1, y1 = room.bounds
    z = room.floor_z + 1.0
    step = 0.005
    free = {}
    for wall, (a, b, make, direction) in {
        "S": (x0, x1, lambda s: (s, y0 + 0.3), (0, -1.0, 0)),
        "N": (x0, x1, lambda s: (s, y1 - 0.3), (0, 1.0, 0)),
        "W": (y0, y1, lambda s: (x0 + 0.3, s), (-1.0, 0, 0)),
        "E": (y0, y1, lambda s: (x1 - 0.3, s), (1.0, 0, 0)),
    }.items():
        s = np.arange(a + 0.06, b - 0.06, step)
        o = np.array([[*make(v), z] for v in s])
        free[wall] = s[_cast(caster, o, np.array(direction), max_t=0.5) == np.inf]
    open_walls = {w: f for w, f in free.items() if len(f)}
    assert list(open_walls) == [{"h": "N" if door["line"] == y1 else "S", "v": "E" if door["line"] == x1 else "W"}[door["orient"]]]
    (gap,) = open_walls.values()
    assert np.all(np.diff(gap) < 1.5 * step)  # one opening
    assert gap[-1] - gap[0] + step == pytest.approx(0.7, abs=0.015)


def test_glass_parts_are_transparent_and_bound_the_rooms(house, caster):
    names = set(house.meta["glass_parts"])
    assert names and names == {p.name for p in house.parts if p.transparent}
    flags = house.face_transparent()
    assert flags.sum() == sum(len(p.faces) for p in house.parts if p.name in names)
    g = house.meta["glass_wall"]
    assert g["parts"] and set(g["parts"]) < names  # the windows and the glass door are glass too
    glass_v = np.concatenate([p.vertices for p in house.parts if p.name in g["parts"]]).astype(float)
    axis = 0 if g["orient"] == "v" else 1
    np.testing.assert_allclose(glass_v[:, axis], g["line"], atol=1e-5)
    assert glass_v[:, 1 - axis].min() >= g["span"][0] - 1e-5 and glass_v[:, 1 - axis].max() <= g["span"][1] + 1e-5
    assert glass_v[:, 2].max() - glass_v[:, 2].min() > 2.0  # floor-to-ceiling glazing
    # from the living room, a ray towards the glass meets a transparent face first
    mids = [(a + b) / 2 for a, b in zip(np.linspace(*g["span"], 5)[:-1], np.linspace(*g["span"], 5)[1:])]
    towards = np.eye(3)[axis]
    o = np.array([towards * (g["line"] - 1.0) + np.eye(3)[1 - axis] * m + [0, 0, 1.3] for m in mids])
    t, face = caster.first_hits(o, np.broadcast_to(towards, o.shape))
    np.testing.assert_allclose(t, 1.0, atol=1e-3)
    assert flags[face].all()


def test_glass_survives_gltf_export_and_load(house, tmp_path):
    path = tmp_path / "house.glb"
    export_glb(house, path)
    back = load_scene(str(path))
    by_name = {p.name: p for p in back.parts}
    for p in house.parts:
        q = by_name[p.name]
        assert q.transparent == p.transparent, p.name
        if p.transparent:
            assert q.base_color[3] == pytest.approx(p.base_color[3], abs=0.5 / 255) and q.base_color[3] < 0.5
    assert back.face_transparent().sum() == house.face_transparent().sum() > 0
    np.testing.assert_allclose(back.bounds, house.bounds, atol=1e-4)


def test_render_through_the_glass_wall_shows_the_room_behind(house):
    from markerplace.render.renderer import Renderer

    g = house.meta["glass_wall"]
    panes = np.linspace(*g["span"], 5)
    y = (panes[1] + panes[2]) / 2  # middle of the second pane, between mullions
    pose = world_from_cam_pose(np.array([g["line"] - 3.0, y, 1.3]), 0.0)  # 3 m from the glass, facing it
    opaque = type(house)(house.name, tuple(
        type(p)(p.name, p.vertices, p.faces, p.uv, p.colors, p.texture, p.base_color, p.normals, False) for p in house.parts))
    with Renderer(house) as r:
        seen = r.render(pose)
    with Renderer(opaque) as r:
        blocked = r.render(pose)
    centre = seen.depth[200:250, 280:320]
    assert np.all(centre > 3.3)  # depth (and normals) of the sunroom behind the glass
    np.testing.assert_allclose(blocked.depth[200:250, 280:320], 3.0, atol=1e-3)  # opaque glass: the pane
    # the colour is the room behind, tinted: it differs from the opaque pane and has texture
    assert np.abs(seen.rgb[200:250, 280:320].astype(int) - blocked.rgb[200:250, 280:320]).mean() > 10
    assert seen.rgb[150:300, 200:400].std() > 10


def test_procedural_step_towards_a_sunken_room_on_either_side_and_floor_holes():
    """The building blocks the house uses: a step on the lower room's side (here +x), walls down
    to the lower floor, no lintel over a full-height opening, and a floor hole."""
    from markerplace.scene.builtin.layout import Door, Layout, RoomSpec
    from markerplace.scene.builtin.procedural import build_scene, subtract_rects

    hole = (0.5, 0.5, 1.5, 2.0)
    layout = Layout(
        "steps", "test",
        (RoomSpec("high", (0.0, 0.0, 3.0, 3.0), lights=0, floor_holes=(hole,)),
         RoomSpec("low", (3.0, 0.0, 6.0, 3.0), lights=0, floor_dz=-0.25)),
        doors=(Door("high", "low", width=2.0, height=5.0),),
        floor_z=1.0,
    )
    scene = build_scene(layout)
    assert [r.floor_z for r in scene.rooms] == [1.0, 0.75] and scene.floor_z == 1.0
    caster = RayCaster(*scene.geometry())
    west = np.array([-1.0, 0, 0])
    # riser flush with the low room's wall face (x = 3.05), in the opening and beside it (wall)
    for y in (1.5, 0.3, 2.7):
        assert _cast(caster, [[4.0, y, 0.85]], west)[0] == pytest.approx(0.95, abs=1e-3), y
    # above the step: open in the opening at every height (no lintel), wall beside it
    for z in (1.1, 2.5, 3.6):
        assert _cast(caster, [[4.0, 1.5, z]], west)[0] > 3.5, z
        assert _cast(caster, [[4.0, 0.3, z]], west)[0] == pytest.approx(0.95, abs=1e-3), z
    # the step's top continues the high floor to the riser; the hole goes through the floor
    assert 2.0 - _cast(caster, [[3.03, 1.5, 2.0]], DOWN)[0] == pytest.approx(1.0, abs=1e-3)
    assert _cast(caster, [[1.0, 1.0, 2.0]], DOWN)[0] == np.inf
    assert 2.0 - _cast(caster, [[1.0, 2.5, 2.0]], DOWN)[0] == pytest.approx(1.0, abs=1e-3)
    pieces = subtract_rects((0.0, 0.0, 3.0, 3.0), [hole])
    assert sum((p[2] - p[0]) * (p[3] - p[1]) for p in pieces) == pytest.approx(9.0 - 1.5)
