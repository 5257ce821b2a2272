"""The built-in ``house``: a two-storey house with a stair, a sunken living room, a glass wall,
windows, a glass door and a front door.

World frame: z up, metres, ground floor at z = 0; footprint x in [0, 10.5], y in [0, 7.5] (wall
centre lines), 78.75 m^2 per storey, 157.5 m^2 in all. Storey height 3.0 m: ceilings 2.7 m above
each storey floor, then a 0.3 m floor slab; upper floor at z = 3.0, roof ceiling at z = 5.7.

Ground floor (z = 0)::

    y=7.5 +---------------------+------------------------------+
          |                     |  stairs: 15 risers up to -x  |  <- wall at y = 6.35
          |  kitchen            +----------------------+ open -+
          |  (island, dining)   door    hall           |       |
    y=4.0 +--- open, 1 step ----+-----------door-------+-------+
          |  living, sunken     |                              |
          |  0.25 m (z = -0.25) glass       sunroom            |
          |                     | wall                         |
    y=0   +---------------------+------------------------------+
         x=0                   x=6.0                         x=10.5

Upper floor (z = 3.0): study [0, 4.5, 3.5, 7.5], landing [3.5, 4.5, 10.5, 7.5] with the stair
opening in its north-east (a 1 m balustrade on its open sides), master bedroom [0, 0, 5, 4.5],
bedroom [5, 0, 8, 4.5], bathroom [8, 0, 10.5, 4.5] behind a 0.7 m doorway from the landing.

The stair runs along the north wall in ``stairs`` (x in [6.05, 9.41], y in [6.40, 7.45], between
the exterior wall and a partition): 15 risers of 0.2 m, 14 treads of 0.24 m, first riser at
x = 9.41 facing +x, arriving on the landing at x = 6.05 going -x. Steps are solid (treads and
risers close the volume against the walls and the floor). The slab has an opening right above the
stair, with slab edge faces; the ground stair room's ceiling and the landing's floor have the
same hole.

Windows (:class:`~.layout.Opening`, sill 0.9 m, top 2.1 m): kitchen north above the counter
(sill 1.05 m), master bedroom south, study north. A glass door from the sunroom (south wall) and
an opaque front door in the hall's east wall, both 0.9 m wide and 2.1 m high.

Everything else (walls, floors, ceilings, lights, furniture, pictures, windows and doors) comes
from :func:`markerplace.scene.builtin.procedural.add_layout`, one :class:`Layout` per storey.
The storeys' rooms, furniture, pictures, windows and doorways are data, in
``scene/builtin/specs/house.toml`` (TOML, format in its header and in :mod:`.spec_loader`);
this module adds the storey heights and the stair opening (``"stair"`` in the file: :data:`HOLE`).

``Scene.meta`` keys (world metres; x/y spans are [min, max]):

* ``storeys``: storey floor heights, ascending (``[0.0, 3.0]``); ``storey_height``,
  ``ceiling_height`` (above each storey floor), ``slab_thickness``.
* ``sunken_room``: name of the sunken room (``"living"``); ``sunken_floor_z`` (-0.25);
  ``sunken_opening``: the open side towards it, ``{"rooms", "orient", "line", "span",
  "step_height"}`` (``orient`` ``"h"``: a wall along x at y = ``line``; ``span``: its x extent).
* ``glass_parts``: names of the transparent parts (the glass wall's, the windows' and the glass
  door's); ``glass_wall``: ``{"rooms", "orient", "line", "span", "z", "parts"}`` of the glazed
  opening (``z``: bottom and top of the glass; ``parts``: its transparent parts).
* ``narrow_door_room``: the room reached only through a narrow doorway (``"bathroom"``);
  ``narrow_door``: ``{"rooms", "orient", "line", "span", "width", "floor_z", "height"}``.
* ``stair``: ``{"x", "y", "bottom_z", "top_z", "risers", "rise", "going", "up"}`` (``up``: the
  climbing direction, ``"-x"``); ``slab_openings``: list of (xmin, ymin, xmax, ymax) holes in the
  slab between the storeys.
* ``twins`` (none), ``seed``.
"""

from __future__ import annotations

import logging

import numpy as np

from markerplace.scene.builtin import textures as tx
from markerplace.scene.builtin.furniture import palette, texture_fns
from markerplace.scene.builtin.layout import Building, Door, Layout
from markerplace.scene.builtin.meshkit import Material, MeshBuilder, add_box
from markerplace.scene.builtin.procedural import add_layout, layout_rooms, wall_material
from markerplace.scene.builtin.spec_loader import build_layout, check_keys, read_spec
from markerplace.scene.builtin.walls import add_slab_edges, door_span
from markerplace.scene.types import Scene

