"""Tags only on structure that stays: the word list (scene/semantics.py), each candidate rule on a
hand-built room (a window by name, an unnamed door leaf in its opening by geometry, an unnamed
picture 2 cm off the wall, a bookcase front, a glass pane by transparency alone, a curtain by
name, a column), ``--allow`` restoring one category at a time, the log's arithmetic, and the
built-in ``house`` and ``apartment`` (windows, a glass door, an opaque door, pictures): no
candidate on any of them."""

from __future__ import annotations

import dataclasses
import logging
import re

import numpy as np
import pytest

from helpers import REPO
from markerplace.plan.discretize.candidate_rules import ALLOWABLE, CandidateConfig, surface_shape
from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster
from markerplace.scene.semantics import CATEGORIES, classify
from markerplace.scene.types import MeshPart, Scene

# ---------------------------------------------------------------- the word list


@pytest.mark.parametrize("names, category", [
    (["RoomWindow_3"], "windows"), (["Door_12"], "doors"), (["FoldingDoor_1"], "doors"), (["Curtain_2"], "curtains"),
    (["Fenster"], "windows"), (["window.001"], "windows"), (["IfcWindow_2345_0"], "windows"),
    (["IfcDoor_77_1"], "doors"), (["Mirror"], "mirrors"), (["TV"], "screens"), (["Picture"], "pictures"),
    (["Frame"], "pictures"), (["Bookcase"], "furniture"), (["Shelf"], "furniture"), (["Cabinet"], "furniture"),
    (["Wardrobe"], "furniture"), (["Haustür"], "doors"), (["Kleiderschrank"], "furniture"),
    (["Bücherregal"], "furniture"), (["boekenkast"], "furniture"), (["Vorhang_links"], "curtains"),
    (["porte-fenêtre"], "doors"), (["窗帘"], "curtains"), (["窗户"], "windows"), (["Book_Case"], "furniture"),
    (["IfcCurtainWall_9_0"], "windows"),  # a glass facade, not a curtain
    (["Window_3", "Frame"], "windows"),  # a window's frame child: the window wins
    (["DoorFrame"], "doors"), (["Door_1", "Glass"], "doors"), (["TVStand"], "screens"),
    (["Wall_North", "Material.003"], "structure"), (["IfcWallStandardCase_4_0"], "structure"),
    (["IfcColumn_8_0"], "structure"),
    (["outdoor_wall"], "structure"),  # English words match whole: no door in outdoor
    (["Struktur", "Textur"], ""),  # compound stems keep their accents: no Tür in Struktur
    (["Cube.012", "Material.005", "Plaster_Board"], ""),
])
def test_names_say_what_a_part_is(names, category):
    assert classify(names).category == category


def test_every_category_is_documented():
    doc = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    assert all(f"`{key}`" in doc for key in ALLOWABLE), "docs/cli.md must list every --allow category"


# ---------------------------------------------------------------- a hand-built room

T, H = 0.1, 2.7  # wall thickness, ceiling height
X1, Y1 = 6.0, 5.0  # inner faces: x in [0, 6], y in [0, 5]


def box(name, lo, hi, names=None, transparent=False) -> MeshPart:
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float32)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                  [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], np.int32)
    return MeshPart(name, v, f, transparent=transparent, names=(name,) if names is None else tuple(names))


# the objects: (what, centre of the face a tag would be on, its normal, half width, half height)
WINDOW = ("window by name, flush", (1.6, Y1, 1.5), (0, -1, 0), 0.6, 0.6)
CURTAIN = ("curtain by name", (4.1, Y1 - 0.15, 1.35), (0, -1, 0), 0.6, 1.3)
DOOR = ("unnamed door leaf set into its opening", (X1 + 0.03, 1.95, 1.05), (-1, 0, 0), 0.45, 1.05)
GLASS = ("glass pane, flush, unnamed", (2.6, 0.0, 1.5), (0, 1, 0), 0.6, 0.7)
PICTURE = ("unnamed picture 2 cm off the wall", (4.7, 0.02, 1.45), (0, 1, 0), 0.5, 0.45)
BOOKCASE = ("bookcase front", (0.35, 1.45, 1.0), (1, 0, 0), 0.45, 1.0)
COLUMN = ("unnamed column", (0.3, 3.35, 1.35), (1, 0, 0), 0.35, 1.35)


