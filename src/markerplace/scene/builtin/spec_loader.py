"""Room specs of the built-in scenes as data: the TOML files in ``scene/builtin/specs/`` and
their loader, which builds the :mod:`.layout` dataclasses from them.

One file per built-in (``specs/<name>.toml``, read with :mod:`tomllib`). The keys are the fields
of the :mod:`.layout` dataclasses; lengths in metres, room contents in room-local coordinates
(metres from the room's (xmin, ymin) corner). A single-storey layout file (:func:`load_layout`)::

    name = "office"                      # Layout fields: name, description,
    description = "..."                  #   and optionally doors, twins, wall_thickness,
    doors = [{a = "open_office", b = "meeting", at = 0.5}]   # ceiling_height, floor_z
    [room_types.twin_bedroom]            # optional: room fields shared by the rooms with
    floor = "wood_dark"                  #   room_type = "twin_bedroom" (their own keys win)
    [[rooms]]                            # RoomSpec fields: name, bounds (xmin, ymin, xmax, ymax),
    name = "open_office"                 #   floor, wall_color, items, pictures, template, lights,
    bounds = [0.0, 0.0, 9.0, 8.0]        #   floor_dz, floor_holes, ceiling_holes, openings;
                                         #   and room_type

Entries of a room's lists:

* ``items``: ``{kind, x, y, yaw_deg?, variant?}`` (an :class:`~.layout.Item`);
  ``{kind, wall, along, variant?}`` (:func:`~.layout.wall_item`: against wall N/S/E/W of the room,
  whose size comes from its bounds); ``{group = "workstation", x, y, yaw_deg}``;
  ``{group = "chairs_around", x, y, half_depth, xs}``; ``{group = "desk_cluster", x, y, xs}``
  (the helpers of :mod:`.layout`, expanded in place).
* ``pictures``: ``{wall, along, width, image, z_center?}``; ``openings``: ``{wall, along, width,
  kind?, sill?, top?}``; ``floor_holes`` / ``ceiling_holes``: ``[xmin, ymin, xmax, ymax]`` or the
  name of a hole the building's code defines (``"stair"``).

Multi-storey files (``house.toml``, ``campus.toml``) use the same room and door entries; their
modules (:mod:`.house`, :mod:`.campus`) say how they are laid out and add the storey heights.
An unknown key, a missing field or a value of the wrong type raises :class:`SpecError` naming the
file and the entry. Numbers are read as written: a float in a file is the float in the layout.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import tomllib

from markerplace.scene.builtin.furniture import FURNITURE
from markerplace.scene.builtin.layout import (
    OPENING_KINDS,
    Door,
    Item,
    Layout,
    Opening,
    Picture,
    RoomSpec,
    chairs_around,
    desk_cluster,
    wall_item,
    workstation,
)

__all__ = ["SPEC_DIR", "SpecError", "build_door", "build_layout", "build_room", "check_keys", "load_layout", "read_spec",
           "spec_names"]

SPEC_DIR = Path(__file__).with_name("specs")
WALLS = ("N", "S", "E", "W")

_ROOM_KEYS = ("floor", "wall_color", "items", "pictures", "template", "lights", "floor_dz", "floor_holes", "ceiling_holes",
              "openings")
_LAYOUT_KEYS = ("doors", "twins", "wall_thickness", "ceiling_height", "floor_z", "room_types", "rooms")


class SpecError(ValueError):
    """A built-in's spec file is malformed; the message names the file and the entry."""


def spec_names() -> list[str]:
    """Names of the spec files (without ``.toml``), sorted."""
    return sorted(p.stem for p in SPEC_DIR.glob("*.toml"))


def read_spec(name: str) -> tuple[dict, str]:
    """The parsed ``specs/<name>.toml`` and the label errors use for it (``specs/<name>.toml``)."""
    where = f"specs/{name}.toml"
    try:
        with open(SPEC_DIR / f"{name}.toml", "rb") as f:
            return tomllib.load(f), where
    except tomllib.TOMLDecodeError as err:
        raise SpecError(f"{where}: {err}") from None


def check_keys(entry: Any, where: str, required: tuple[str, ...] = (), optional: tuple[str, ...] = ()) -> dict:
    """``entry`` if it is a table with all ``required`` keys and no others than ``optional``."""
    if not isinstance(entry, dict):
        raise SpecError(f"{where}: expected a table, got {type(entry).__name__} {entry!r}")
    allowed = (*required, *optional)
    for key in entry:
        if key not in allowed:
            raise SpecError(f"{where}: unknown key {key!r} (allowed: {', '.join(allowed)})")
    for key in required:
        if key not in entry:
            raise SpecError(f"{where}: missing field {key!r}")
    return entry


