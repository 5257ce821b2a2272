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
from markerplace.scene.builtin.layout import Building, Door, Item, Layout, Picture, RoomSpec, chairs_around, wall_item, workstation
from markerplace.scene.builtin.meshkit import Material, MeshBuilder, add_box
from markerplace.scene.builtin.procedural import add_layout, layout_rooms, wall_material
from markerplace.scene.types import Scene
from markerplace.scene.builtin.walls import door_span

log = logging.getLogger(__name__)

__all__ = ["campus_plan", "build_campus", "twin_pairs", "STOREY_HEIGHT", "CEILING_HEIGHT", "SLAB", "FOOTPRINT", "HOLE"]

FOOTPRINT = (0.0, 0.0, 48.0, 21.5)
STOREY_HEIGHT = 3.0
CEILING_HEIGHT = 2.7
SLAB = STOREY_HEIGHT - CEILING_HEIGHT
STOREYS = 2
CELL = 4.0  # office width
SOUTH, CORRIDOR, NORTH = 5.5, 7.5, 21.5  # y of the office band's top, the corridor's top, the north wall
MID = 14.5  # y of the partition between the north band's front and back rooms
OPEN_A, OPEN_B = (0.0, 16.0), (26.0, 42.0)  # x spans of the open-plan areas
MEET_X, CORE_X, EAST_X = (16.0, 22.0), (22.0, 26.0), (42.0, 48.0)
RECEPTION = (5, 7)  # ground floor: office cells [5, 7) are the reception
POSTERS = ("art:11", "art:12", "art:13")  # office posters cycle through these
# stair: 15 risers x 0.2 m, 14 treads x 0.24 m along the stair hall's east wall, climbing -y
RISERS, RISE, GOING = 15, STOREY_HEIGHT / 15, 0.24
STAIR_X = (CORE_X[1] - 0.05 - 1.2, CORE_X[1] - 0.05)  # 1.2 m wide, against the east wall
STAIR_FOOT_Y = MID - 0.05 - 1.0  # first riser; 1 m to stand in before it
STAIR_TOP_Y = round(STAIR_FOOT_Y - (RISERS - 1) * GOING, 6)
HOLE = (STAIR_X[0], STAIR_TOP_Y, STAIR_X[1], STAIR_FOOT_Y)
BALUSTRADE = (0.1, 1.0)  # thickness, height
HT = 0.05  # half wall thickness
STAIR_WALL = (232, 232, 226)
OPEN_DOOR = CEILING_HEIGHT + 1.0  # a door at least this high is an opening up to the ceiling


# ----------------------------------------------------------------------------------------------
# room templates (room-local coordinates: metres from the room's (xmin, ymin) corner)


def _office(name: str, x0: float, poster: str) -> RoomSpec:
    """One 4 m x 5.5 m office of the south band; its door is in the north wall, 1 m from the west."""
    size = (CELL, SOUTH)
    return RoomSpec(
        name,
        (x0, 0.0, x0 + CELL, SOUTH),
        floor="carpet",
        wall_color=(236, 234, 228),
        items=(
            *workstation(2.0, 0.45, 180.0),
            wall_item("bookshelf", size, "E", 3.0),
            wall_item("cabinet", size, "W", 1.0),
            Item("plant", 3.45, 4.95),
        ),
        pictures=(Picture("W", 3.2, 0.8, poster),),
        template="office",
        lights=1,
    )


def _reception(name: str) -> RoomSpec:
    x0, x1 = RECEPTION[0] * CELL, RECEPTION[1] * CELL
    size = (x1 - x0, SOUTH)
    return RoomSpec(
        name,
        (x0, 0.0, x1, SOUTH),
        floor="wood",
        wall_color=(240, 236, 226),
        items=(
            *workstation(3.3, 2.0, 0.0),
            *workstation(4.7, 2.0, 0.0),
            wall_item("sofa", size, "W", 3.5),
            Item("coffee_table", 1.7, 3.5, 90.0),
            Item("plant", 7.45, 0.5),
            Item("plant", 7.45, 4.2),
        ),
        pictures=(Picture("S", 4.0, 1.6, "logo"), Picture("E", 2.75, 1.0, "hubble")),
        lights=2,
    )


