"""The built-in ``corridor``: a hotel floor that is hard to localize in, sized by its room count.

World frame: z up, metres, floor at z = 0, ceiling 2.7 m. With ``n`` guest rooms (default
:data:`ROOMS` = 10; wall centre lines)::

    y=6.8  +-----------+------------------------------------------------+
           |  lobby    |  corridor (n x 3.6 m long, 1.8 m wide, plain)   |
           |           =  (open to the lobby, 1.5 m)                     |
    y=5.0  |  (pictures+---d--+---d--+---d--+---d--+ ... +---d--+---d--+
           |  reception|room_01|room_02|room_03|room_04|     |       |room_n |
           |  lounge,  |       |       |       |       |     |       |       |
           |  wood)    |  bed, nightstands, desk, chair, wardrobe,     |       |
    y=0    +-----------+---w---+---w---+---w---+---w---+ ... +---w---+-------+
          x=-6.4      x=0    3.6     7.2    10.8                    3.6 n

``d``: a 0.9 m doorway (an opening, no leaf) from each room into the corridor, 0.72 m from the
room's west wall; ``w``: a window in each room's south (outside) wall. All guest rooms are one
template (``guest_room`` in the spec): same size, furniture, print, doorway and window, and the same
seeded chair jitter, so they are identical up to a translation of :data:`CELL` along x; only the
lobby at the west end carries distinctive texture (wood floor, rug, five pictures, a reception
counter, a lounge). At the default size the floor is 180 m^2 of rooms + 64.8 m^2 of corridor +
43.5 m^2 of lobby = 288.3 m^2.

The seed (``--seed``) changes what it changes in every built-in: the textures' noise (the same
noise in every room, as the rooms share textures) and the chair jitter (the same in every room).
It never makes one room differ from another.

The rooms' contents, the corridor's finish, the lobby and its doorway are data, in
``scene/builtin/specs/corridor.toml`` (TOML, format in its header and in :mod:`.spec_loader`);
this module lays out the ``n`` rooms and the corridor and connects them.

The built-in ``corridor-small`` is the same floor with :data:`SMALL_ROOMS` guest rooms (the
demo's scene: small enough to plan and evaluate in minutes, still one template repeated).

``Scene.meta`` keys: ``twins`` (pairs (room_01, room_k): identical up to a translation),
``ceiling_height``, ``seed``, ``guest_rooms`` (their names, west to east), ``cell`` (the x step
between rooms, metres).
"""

from __future__ import annotations

import logging
from dataclasses import replace

from markerplace.errors import UserError
from markerplace.scene.builtin.layout import Layout
from markerplace.scene.builtin.procedural import build_scene
from markerplace.scene.builtin.spec_loader import SpecError, build_door, build_room, check_keys, read_spec
from markerplace.scene.types import Scene

log = logging.getLogger(__name__)

__all__ = ["CELL", "CORRIDOR_WIDTH", "MIN_ROOMS", "ROOM_DEPTH", "ROOMS", "SMALL_NAME", "SMALL_ROOMS", "build_corridor",
           "build_small_corridor", "corridor_plan", "room_name", "small_corridor_plan"]

ROOMS = 10  # guest rooms at the default size
SMALL_ROOMS = 4  # guest rooms of the built-in ``corridor-small`` (the demo's scene)
SMALL_NAME = "corridor-small"
MIN_ROOMS = 2  # identical rooms need at least two
CELL = 3.6  # guest room width along the corridor (x), metres
ROOM_DEPTH = 5.0  # guest room depth (y), metres; the corridor's south wall is at y = ROOM_DEPTH
CORRIDOR_WIDTH = 1.8


def room_name(i: int) -> str:
    """Name of guest room ``i`` (0-based, west to east): ``room_01``, ``room_02``, ..."""
    return f"room_{i + 1:02d}"


def corridor_plan(rooms: int = ROOMS) -> Layout:
    """The hotel floor with ``rooms`` guest rooms (at least :data:`MIN_ROOMS`); see the module
    docstring. Raises UserError for fewer rooms, SpecError for a malformed spec file."""
    if isinstance(rooms, bool) or not isinstance(rooms, int) or rooms < MIN_ROOMS:
        raise UserError(f"corridor: need a whole number of at least {MIN_ROOMS} guest rooms, got {rooms!r}")
    spec, where = read_spec("corridor")
    check_keys(spec, where, ("name", "description", "room_door", "room_types", "rooms"), ("doors",))
    types = spec["room_types"]
    for key in ("guest_room", "corridor"):
        if key not in types:
            raise SpecError(f"{where}: room_types: missing {key!r}")
    door = check_keys(spec["room_door"], f"{where}: room_door", (), ("at", "width", "height"))
    guests = [build_room({"name": room_name(i), "room_type": "guest_room", "bounds": (i * CELL, 0.0, (i + 1) * CELL, ROOM_DEPTH)},
                         f"{where}: guest room {i + 1}", types) for i in range(rooms)]
    hall = build_room({"name": "corridor", "room_type": "corridor",
                       "bounds": (0.0, ROOM_DEPTH, rooms * CELL, ROOM_DEPTH + CORRIDOR_WIDTH)}, f"{where}: corridor", types)
    others = [build_room(e, f"{where}: rooms[{i}]", types) for i, e in enumerate(spec["rooms"])]
    doors = [build_door({"a": g.name, "b": "corridor", **door}, f"{where}: room_door") for g in guests]
    doors += [build_door(e, f"{where}: doors[{k}]") for k, e in enumerate(spec.get("doors", []))]
    twins = tuple((guests[0].name, g.name) for g in guests[1:])
    layout = Layout(spec["name"], "", tuple(guests + [hall] + others), doors=tuple(doors), twins=twins)
    return replace(layout, description=spec["description"].format(rooms=rooms, area=layout.floor_area))


def small_corridor_plan() -> Layout:
    """The layout of ``corridor-small``: :func:`corridor_plan` with :data:`SMALL_ROOMS` rooms,
    named :data:`SMALL_NAME`."""
    return replace(corridor_plan(SMALL_ROOMS), name=SMALL_NAME)


def build_corridor(seed: int = 0, rooms: int = ROOMS, name: str = "corridor") -> Scene:
    """Build the hotel floor with ``rooms`` guest rooms (deterministic in ``seed`` and ``rooms``),
    named ``name`` (``source = "builtin:<name>"``; the built-ins ``corridor`` and
    ``corridor-small``); ``meta["guest_rooms"]`` says how many rooms it has. Part names start
    with ``name``, so the same floor under two names differs only in its names."""
    plan = replace(corridor_plan(rooms), name=name)
    scene = build_scene(plan, seed)
    guests = [room_name(i) for i in range(rooms)]
    log.debug("built %s with %d guest rooms (%.1f m^2)", name, rooms, plan.floor_area)
    return replace(scene, meta={**scene.meta, "guest_rooms": guests, "cell": CELL})


def build_small_corridor(seed: int = 0) -> Scene:
    """Build ``corridor-small`` (:data:`SMALL_ROOMS` guest rooms); see :func:`build_corridor`."""
    return build_corridor(seed, SMALL_ROOMS, SMALL_NAME)
