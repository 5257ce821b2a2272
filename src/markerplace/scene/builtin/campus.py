"""The built-in ``campus``: a two-storey office building of 2,064 m^2 for scale tests.

World frame: z up, metres, ground floor at z = 0; footprint x in [0, 48], y in [0, 21.5] (wall
centre lines), 1,032 m^2 per storey. Storey height 3.0 m: ceilings 2.7 m above each storey
floor, then a 0.3 m slab; upper floor at z = 3.0, roof ceiling at z = 5.7. Both storeys share
one plan, like the floors of a real office building::

    y=21.5 +-----------------+------+----+-----------------+------+
           |                 | meet | copy                 | meet |
           |   open plan     |  b   |room|   open plan     |  c   |
           |   (open_a)      +------+----+   (open_b)      +------+
           |                 | meet |stair                 |kitch-|
           |                 |  a   |hall|                 |  en  |
    y=7.5  +----- opening ---+------+----+----- opening ---+------+
           |  corridor (48 m x 2 m)                               |
    y=5.5  +----+----+----+----+----+----+----+----+----+----+----+
           | 12 identical offices, 4 m x 5.5 m (ground floor: a    |
           | reception in place of offices 6 and 7)               |
    y=0    +------------------------------------------------------+
          x=0   4    8   ...  16  22   26                42     48

Repeated room templates give the perceptual aliasing of real office floors: 22 offices with
the same furniture (posters cycle through three images), four open-plan areas with the same desk
clusters, three meeting rooms, and two storeys with the same north half. ``Scene.meta["twins"]``
lists every pair of rooms that are identical up to a translation.

The stair climbs -y along the east wall of the ground floor's stair hall: 15 risers of 0.2 m,
14 treads of 0.24 m, first riser at y = ``STAIR_FOOT_Y`` facing +y, arriving on the upper floor
at y = ``STAIR_TOP_Y``. Steps are closed solids (treads, risers, a side face down to the floor);
the slab, the ground hall's ceiling and the upper hall's floor have one opening above the flight
with slab-edge faces, and a 1 m balustrade guards its open sides upstairs.

Everything else (walls, floors, ceilings, lights, furniture, pictures) comes from
:func:`markerplace.scene.builtin.procedural.add_layout`, one :class:`Layout` per storey.
The rooms (their types, furniture and pictures), the office posters and the doorways are data, in
``scene/builtin/specs/campus.toml`` (TOML, format in its header and in :mod:`.spec_loader`; entries
with ``levels`` are only on those storeys); this module lays out the offices, one per ``CELL`` of
the south band where no room of the file stands, prefixes room names with ``l<storey>_`` and
defines the stair opening (``"stair"`` in the file: :data:`HOLE`).

``Scene.meta`` keys (world metres): ``storeys`` (``[0.0, 3.0]``), ``storey_height``,
``ceiling_height``, ``slab_thickness``, ``stair`` (``{"x", "y", "bottom_z", "top_z", "risers",
"rise", "going", "up"}``), ``slab_openings`` (list of (xmin, ymin, xmax, ymax)), ``templates``
(room name -> template), ``twins`` (pairs of identical rooms), ``seed``.
"""

from __future__ import annotations

import logging
from dataclasses import replace

from markerplace.scene.builtin import textures as tx
from markerplace.scene.builtin.furniture import palette, texture_fns
from markerplace.scene.builtin.layout import Building, Door, Layout, RoomSpec
from markerplace.scene.builtin.meshkit import Material, MeshBuilder, add_box
from markerplace.scene.builtin.procedural import add_layout, layout_rooms, wall_material
from markerplace.scene.builtin.spec_loader import SpecError, build_door, build_room, check_keys, read_spec
from markerplace.scene.builtin.walls import add_slab_edges, door_span
from markerplace.scene.types import Scene

log = logging.getLogger(__name__)

__all__ = ["campus_plan", "build_campus", "twin_pairs", "STOREY_HEIGHT", "CEILING_HEIGHT", "SLAB", "FOOTPRINT", "HOLE"]

FOOTPRINT = (0.0, 0.0, 48.0, 21.5)
STOREY_HEIGHT = 3.0
CEILING_HEIGHT = 2.7
SLAB = STOREY_HEIGHT - CEILING_HEIGHT
STOREYS = 2
CELL = 4.0  # office width
SOUTH = 5.5  # y of the office band's top (the corridor's south wall)
MID = 14.5  # y of the partition between the north band's front and back rooms
CORE_X = (22.0, 26.0)  # x span of the stair hall and the copy room
# stair: 15 risers x 0.2 m, 14 treads x 0.24 m along the stair hall's east wall, climbing -y
RISERS, RISE, GOING = 15, STOREY_HEIGHT / 15, 0.24
STAIR_X = (CORE_X[1] - 0.05 - 1.2, CORE_X[1] - 0.05)  # 1.2 m wide, against the east wall
STAIR_FOOT_Y = MID - 0.05 - 1.0  # first riser; 1 m to stand in before it
STAIR_TOP_Y = round(STAIR_FOOT_Y - (RISERS - 1) * GOING, 6)
HOLE = (STAIR_X[0], STAIR_TOP_Y, STAIR_X[1], STAIR_FOOT_Y)
BALUSTRADE = (0.1, 1.0)  # thickness, height
HT = 0.05  # half wall thickness