def _corridor(name: str, level: int) -> RoomSpec:
    """The 48 m corridor; pictures hang between the doors (a different set on each storey)."""
    photos = (("rocket", "camera", "moon", "coins", "retina"), ("chelsea", "clock", "motorcycle", "ihc", "gravel"))[level % 2]
    south = [Picture("S", i * CELL + 3.0, 1.0, photos[k % len(photos)]) for k, i in enumerate((1, 3, 8, 10))]
    north = [Picture("N", x, 1.2, photos[(k + 2) % len(photos)]) for k, x in enumerate((3.0, 13.0, 29.0, 39.0))]
    return RoomSpec(name, (0.0, SOUTH, FOOTPRINT[2], CORRIDOR), floor="tiles", wall_color=(240, 240, 236),
                    pictures=(*south, *north), lights=8)


def _open_plan(name: str, x0: float) -> RoomSpec:
    """A 16 m x 14 m open-plan area: three clusters of four desks, a lounge, shelves, a printer."""
    size = (16.0, NORTH - CORRIDOR)
    desks = []
    for cx, cy in ((3.2, 4.2), (3.2, 9.8), (12.8, 9.8)):
        for dx in (-0.7, 0.7):
            desks += workstation(cx + dx, cy - 0.35, 0.0)
            desks += workstation(cx + dx, cy + 0.35, 180.0)
    lounge = (
        Item("rug", 12.8, 4.4),
        Item("coffee_table", 12.8, 4.2),
        Item("sofa", 12.8, 5.3, 0.0),
        Item("armchair", 11.6, 4.2, 90.0),
        Item("armchair", 14.0, 4.2, -90.0),
    )
    return RoomSpec(
        name,
        (x0, CORRIDOR, x0 + size[0], NORTH),
        floor="carpet",
        wall_color=(234, 236, 232),
        items=(
            *desks,
            *lounge,
            wall_item("bookshelf", size, "N", 6.5),
            wall_item("bookshelf", size, "N", 7.45),
            wall_item("printer", size, "N", 9.3),
            wall_item("cabinet", size, "W", 7.0),
            Item("plant", 0.5, 13.5),
            Item("plant", 15.5, 0.5),
        ),
        pictures=(
            Picture("N", 3.2, 2.0, "whiteboard"),
            Picture("N", 12.8, 1.2, "art:21"),
            Picture("W", 4.2, 1.0, "art:22"),
            Picture("E", 7.0, 0.8, "astronaut"),
        ),
        template="open_plan",
        lights=6,
    )


def _meeting(name: str, x0: float, y0: float) -> RoomSpec:
    """A 6 m x 7 m meeting room: a big table with four chairs, a TV, a whiteboard."""
    size = (6.0, 7.0)
    return RoomSpec(
        name,
        (x0, y0, x0 + size[0], y0 + size[1]),
        floor="wood",
        wall_color=(226, 231, 236),
        items=(
            Item("big_table", 3.0, 3.5),
            *chairs_around(3.0, 3.5, 0.55, (-0.6, 0.6)),
            wall_item("tv_stand", size, "N", 3.0),
        ),
        pictures=(Picture("E", 3.5, 1.6, "whiteboard"), Picture("S", 1.2, 0.8, "brick")),
        template="meeting",
        lights=2,
    )


def _kitchen(name: str) -> RoomSpec:
    size = (6.0, 7.0)
    return RoomSpec(
        name,
        (EAST_X[0], CORRIDOR, EAST_X[1], MID),
        floor="tiles",
        wall_color=(240, 233, 216),
        items=(
            wall_item("counter", size, "E", 2.0),
            wall_item("fridge", size, "E", 3.8),
            Item("table", 3.0, 5.2),
            *chairs_around(3.0, 5.2, 0.45, (-0.4, 0.4)),
            Item("plant", 0.5, 6.5),
        ),
        pictures=(Picture("N", 3.0, 0.8, "coffee"),),
        lights=2,
    )


def _copy_room(name: str) -> RoomSpec:
    size = (4.0, 7.0)
    return RoomSpec(
        name,
        (CORE_X[0], MID, CORE_X[1], NORTH),
        floor="tiles",
        wall_color=(230, 230, 225),
        items=(
            wall_item("printer", size, "N", 2.0),
            wall_item("bookshelf", size, "E", 2.5),
            wall_item("bookshelf", size, "E", 3.45),
            wall_item("bookshelf", size, "E", 4.4),
            wall_item("cabinet", size, "W", 4.0),
        ),
        pictures=(Picture("W", 2.0, 0.6, "page"),),
        template="copy_room",
        lights=1,
    )