log = logging.getLogger(__name__)

__all__ = ["build_house", "house_plan"]

STOREY_HEIGHT = 3.0
CEILING_HEIGHT = 2.7
SLAB = 0.3  # STOREY_HEIGHT - CEILING_HEIGHT
HT = 0.05  # half wall thickness
# stair: 15 risers x 0.2 m, 14 treads x 0.24 m along the north wall, climbing towards -x
RISERS, RISE, GOING = 15, STOREY_HEIGHT / 15, 0.24
STAIR_Y = (6.40, 7.45)
STAIR_TOP_X = 6.05
STAIR_FOOT_X = STAIR_TOP_X + (RISERS - 1) * GOING  # 9.41: the first riser
HOLE = (STAIR_TOP_X, STAIR_Y[0], STAIR_FOOT_X, STAIR_Y[1])
BALUSTRADE = (0.1, 1.0)  # thickness, height
GLASS_PANES = 4
FRAME = 0.05  # glazing frame members: width (and rail height)


def house_plan() -> Building:
    """The house's storeys (ground floor, upper floor), their rooms and doors from ``specs/house.toml``."""
    spec, where = read_spec("house")
    check_keys(spec, where, ("name", "description", "storeys"))
    storeys = tuple(build_layout(s, f"{where}: storeys[{level}]", {"stair": HOLE}, name=spec["name"],
                                 ceiling_height=CEILING_HEIGHT, floor_z=level * STOREY_HEIGHT)
                    for level, s in enumerate(spec["storeys"]))
    return Building(spec["name"], spec["description"], storeys, slab_thickness=SLAB)


# ----------------------------------------------------------------------------------------------
# geometry beyond the storey layouts


def _add_stair(mb: MeshBuilder, pal: dict[str, Material]) -> None:
    """Treads and risers of the stair; the last riser is the slab edge (see :func:`_add_slab`)."""
    y0, y1 = STAIR_Y
    for k in range(1, RISERS):
        xa, xb = STAIR_FOOT_X - k * GOING, STAIR_FOOT_X - (k - 1) * GOING
        # one step: its riser (+x face) and tread (+z face); below it, the steps in front of it
        add_box(mb, (xa, y0, (k - 1) * RISE), (xb, y1, k * RISE), {"+x": pal["trim"], "+z": pal["wood"]}, None, skip=())


def _add_slab(mb: MeshBuilder, pal: dict[str, Material], stair_wall: Material, footprint) -> None:
    """Slab edges between the storeys (z from the ceiling, 2.7, to the upper floor, 3.0).

    The outer band continues the exterior wall faces; the stair opening's faces continue the
    stair room's walls, and its west face above the last tread is the stair's 15th riser.
    ``footprint`` is (xmin, ymin, xmax, ymax) on the exterior walls' centre lines.
    """
    add_slab_edges(mb, footprint, HOLE, CEILING_HEIGHT, STOREY_HEIGHT, HT, pal["exterior"], stair_wall, pal["trim"],
                   arrival="-x", rise=RISE)


def _add_balustrade(mb: MeshBuilder, pal: dict[str, Material]) -> None:
    """A solid 1 m balustrade on the landing along the opening's south and east edges."""
    t, h = BALUSTRADE
    hx0, hy0, hx1, hy1 = HOLE
    z = STOREY_HEIGHT
    mats = {"+z": pal["wood"], "*": pal["trim"]}
    add_box(mb, (hx0, hy0 - t, z), (hx1 + t, hy0, z + h), mats, None)
    # the east part abuts the south part and the north wall: those faces are hidden
    add_box(mb, (hx1, hy0, z), (hx1 + t, hy1, z + h), mats, None, skip=("-z", "-y", "+y"))