# ----------------------------------------------------------------------------------------------
# storeys (rooms and doors from specs/campus.toml)


def _on_storey(entry, where: str, level: int) -> dict | None:
    """A ``rooms`` / ``doors`` entry of the spec without its ``levels``, or None when it is not on
    storey ``level`` (an entry without ``levels`` is on every storey)."""
    if isinstance(entry, dict) and "levels" in entry:
        levels = entry["levels"]
        if not isinstance(levels, list) or not all(isinstance(n, int) and not isinstance(n, bool) for n in levels):
            raise SpecError(f"{where}: levels: expected a list of storey numbers, got {levels!r}")
        if level not in levels:
            return None
        return {k: v for k, v in entry.items() if k != "levels"}
    return entry


def _storey(spec: dict, where: str, level: int) -> Layout:
    """Storey ``level`` (0 = ground floor): rooms and doors; room names start with ``l<level>_``.

    First the south band's offices, one per ``CELL`` where no room of the spec stands (the
    ground floor's reception takes two), office k with poster k mod 3; then the spec's rooms."""
    p = f"l{level}_"
    types = spec.get("room_types", {})
    rooms = []
    for i, e in enumerate(spec["rooms"]):
        e = _on_storey(e, f"{where}: rooms[{i}]", level)
        if e is not None:
            named = {**e, "name": p + e["name"]} if isinstance(e.get("name"), str) else e
            rooms.append(build_room(named, f"{where}: rooms[{i}]", types, {"stair": HOLE}))
    corridor = p + "corridor"
    offices, doors = [], []
    for i in range(int(FOOTPRINT[2] / CELL)):
        x0, x1 = i * CELL, i * CELL + CELL
        if any(r.bounds[0] < x1 and x0 < r.bounds[2] and r.bounds[1] < SOUTH for r in rooms):
            continue
        poster = spec["office_posters"][len(offices) % len(spec["office_posters"])]
        entry = {"name": f"{p}office_{i + 1:02d}", "room_type": "office", "bounds": (x0, 0.0, x1, SOUTH), "pictures": [poster]}
        offices.append(build_room(entry, f"{where}: office {i + 1}", types))
        doors.append(Door(offices[-1].name, corridor, at=0.25))
    for k, e in enumerate(spec.get("doors", [])):
        e = _on_storey(e, f"{where}: doors[{k}]", level)
        if e is not None:
            doors.append(build_door(e, f"{where}: doors[{k}]", prefix=p))
    what = "ground floor" if level == 0 else f"floor {level}"
    return Layout(spec["name"], what, tuple(offices + rooms), doors=tuple(doors), ceiling_height=CEILING_HEIGHT,
                  floor_z=level * STOREY_HEIGHT)


def campus_plan() -> Building:
    """The campus storeys (ground floor, upper floor)."""
    spec, where = read_spec("campus")
    check_keys(spec, where, ("name", "description", "office_posters", "rooms"), ("doors", "room_types"))
    for key in ("office_posters", "rooms", "doors"):
        if not isinstance(spec.get(key, []), list) or not spec.get(key, [None]):
            raise SpecError(f"{where}: {key}: expected a non-empty list, got {spec[key]!r}")
    storeys = tuple(_storey(spec, where, level) for level in range(STOREYS))
    area = sum(s.floor_area for s in storeys)
    offices = sum(r.template == "office" for s in storeys for r in s.rooms)
    return Building(spec["name"], spec["description"].format(area=area, offices=offices), storeys, slab_thickness=SLAB)