def rules_room(names: bool = True) -> Scene:
    """The room; ``names=False`` strips every name (only glass and geometry tell)."""
    wall = ["Wall"]
    parts = [
        box("floor", (-1, -1, -0.1), (X1 + 1, Y1 + 1, 0)), box("ceiling", (-1, -1, H), (X1 + 1, Y1 + 1, H + 0.1)),
        # north wall with a 1.2 x 1.2 m window, flush with it: only its name tells
        box("north_a", (-T, Y1, 0), (1.0, Y1 + T, H), wall), box("north_b", (2.2, Y1, 0), (X1 + T, Y1 + T, H), wall),
        box("north_sill", (1.0, Y1, 0), (2.2, Y1 + T, 0.9), wall), box("north_head", (1.0, Y1, 2.1), (2.2, Y1 + T, H), wall),
        box("RoomWindow_3", (1.0, Y1, 0.9), (2.2, Y1 + T, 2.1)),
        box("Curtain_2", (3.5, Y1 - 0.15, 0.05), (4.7, Y1 - 0.1, H - 0.05)),  # floor to ceiling, 10 cm off the wall
        # east wall with a 0.9 m door opening and an unnamed leaf 4 cm thick in the middle of the wall
        box("east_a", (X1, -T, 0), (X1 + T, 1.5, H), wall), box("east_b", (X1, 2.4, 0), (X1 + T, Y1 + T, H), wall),
        box("east_lintel", (X1, 1.5, 2.1), (X1 + T, 2.4, H), wall),
        box("Cube.007", (X1 + 0.03, 1.5, 0), (X1 + 0.07, 2.4, 2.1), ()),
        # south wall with a flush, unnamed glass pane (transparency alone tells) and an unnamed picture
        box("south_a", (-T, -T, 0), (2.0, 0, H), wall), box("south_b", (3.2, -T, 0), (X1 + T, 0, H), wall),
        box("south_sill", (2.0, -T, 0), (3.2, 0, 0.8), wall), box("south_head", (2.0, -T, 2.2), (3.2, 0, H), wall),
        box("Mesh_12", (2.0, -T, 0.8), (3.2, 0, 2.2), (), transparent=True),
        box("Cube.099", (4.2, 0.0, 1.0), (5.2, 0.02, 1.9), ()),
        # west wall with a bookcase (named) and an unnamed column
        box("west", (-T, 0, 0), (0, Y1, H), wall),
        box("Bookcase", (0.0, 1.0, 0), (0.35, 1.9, 2.0)),
        box("Cube.050", (0.0, 3.0, 0), (0.3, 3.7, H), ()),
    ]
    if not names:
        parts = [dataclasses.replace(p, names=()) for p in parts]
    return Scene("rules_room", tuple(parts), (), 0.0)


def on(disc, obj) -> np.ndarray:
    """(C,) bool: the candidate's centre is on the object's face."""
    _, c, n, hw, hh = obj
    c, n = np.asarray(c, float), np.asarray(n, float)
    d = disc.candidate_position - c
    across = np.abs(d @ n) < 0.03
    along = np.abs(d @ np.cross([0.0, 0.0, 1.0], n)) <= hw
    return across & along & (np.abs(d[:, 2]) <= hh) & (disc.candidate_normal @ n > 0.9)


FAST = dict(grid_spacing=0.5, num_yaws=4)


@pytest.fixture(scope="module")
def default_disc():
    return discretize(rules_room(), DiscretizeConfig(**FAST))


@pytest.mark.parametrize("obj", [WINDOW, CURTAIN, DOOR, GLASS, PICTURE, BOOKCASE], ids=lambda o: o[0])
def test_no_candidate_on_what_a_person_would_not_use(default_disc, obj):
    assert not on(default_disc, obj).any(), obj[0]


def test_walls_and_the_column_keep_candidates(default_disc):
    d = default_disc
    assert set(d.candidate_surface) <= {"wall", "column"}
    assert (d.candidate_surface == "wall").sum() >= 6
    col = on(d, COLUMN)
    assert col.any() and set(d.candidate_surface[col]) == {"column"}
    assert all(p.startswith("Cube.050") for p in d.candidate_part[col])
    removed = d.summary["candidates_removed"]
    assert removed["glass"] >= 1 and removed["windows"] >= 1 and removed["curtains"] >= 1
    assert removed["furniture"] >= 1