def _stair_hall(name: str, level: int) -> RoomSpec:
    """The stair hall: the ground floor's has the flight and a ceiling opening above it, the
    upper floor's the opening in its floor."""
    holes = {"ceiling_holes": (HOLE,)} if level == 0 else {"floor_holes": (HOLE,)}
    return RoomSpec(name, (CORE_X[0], CORRIDOR, CORE_X[1], MID), floor="wood_dark", wall_color=STAIR_WALL,
                    pictures=(Picture("W", 4.5, 0.8, "text"),), lights=1, **holes)


# ----------------------------------------------------------------------------------------------
# storeys


def _storey(level: int) -> Layout:
    """Storey ``level`` (0 = ground floor): rooms and doors; room names start with ``l<level>_``."""
    p = f"l{level}_"
    rooms, doors = [], []
    corridor = p + "corridor"
    cells = [i for i in range(int(FOOTPRINT[2] / CELL)) if level > 0 or not RECEPTION[0] <= i < RECEPTION[1]]
    for k, i in enumerate(cells):
        office = _office(f"{p}office_{i + 1:02d}", i * CELL, POSTERS[k % len(POSTERS)])
        rooms.append(office)
        doors.append(Door(office.name, corridor, at=0.25))
    if level == 0:
        rooms.append(_reception(p + "reception"))
        doors.append(Door(corridor, p + "reception", width=4.0, height=OPEN_DOOR))
    rooms.append(_corridor(corridor, level))
    names = {"open_a": OPEN_A[0], "open_b": OPEN_B[0]}
    for key, x0 in names.items():
        rooms.append(_open_plan(p + key, x0))
        doors.append(Door(corridor, p + key, width=4.0, height=OPEN_DOOR))
    rooms += [
        _meeting(p + "meeting_a", MEET_X[0], CORRIDOR),
        _meeting(p + "meeting_b", MEET_X[0], MID),
        _meeting(p + "meeting_c", EAST_X[0], MID),
        _kitchen(p + "kitchen"),
        _stair_hall(p + "stair_hall", level),
        _copy_room(p + "copy_room"),
    ]
    doors += [
        Door(p + "meeting_a", corridor),
        Door(p + "open_a", p + "meeting_a"),
        Door(p + "open_a", p + "meeting_b"),
        Door(p + "open_b", p + "meeting_c"),
        Door(p + "open_b", p + "kitchen"),
        Door(p + "kitchen", corridor),
        Door(p + "stair_hall", corridor, at=0.3),
        Door(p + "copy_room", p + "stair_hall", at=0.3),
    ]
    what = "ground floor" if level == 0 else f"floor {level}"
    return Layout("campus", what, tuple(rooms), doors=tuple(doors), ceiling_height=CEILING_HEIGHT,
                  floor_z=level * STOREY_HEIGHT)


def campus_plan() -> Building:
    """The campus storeys (ground floor, upper floor)."""
    storeys = tuple(_storey(level) for level in range(STOREYS))
    area = sum(s.floor_area for s in storeys)
    offices = sum(r.template == "office" for s in storeys for r in s.rooms)
    return Building(
        "campus",
        f"a two-storey office building ({area:.0f} m^2) for scale tests: {offices} offices furnished alike, "
        "four open-plan areas, meeting rooms, kitchens, a stair",
        storeys,
        slab_thickness=SLAB,
    )


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
    x0, y0, x1, y1 = FOOTPRINT
    z0, z1 = CEILING_HEIGHT, STOREY_HEIGHT
    band = {"-y": (x0 - HT, y0 - HT, x1 + HT, y0 + HT), "+y": (x0 - HT, y1 - HT, x1 + HT, y1 + HT),
            "-x": (x0 - HT, y0 - HT, x0 + HT, y1 + HT), "+x": (x1 - HT, y0 - HT, x1 + HT, y1 + HT)}
    for face, (a0, b0, a1, b1) in band.items():
        add_box(mb, (a0, b0, z0), (a1, b1, z1), {face: pal["exterior"]}, None, skip=())
    hx0, hy0, hx1, hy1 = HOLE
    # each face of the opening is the one inward-looking face of a box just outside that edge
    add_box(mb, (hx0, hy0 - HT, z1 - RISE), (hx1, hy0, z1), {"+y": pal["trim"]}, None, skip=())
    add_box(mb, (hx0 - HT, hy0, z0), (hx0, hy1, z1), {"+x": stair_wall}, None, skip=())
    add_box(mb, (hx0, hy1, z0), (hx1, hy1 + HT, z1), {"-y": stair_wall}, None, skip=())
    add_box(mb, (hx1, hy0, z0), (hx1 + HT, hy1, z1), {"-x": stair_wall}, None, skip=())


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
    stair_wall = wall_material(mb, STAIR_WALL)
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