def twin_pairs(plan: Building) -> list[tuple[str, str]]:
    """Pairs (first, other) of rooms identical up to a translation: same template, size and
    contents, doors at the same room-local places (the first room of each group with each other)."""
    def door_key(layout: Layout, room: RoomSpec):
        x0, y0 = room.bounds[0], room.bounds[1]
        out = []
        for d in layout.doors:
            if room.name in (d.a, d.b):
                orient, line, g0, g1 = door_span(layout, d)
                o = (x0, y0) if orient == "v" else (y0, x0)  # (across, along) origin
                out.append((orient, round(line - o[0], 6), round(g0 - o[1], 6), round(g1 - o[1], 6), d.height))
        return tuple(sorted(out))

    groups: dict = {}
    for layout in plan.storeys:
        for room in layout.rooms:
            x0, y0, x1, y1 = room.bounds
            shape = replace(room, name="", bounds=(0.0, 0.0, round(x1 - x0, 6), round(y1 - y0, 6)))
            if room.template is not None:
                groups.setdefault((shape, door_key(layout, room)), []).append(room.name)
    return [(names[0], other) for names in groups.values() for other in names[1:]]


# ----------------------------------------------------------------------------------------------
# geometry beyond the storey layouts


def _add_stair(mb: MeshBuilder, pal: dict[str, Material], side: Material) -> None:
    """Steps 1..14 as closed solids: a riser band and a tread, a side face down to the floor on
    the open (west) side; the last step's back face faces the hall. The 15th riser is the slab
    edge (:func:`_add_slab`)."""
    x0, x1 = STAIR_X
    for k in range(1, RISERS):
        ya, yb = STAIR_FOOT_Y - k * GOING, STAIR_FOOT_Y - (k - 1) * GOING
        add_box(mb, (x0, ya, (k - 1) * RISE), (x1, yb, k * RISE), {"+y": pal["trim"], "+z": pal["wood"]}, None, skip=())
        faces = {"-x": side, "-y": side} if k == RISERS - 1 else {"-x": side}
        add_box(mb, (x0, ya, 0.0), (x1, yb, k * RISE), faces, None, skip=())


def _add_slab(mb: MeshBuilder, pal: dict[str, Material], stair_wall: Material) -> None:
    """Slab edges between the storeys (z from 2.7 to 3.0): a band continuing the exterior wall
    faces, and the faces of the stair opening (the arrival side is the 15th riser)."""
    add_slab_edges(mb, FOOTPRINT, HOLE, CEILING_HEIGHT, STOREY_HEIGHT, HT, pal["exterior"], stair_wall, pal["trim"],
                   arrival="-y", rise=RISE)


def _add_balustrade(mb: MeshBuilder, pal: dict[str, Material]) -> None:
    """A solid 1 m balustrade on the upper floor along the opening's west and north edges."""
    t, h = BALUSTRADE
    hx0, hy0, hx1, hy1 = HOLE
    z = STOREY_HEIGHT
    mats = {"+z": pal["wood"], "*": pal["trim"]}
    add_box(mb, (hx0 - t, hy0, z), (hx0, hy1 + t, z + h), mats, None)
    # the north part abuts the west part and the east wall: those faces are hidden
    add_box(mb, (hx0, hy1, z), (hx1, hy1 + t, z + h), mats, None, skip=("-z", "-x", "+x"))


def build_campus(seed: int = 0) -> Scene:
    """Build the ``campus`` scene (deterministic in ``seed``); see the module docstring."""
    plan = campus_plan()
    bank = tx.TextureBank(seed)
    mb = MeshBuilder(plan.name, bank, texture_fns())
    pal = palette()
    for storey in plan.storeys:
        add_layout(mb, storey, pal, seed)
    stair_wall = wall_material(mb, next(r for r in plan.rooms if r.name == "l0_stair_hall").wall_color)
    with mb.labelled("stair"):
        _add_stair(mb, pal, stair_wall)
    with mb.labelled("wall"):  # the slab's edges continue the walls
        _add_slab(mb, pal, stair_wall)
    with mb.labelled("balustrade"):
        _add_balustrade(mb, pal)
    parts = mb.parts()
    meta = {
        "storeys": [float(s.floor_z) for s in plan.storeys],
        "storey_height": STOREY_HEIGHT,
        "ceiling_height": CEILING_HEIGHT,
        "slab_thickness": SLAB,
        "stair": {"x": [HOLE[0], HOLE[2]], "y": [HOLE[1], HOLE[3]], "bottom_z": 0.0, "top_z": STOREY_HEIGHT,
                  "risers": RISERS, "rise": RISE, "going": GOING, "up": "-y"},
        "slab_openings": [list(HOLE)],
        "templates": {r.name: r.template for r in plan.rooms if r.template is not None},
        "twins": [list(p) for p in twin_pairs(plan)],
        "seed": int(seed),
    }
    rooms = tuple(r for s in plan.storeys for r in layout_rooms(s))
    log.debug("built campus: %d parts, %d faces, %d textures", len(parts), sum(len(p.faces) for p in parts), len(bank))
    return Scene(name=plan.name, parts=tuple(parts), rooms=rooms, floor_z=0.0, source="builtin:campus", meta=meta)