@pytest.mark.parametrize("allow, obj, surface", [
    ("windows", WINDOW, "window"), ("curtains", CURTAIN, "curtain"), ("furniture", BOOKCASE, "bookcase front"),
    ("off-wall", PICTURE, "surface standing off the wall"), ("in-opening", DOOR, "panel in a wall opening"),
], ids=lambda v: v if isinstance(v, str) else "")
def test_allow_restores_one_category(allow, obj, surface, default_disc):
    d = discretize(rules_room(), DiscretizeConfig(**FAST, candidates=CandidateConfig(allow=(allow,))))
    assert on(d, obj).any(), f"--allow {allow}: no candidate on the {obj[0]}"
    assert set(d.candidate_surface[on(d, obj)]) == {surface}
    others = [o for o in (WINDOW, CURTAIN, DOOR, GLASS, PICTURE, BOOKCASE) if o is not obj]
    assert not any(on(d, o).any() for o in others)  # only that one
    assert len(d.candidate_position) > len(default_disc.candidate_position)


def test_glass_is_never_allowed():
    d = discretize(rules_room(), DiscretizeConfig(**FAST, candidates=CandidateConfig(allow=tuple(ALLOWABLE))))
    assert not on(d, GLASS).any() and on(d, WINDOW).any()
    # the same pane, opaque: a tag fits there, so transparency alone kept it off
    opaque = rules_room()
    opaque = dataclasses.replace(opaque, parts=tuple(dataclasses.replace(p, transparent=False) for p in opaque.parts))
    assert on(discretize(opaque, DiscretizeConfig(**FAST)), GLASS).any()


def test_geometry_finds_the_unnamed_door_picture_and_column():
    scene = rules_room(names=False)
    rc = RayCaster(*scene.geometry())
    spots = [  # (centre, normal): door leaf, picture, column, bookcase, then three plain walls
        ((X1 + 0.03, 1.95, 1.5), (-1, 0, 0)), ((4.7, 0.02, 1.45), (0, 1, 0)), ((0.3, 3.35, 1.5), (1, 0, 0)),
        ((0.35, 1.45, 1.5), (1, 0, 0)), ((3.0, Y1, 1.5), (0, -1, 0)), ((X1, 3.5, 1.5), (-1, 0, 0)),
        ((2.85, Y1, 1.5), (0, -1, 0))]
    centres, normals = (np.array([s[i] for s in spots], float) for i in (0, 1))
    shape = surface_shape(rc, centres, normals, np.zeros(len(spots)), CandidateConfig())
    assert shape["in-opening"].tolist() == [True, False, False, False, False, False, False]
    assert shape["off-wall"].tolist() == [False, True, False, True, False, False, False]
    assert shape["column"].tolist() == [False, False, True, False, False, False, False]


def test_without_names_geometry_and_glass_still_keep_tags_off(caplog):
    d = discretize(rules_room(names=False), DiscretizeConfig(**FAST))
    for obj in (DOOR, GLASS, PICTURE, BOOKCASE):
        assert not on(d, obj).any(), obj[0]
    # a flush window and a floor-to-ceiling curtain have no geometry: only their names tell
    assert on(d, WINDOW).any() or on(d, CURTAIN).any()


def test_the_log_line_adds_up(caplog):
    caplog.set_level(logging.INFO, logger="markerplace.plan.discretize.stage")
    d = discretize(rules_room(), DiscretizeConfig(**FAST))
    line = next(r.getMessage() for r in caplog.records if "wall spots" in r.getMessage())
    m = re.search(r"(\d+) wall spots [\d.]+ m apart = (.*) \+ (\d+) that pass; candidates = those (\d+)"
                  r"(?: - (\d+) crowded out)? \+ (\d+) found .* = (\d+)$", line)
    assert m, line
    spots, removed, passed, passed2, crowded, added, total = m.groups()
    removed = [int(t.split()[0]) for t in removed.split(" + ")]
    assert int(spots) == sum(removed) + int(passed) and passed == passed2
    assert int(passed) - int(crowded or 0) + int(added) == int(total) == len(d.candidate_position)
    counts = d.summary["candidates_removed"]
    assert sorted(removed) == sorted(v for v in counts.values() if v)


# ---------------------------------------------------------------- the built-in scenes


def _covered_labels(scene, disc, half: float) -> list[set]:
    """Per candidate, the labels of the parts under its tag square (``half`` metres each side),
    from rays 5 cm in front of the wall."""
    rc = RayCaster(*scene.geometry())
    part = scene.face_part()
    P, N = disc.candidate_position, disc.candidate_normal
    x = np.cross([0.0, 0.0, 1.0], N)
    a = np.linspace(-half, half, 7)
    A, B = (v.ravel() for v in np.meshgrid(a, a))
    o = P[:, None] + A[None, :, None] * x[:, None] + B[None, :, None] * np.array([0, 0, 1.0]) + 0.05 * N[:, None]
    _, f = rc.first_hits(o.reshape(-1, 3), np.repeat(-N, len(A), axis=0), 0.15)
    labels = np.array([scene.parts[part[i]].names[0] if i >= 0 else "nothing" for i in f]).reshape(len(P), -1)
    return [set(row) for row in labels]


