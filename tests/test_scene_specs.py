"""The built-in scenes' room specs as data (scene/builtin/specs/*.toml) and their loader."""

from __future__ import annotations

import pytest
import tomllib

from markerplace.scene.builtin import campus, house
from markerplace.scene.builtin.catalogue import builtin_names, get_layout, spec_of
from markerplace.scene.builtin.layout import Item, Layout, wall_item, workstation
from markerplace.scene.builtin.spec_loader import SPEC_DIR, SpecError, build_door, build_layout, build_room, spec_names

ROOM = {"name": "r", "bounds": [0.0, 0.0, 4.0, 3.0]}


def _spec(text: str) -> dict:
    return tomllib.loads(text)


def test_every_builtin_has_a_spec_and_every_spec_loads():
    assert spec_names() == sorted({spec_of(name) for name in builtin_names()})  # each spec used, each built-in has one
    for name in builtin_names():
        plan = get_layout.__wrapped__(name)  # uncached: read the file now
        assert plan.rooms and plan.description
        assert all(r.name for r in plan.rooms)


def test_every_spec_file_has_a_format_header():
    for path in SPEC_DIR.glob("*.toml"):
        head = path.read_text().splitlines()[:20]
        assert head[0].startswith("# Built-in scene"), path.name
        assert any("spec_loader.py" in line for line in head), path.name


def test_items_against_walls_and_groups_expand_as_the_helpers_do():
    room = build_room({**ROOM, "items": [{"kind": "bookshelf", "wall": "N", "along": 1.0},
                                         {"group": "workstation", "x": 1.0, "y": 1.5, "yaw_deg": 90.0},
                                         {"kind": "plant", "x": 0.5, "y": 0.5}]}, "t")
    assert room.items == (wall_item("bookshelf", (4.0, 3.0), "N", 1.0), *workstation(1.0, 1.5, 90.0), Item("plant", 0.5, 0.5))


def test_a_room_type_gives_defaults_the_room_overrides():
    spec = _spec("""
        name = "x"
        description = "y"
        [room_types.t]
        floor = "tiles"
        lights = 3
        [[rooms]]
        name = "a"
        room_type = "t"
        bounds = [0, 0, 2, 2]
        lights = 1
    """)
    layout = build_layout(spec, "x.toml")
    assert isinstance(layout, Layout)
    (room,) = layout.rooms
    assert (room.floor, room.lights, room.bounds) == ("tiles", 1, (0.0, 0.0, 2.0, 2.0))
    assert all(type(v) is float for v in room.bounds)  # whole numbers in a file are floats in the layout


@pytest.mark.parametrize("entry, message", [
    ({**ROOM, "colour": [1, 2, 3]}, "unknown key 'colour'"),
    ({"name": "r"}, "missing field 'bounds'"),
    ({**ROOM, "items": [{"kind": "sofa", "x": 1.0}]}, "items[0]: missing field 'y'"),
    ({**ROOM, "items": [{"kind": "sofa", "x": 1.0, "y": 1.0, "yaw": 90}]}, "items[0]: unknown key 'yaw'"),
    ({**ROOM, "items": [{"kind": "sofaa", "x": 1.0, "y": 1.0}]}, "'sofaa' is not one of"),
    ({**ROOM, "items": [{"group": "workstations", "x": 1.0}]}, "'workstations' is not one of"),
    ({**ROOM, "pictures": [{"wall": "X", "along": 1.0, "width": 1.0, "image": "moon"}]}, "'X' is not one of N, S, E, W"),
    ({**ROOM, "pictures": [{"wall": "N", "along": 1.0, "image": "moon"}]}, "pictures[0]: missing field 'width'"),
    ({**ROOM, "openings": [{"wall": "N", "along": 1.0, "width": 1.0, "kind": "hatch"}]}, "'hatch' is not one of"),
    ({**ROOM, "bounds": [0.0, 0.0, 4.0]}, "bounds: expected a list of 4"),
    ({**ROOM, "lights": 1.5}, "lights: expected a whole number"),
    ({**ROOM, "floor_dz": "low"}, "floor_dz: expected a number"),
    ({**ROOM, "ceiling_holes": ["stairs"]}, "unknown hole 'stairs'"),
    ({**ROOM, "room_type": "meeting"}, "unknown room_type 'meeting'"),
])
def test_a_malformed_room_is_rejected_with_a_clear_error(entry, message):
    with pytest.raises(SpecError) as err:
        build_room(entry, "specs/x.toml: rooms[0]")
    assert message in str(err.value)
    assert str(err.value).startswith("specs/x.toml: rooms[0]")


def test_a_malformed_door_or_layout_is_rejected():
    with pytest.raises(SpecError, match=r"doors\[1\]: unknown key 'with'"):
        build_layout({"name": "x", "description": "y", "rooms": [ROOM], "doors": [{"a": "r", "b": "s"}, {"a": "r", "b": "s", "with": 1}]},
                     "x.toml")
    with pytest.raises(SpecError, match="missing field 'b'"):
        build_door({"a": "r"}, "x.toml: doors[0]")
    with pytest.raises(SpecError, match="x.toml: unknown key 'room'"):
        build_layout({"name": "x", "description": "y", "rooms": [ROOM], "room": ROOM}, "x.toml")
    with pytest.raises(SpecError, match="x.toml: missing field 'rooms'"):
        build_layout({"name": "x", "description": "y"}, "x.toml")


def test_the_buildings_reject_unknown_keys_in_their_files(monkeypatch):
    def bad_house(name):
        spec = tomllib.loads((SPEC_DIR / "house.toml").read_text())
        spec["storeys"][1]["rooms"][0]["item"] = []
        return spec, "specs/house.toml"
    monkeypatch.setattr(house, "read_spec", bad_house)
    with pytest.raises(SpecError, match=r"storeys\[1\]: rooms\[0\] 'master_bedroom': unknown key 'item'"):
        house.house_plan()

    def bad_campus(name):
        spec = tomllib.loads((SPEC_DIR / "campus.toml").read_text())
        spec["rooms"][0]["levels"] = "ground"
        return spec, "specs/campus.toml"
    monkeypatch.setattr(campus, "read_spec", bad_campus)
    with pytest.raises(SpecError, match=r"rooms\[0\]: levels: expected a list"):
        campus.campus_plan()


def test_campus_storeys_come_from_the_levels_of_the_spec():
    plan = get_layout("campus")
    ground, upper = plan.storeys
    names = {s.floor_z: {r.name for r in s.rooms} for s in plan.storeys}
    assert "l0_reception" in names[0.0] and not any("reception" in n for n in names[3.0])
    # the reception takes the ground floor's office cells 6 and 7
    assert {"l0_office_06", "l0_office_07"}.isdisjoint(names[0.0]) and {"l1_office_06", "l1_office_07"} <= names[3.0]
    hall0 = next(r for r in ground.rooms if r.name == "l0_stair_hall")
    hall1 = next(r for r in upper.rooms if r.name == "l1_stair_hall")
    assert hall0.ceiling_holes == (campus.HOLE,) and hall1.floor_holes == (campus.HOLE,)
    assert "2064 m^2" in plan.description and "22 offices" in plan.description