def _add_glazing(mb: MeshBuilder, pal: dict[str, Material], orient: str, line: float, g0: float, g1: float, z0: float, z1: float) -> None:
    """Fill the opening [g0, g1] of the wall line ``x = line`` (``orient`` "v") with glass.

    A dark frame (bottom and top rails, mullions between ``GLASS_PANES`` panes, ``FRAME`` wide,
    the wall's thickness deep) and one transparent quad per pane on the wall's centre plane,
    its normal +x. The opening's jambs are the walls' end caps.
    """
    if orient != "v":
        raise ValueError("glazing is implemented for walls along y only")
    frame, glass = pal["glass_frame"], pal["glass"]
    a, b = line - HT, line + HT
    add_box(mb, (a, g0, z0), (b, g1, z0 + FRAME), frame, None)  # bottom rail on the step/kerb
    add_box(mb, (a, g0, z1 - FRAME), (b, g1, z1), frame, None, skip=("+z",))  # top rail
    edges = np.linspace(g0, g1, GLASS_PANES + 1)
    for m in edges[1:-1]:
        add_box(mb, (a, m - FRAME / 2, z0 + FRAME), (b, m + FRAME / 2, z1 - FRAME), frame, None, skip=("+z", "-z"))
    lo = [g0] + [m + FRAME / 2 for m in edges[1:-1]]
    hi = [m - FRAME / 2 for m in edges[1:-1]] + [g1]
    za, zb = z0 + FRAME, z1 - FRAME
    for p, q in zip(lo, hi):
        corners = np.array([[line, p, za], [line, q, za], [line, q, zb], [line, p, zb]])
        uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        mb.quad(glass, corners, uv, (1.0, 0.0, 0.0))


def _opening(layout: Layout, a: str, b: str) -> tuple[Door, tuple[str, float, float, float]]:
    """The door between rooms a and b and its (orient, line, start, end), rounded to 1 um."""
    door = next(d for d in layout.doors if {d.a, d.b} == {a, b})
    orient, line, g0, g1 = door_span(layout, door)
    return door, (orient, round(line, 6), round(g0, 6), round(g1, 6))


def build_house(seed: int = 0) -> Scene:
    """Build the ``house`` scene (deterministic in ``seed``); see the module docstring."""
    plan = house_plan()
    ground, upper = plan.storeys
    bank = tx.TextureBank(seed)
    mb = MeshBuilder(plan.name, bank, texture_fns())
    pal = palette()
    for storey in plan.storeys:
        add_layout(mb, storey, pal, seed)
    stairs = next(r for r in ground.rooms if r.name == "stairs")
    with mb.labelled("stair"):
        _add_stair(mb, pal)
    with mb.labelled("wall"):  # the slab's edges continue the walls
        _add_slab(mb, pal, wall_material(mb, stairs.wall_color), (0.0, 0.0, 10.5, 7.5))
    with mb.labelled("balustrade"):
        _add_balustrade(mb, pal)
    _, (g_or, g_line, g0, g1) = _opening(ground, "living", "sunroom")
    with mb.labelled("glazing"):
        _add_glazing(mb, pal, g_or, g_line, g0, g1, ground.floor_z, ground.floor_z + CEILING_HEIGHT)
    parts = mb.parts()

    sunken = -next(r for r in ground.rooms if r.name == "living").floor_dz
    _, (s_or, s_line, s0, s1) = _opening(ground, "kitchen", "living")
    narrow, (n_or, n_line, n0, n1) = _opening(upper, "bathroom", "landing")
    meta = {
        "storeys": [float(s.floor_z) for s in plan.storeys],
        "storey_height": STOREY_HEIGHT,
        "ceiling_height": CEILING_HEIGHT,
        "slab_thickness": SLAB,
        "sunken_room": "living",
        "sunken_floor_z": -sunken,
        "sunken_opening": {"rooms": ["kitchen", "living"], "orient": s_or, "line": s_line, "span": [s0, s1], "step_height": sunken},
        "glass_parts": [p.name for p in parts if p.transparent],
        "glass_wall": {"rooms": ["living", "sunroom"], "orient": g_or, "line": g_line, "span": [g0, g1],
                       "z": [round(ground.floor_z + FRAME, 6), round(ground.floor_z + CEILING_HEIGHT - FRAME, 6)],
                       "parts": [p.name for p in parts if p.transparent and "glazing" in p.names]},
        "narrow_door_room": "bathroom",
        "narrow_door": {"rooms": ["bathroom", "landing"], "orient": n_or, "line": n_line, "span": [n0, n1],
                        "width": narrow.width, "floor_z": upper.floor_z, "height": narrow.height},
        "stair": {"x": [HOLE[0], HOLE[2]], "y": [HOLE[1], HOLE[3]], "bottom_z": ground.floor_z, "top_z": upper.floor_z,
                  "risers": RISERS, "rise": RISE, "going": GOING, "up": "-x"},
        "slab_openings": [list(HOLE)],
        "twins": [],
        "seed": int(seed),
    }
    rooms = layout_rooms(ground) + layout_rooms(upper)
    log.debug("built house: %d parts, %d faces, %d textures", len(parts), sum(len(p.faces) for p in parts), len(bank))
    return Scene(name=plan.name, parts=tuple(parts), rooms=rooms, floor_z=float(ground.floor_z), source="builtin:house", meta=meta)