@pytest.mark.parametrize("name", ["house", "apartment"])
def test_builtins_have_windows_doors_pictures_and_no_tag_on_them(name):
    scene = load_scene(name)
    labels = {p.names[0] for p in scene.parts if p.names}
    assert {"window", "door", "picture"} <= labels
    assert any(p.transparent and "door" in p.names for p in scene.parts)  # a glass door
    assert any(not p.transparent and "door" in p.names for p in scene.parts)  # an opaque one
    disc = discretize(scene, DiscretizeConfig())
    # the tag and its white border lie on wall faces only
    assert all(s == {"wall"} for s in _covered_labels(scene, disc, 0.3))
    assert set(disc.candidate_surface) == {"wall"}
    removed = disc.summary["candidates_removed"]
    assert removed["windows"] + removed["glass"] >= 2 and removed["pictures"] >= 2 and removed["furniture"] >= 2


def test_house_without_names_keeps_tags_off_by_geometry_and_glass():
    house = load_scene("house")
    bare = dataclasses.replace(house, parts=tuple(dataclasses.replace(p, names=()) for p in house.parts))
    disc = discretize(bare, DiscretizeConfig())
    # the black square (the border may touch a window frame 1.5 cm behind the wall, within flatness)
    assert all(s == {"wall"} for s in _covered_labels(house, disc, 0.2))


def test_categories_are_the_documented_ones():
    assert list(ALLOWABLE)[:len(CATEGORIES)] == list(CATEGORIES)
    assert set(ALLOWABLE) - set(CATEGORIES) == {"off-wall", "in-opening"}


# ---------------------------------------------------------------- names read from files


def test_loader_keeps_node_parent_mesh_and_material_names(tmp_path):
    """A glTF as artists export it: a ``RoomWindow_3`` group holding a mesh ``Cube.012`` with a
    ``Material.005``; the window is known by its parent node. A PLY's own file name says nothing."""
    import trimesh

    from markerplace.scene.loader import load_mesh_file

    scene = trimesh.Scene()
    scene.graph.update(frame_from="world", frame_to="RoomWindow_3")
    panel = trimesh.creation.box(extents=(1.2, 0.05, 1.2))
    panel.visual = trimesh.visual.TextureVisuals(material=trimesh.visual.material.PBRMaterial(name="Material.005"))
    scene.add_geometry(panel, node_name="Cube.012_node", geom_name="Cube.012", parent_node_name="RoomWindow_3")
    wall = trimesh.creation.box(extents=(4.0, 0.1, 2.7))
    wall.apply_translation((0.0, 1.0, 0.0))
    scene.add_geometry(wall, node_name="Wall_North", geom_name="Cube.013")
    scene.export(tmp_path / "house.glb")
    parts = {p.name: p for p in load_mesh_file(tmp_path / "house.glb").parts}
    assert "RoomWindow_3" in parts["Cube.012"].names and "Material.005" in parts["Cube.012"].names
    assert classify(parts["Cube.012"].names).category == "windows"
    assert classify(parts["Cube.013"].names).category == "structure"
    trimesh.creation.box(extents=(3.0, 3.0, 3.0)).export(tmp_path / "window_scan.ply")
    (part,) = load_mesh_file(tmp_path / "window_scan.ply").parts
    assert classify(part.names).category == ""


def test_builtin_labels_survive_gltf_export(tmp_path):
    from markerplace.scene.export import export_glb
    from markerplace.scene.loader import load_mesh_file

    room = load_scene("room")
    export_glb(room, tmp_path / "room.glb")
    back = {p.name: p for p in load_mesh_file(tmp_path / "room.glb").parts}
    for p in room.parts:
        assert classify(back[p.name].names).category == classify(p.names).category, p.name
    assert {classify(p.names).category for p in room.parts} >= {"structure", "furniture", "pictures", "screens"}


def test_allow_on_the_command_line(capsys):
    from markerplace.cli.main import main
    from markerplace.cli.options import parse_allow

    assert parse_allow("Furniture, doors,furniture") == ("furniture", "doors") and parse_allow("none") == ()
    assert main(["plan", "tiny", "--allow", "furniture,sofas", "--out", "unused", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error: --allow") and "'sofas'" in err[0]