def _num(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(f"{where}: expected a number, got {value!r}")
    return float(value)


def _int(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise SpecError(f"{where}: expected a whole number, got {value!r}")
    return value


def _str(value: Any, where: str, choices: tuple[str, ...] | None = None) -> str:
    if not isinstance(value, str):
        raise SpecError(f"{where}: expected a string, got {value!r}")
    if choices is not None and value not in choices:
        raise SpecError(f"{where}: {value!r} is not one of {', '.join(choices)}")
    return value


def _list(value: Any, where: str, length: int | None = None) -> list:
    if not isinstance(value, (list, tuple)) or (length is not None and len(value) != length):
        n = f" of {length}" if length is not None else ""
        raise SpecError(f"{where}: expected a list{n}, got {value!r}")
    return list(value)


def _nums(value: Any, where: str, length: int | None = None) -> tuple[float, ...]:
    return tuple(_num(v, f"{where}[{i}]") for i, v in enumerate(_list(value, where, length)))


def _items(entry: dict, where: str, size: tuple[float, float]) -> tuple[Item, ...]:
    """One ``items`` entry: an item, an item against a wall, or a group of items."""
    if "group" in entry:
        group = _str(entry["group"], f"{where}: group", ("workstation", "chairs_around", "desk_cluster"))
        if group == "workstation":
            check_keys(entry, where, ("group", "x", "y", "yaw_deg"))
            return workstation(_num(entry["x"], f"{where}: x"), _num(entry["y"], f"{where}: y"), _num(entry["yaw_deg"], f"{where}: yaw_deg"))
        if group == "chairs_around":
            check_keys(entry, where, ("group", "x", "y", "half_depth", "xs"))
            return chairs_around(_num(entry["x"], f"{where}: x"), _num(entry["y"], f"{where}: y"),
                                 _num(entry["half_depth"], f"{where}: half_depth"), _nums(entry["xs"], f"{where}: xs"))
        check_keys(entry, where, ("group", "x", "y", "xs"))
        return desk_cluster(_num(entry["x"], f"{where}: x"), _num(entry["y"], f"{where}: y"), _nums(entry["xs"], f"{where}: xs"))
    if "wall" in entry:
        check_keys(entry, where, ("kind", "wall", "along"), ("variant",))
    else:
        check_keys(entry, where, ("kind", "x", "y"), ("yaw_deg", "variant"))
    kind = _str(entry["kind"], f"{where}: kind", tuple(FURNITURE))
    variant = _int(entry.get("variant", 0), f"{where}: variant")
    if "wall" in entry:
        return (wall_item(kind, size, _str(entry["wall"], f"{where}: wall", WALLS), _num(entry["along"], f"{where}: along"), variant),)
    yaw = _num(entry.get("yaw_deg", 0.0), f"{where}: yaw_deg")
    return (Item(kind, _num(entry["x"], f"{where}: x"), _num(entry["y"], f"{where}: y"), yaw, variant),)


def _picture(entry: dict, where: str) -> Picture:
    check_keys(entry, where, ("wall", "along", "width", "image"), ("z_center",))
    return Picture(_str(entry["wall"], f"{where}: wall", WALLS), _num(entry["along"], f"{where}: along"),
                   _num(entry["width"], f"{where}: width"), _str(entry["image"], f"{where}: image"),
                   _num(entry.get("z_center", 1.5), f"{where}: z_center"))


def _opening(entry: dict, where: str) -> Opening:
    check_keys(entry, where, ("wall", "along", "width"), ("kind", "sill", "top"))
    return Opening(_str(entry["wall"], f"{where}: wall", WALLS), _num(entry["along"], f"{where}: along"),
                   _num(entry["width"], f"{where}: width"), _str(entry.get("kind", "window"), f"{where}: kind", OPENING_KINDS),
                   _num(entry.get("sill", 0.9), f"{where}: sill"), _num(entry.get("top", 2.1), f"{where}: top"))


def _holes(value: Any, where: str, holes: dict[str, tuple]) -> tuple[tuple[float, float, float, float], ...]:
    out = []
    for i, h in enumerate(_list(value, where)):
        if isinstance(h, str):
            if h not in holes:
                raise SpecError(f"{where}[{i}]: unknown hole {h!r} (defined: {', '.join(holes) or 'none'})")
            out.append(tuple(holes[h]))
        else:
            out.append(_nums(h, f"{where}[{i}]", 4))
    return tuple(out)


def build_room(entry: Any, where: str, room_types: dict | None = None, holes: dict[str, tuple] | None = None) -> RoomSpec:
    """A :class:`~.layout.RoomSpec` from a ``rooms`` entry (with ``room_type``: the keys of that
    entry of ``room_types`` first). ``holes``: the named floor/ceiling holes. The room's size for
    items against a wall is its bounds' extent, rounded to 1 nm."""
    if isinstance(entry, dict) and isinstance(entry.get("name"), str):
        where = f"{where} {entry['name']!r}"
    check_keys(entry, where, ("name", "bounds"), (*_ROOM_KEYS, "room_type"))
    name = _str(entry["name"], f"{where}: name")
    if "room_type" in entry:
        kind = _str(entry["room_type"], f"{where}: room_type")
        if kind not in (room_types or {}):
            raise SpecError(f"{where}: unknown room_type {kind!r} (defined: {', '.join(room_types or {}) or 'none'})")
        base = check_keys(room_types[kind], f"{where}: room_types.{kind}", (), _ROOM_KEYS)
        entry = {**base, **{k: v for k, v in entry.items() if k != "room_type"}}
    bounds = _nums(entry["bounds"], f"{where}: bounds", 4)
    size = (round(bounds[2] - bounds[0], 9), round(bounds[3] - bounds[1], 9))
    items = tuple(it for i, e in enumerate(_list(entry.get("items", []), f"{where}: items"))
                  for it in _items(e, f"{where}: items[{i}]", size))
    kw: dict[str, Any] = {"items": items}
    kw["pictures"] = tuple(_picture(e, f"{where}: pictures[{i}]") for i, e in enumerate(_list(entry.get("pictures", []), f"{where}: pictures")))
    kw["openings"] = tuple(_opening(e, f"{where}: openings[{i}]") for i, e in enumerate(_list(entry.get("openings", []), f"{where}: openings")))
    if "floor" in entry:
        kw["floor"] = _str(entry["floor"], f"{where}: floor")
    if "wall_color" in entry:
        kw["wall_color"] = tuple(_int(v, f"{where}: wall_color") for v in _list(entry["wall_color"], f"{where}: wall_color", 3))
    if "template" in entry:
        kw["template"] = _str(entry["template"], f"{where}: template")
    if "lights" in entry:
        kw["lights"] = _int(entry["lights"], f"{where}: lights")
    if "floor_dz" in entry:
        kw["floor_dz"] = _num(entry["floor_dz"], f"{where}: floor_dz")
    for key in ("floor_holes", "ceiling_holes"):
        if key in entry:
            kw[key] = _holes(entry[key], f"{where}: {key}", holes or {})
    return RoomSpec(name, bounds, **kw)


def build_door(entry: Any, where: str, prefix: str = "") -> Door:
    """A :class:`~.layout.Door` from a ``doors`` entry ``{a, b, at?, width?, height?}``; ``prefix``
    goes before both room names."""
    check_keys(entry, where, ("a", "b"), ("at", "width", "height"))
    return Door(prefix + _str(entry["a"], f"{where}: a"), prefix + _str(entry["b"], f"{where}: b"),
                _num(entry.get("at", 0.5), f"{where}: at"), _num(entry.get("width", 0.95), f"{where}: width"),
                _num(entry.get("height", 2.1), f"{where}: height"))


def build_layout(spec: dict, where: str, holes: dict[str, tuple] | None = None, **fields) -> Layout:
    """A :class:`~.layout.Layout` from a table with ``rooms``, ``doors``, ... (see the module
    docstring); ``fields`` (e.g. ``name``, ``floor_z``) are given by the caller, not the table."""
    check_keys(spec, where, tuple(k for k in ("name", "description", "rooms") if k not in fields),
               tuple(k for k in _LAYOUT_KEYS if k != "rooms" and k not in fields))
    room_types = spec.get("room_types", {})
    check_keys(room_types, f"{where}: room_types", (), tuple(room_types) if isinstance(room_types, dict) else ())
    rooms = tuple(build_room(e, f"{where}: rooms[{i}]", room_types, holes) for i, e in enumerate(_list(spec["rooms"], f"{where}: rooms")))
    doors = tuple(build_door(e, f"{where}: doors[{i}]") for i, e in enumerate(_list(spec.get("doors", []), f"{where}: doors")))
    kw: dict[str, Any] = {"doors": doors}
    if "twins" in spec:
        kw["twins"] = tuple(tuple(_str(n, f"{where}: twins") for n in _list(p, f"{where}: twins", 2)) for p in _list(spec["twins"], f"{where}: twins"))
    for key in ("wall_thickness", "ceiling_height", "floor_z"):
        if key in spec:
            kw[key] = _num(spec[key], f"{where}: {key}")
    for key in ("name", "description"):
        kw[key] = fields.pop(key) if key in fields else _str(spec[key], f"{where}: {key}")
    return Layout(rooms=rooms, **kw, **fields)


def load_layout(name: str) -> Layout:
    """The single-storey built-in ``name`` from ``specs/<name>.toml``."""
    spec, where = read_spec(name)
    return build_layout(spec, where)
