"""Layout description of the procedural interiors: rooms, furniture items, pictures, doors.

World frame: z up, metres. Room bounds are wall centre lines; furniture and pictures are in
room-local coordinates (metres from the room's (xmin, ymin) corner). A :class:`Layout` is one
interior or one storey of a building (its ``floor_z``); :mod:`.procedural` turns it into meshes.
A :class:`Building` is a multi-storey built-in: one layout per storey (:mod:`.house`, :mod:`.campus`).
Windows and doors with a leaf are :class:`Opening` of one room's wall (usually an outside wall);
a :class:`Door` is an open doorway between two rooms.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from markerplace.scene.builtin.furniture import FURNITURE

__all__ = ["Building", "Door", "Item", "Layout", "Opening", "OPENING_KINDS", "Picture", "RoomSpec", "chairs_around",
           "desk_cluster", "wall_item", "workstation"]


@dataclass(frozen=True)
class Item:
    """A piece of furniture. ``kind`` is a key of :data:`.furniture.FURNITURE`; (x, y) its footprint centre in
    room-local metres; ``yaw_deg`` its rotation (0: front faces -y); ``variant`` picks colours."""

    kind: str
    x: float
    y: float
    yaw_deg: float = 0.0
    variant: int = 0


@dataclass(frozen=True)
class Picture:
    """A framed picture or poster on a room wall.

    Attributes:
        wall: ``"N"`` (y max), ``"S"`` (y min), ``"E"`` (x max) or ``"W"`` (x min).
        along: room-local coordinate of the picture centre along the wall (x for N/S, y for E/W).
        width: picture width in metres (height follows the image aspect ratio).
        image: a bundled photo name (:data:`textures.BUNDLED_PHOTOS`) or ``"art:<k>"`` for
            procedural art number k, or ``"whiteboard"``.
        z_center: height of the picture centre above the room's floor (default 1.5 m, eye level).
    """

    wall: str
    along: float
    width: float
    image: str
    z_center: float = 1.5


OPENING_KINDS = ("window", "door", "glass_door")
"""Kinds of :class:`Opening`: a glazed window, an opaque door leaf, a glazed door."""


@dataclass(frozen=True)
class Opening:
    """A window or a door (with its leaf, closed) set into one of a room's walls.

    Built by :func:`markerplace.scene.builtin.walls.build_openings`: the wall gets a hole from ``sill``
    to ``top`` above the room's floor; a ``window`` fills it with a frame and a glass pane, a
    ``glass_door`` likewise down to the floor, a ``door`` with an opaque leaf set into the middle
    of the wall's thickness (its faces 3 cm behind the wall's). Meant for outside walls: a closed
    door between two rooms would cut them apart (use :class:`Door` for a doorway).

    Attributes:
        wall: ``"N"``, ``"S"``, ``"E"`` or ``"W"`` (as :class:`Picture`).
        along: room-local coordinate of its centre along the wall (x for N/S, y for E/W), metres.
        width: clear width, metres.
        kind: one of :data:`OPENING_KINDS`.
        sill: bottom of the opening above the room's floor, metres (doors: 0).
        top: top of the opening above the room's floor, metres.
    """

    wall: str
    along: float
    width: float
    kind: str = "window"
    sill: float = 0.9
    top: float = 2.1


@dataclass(frozen=True)
class RoomSpec:
    """A room: footprint (xmin, ymin, xmax, ymax) on wall centre lines, floor and wall finish.

    Attributes:
        floor: ``"wood"``, ``"tiles"``, ``"carpet"`` or ``"wood_dark"``.
        wall_color: RGB 0-255 paint colour of its walls (inside faces).
        items / pictures: contents in room-local coordinates.
        template: rooms with the same template get identical seeded jitter (twins).
        lights: number of ceiling light panels (panels over a ceiling hole are left out).
        floor_dz: height of the room's floor relative to its storey's floor, metres (-0.25: a
            sunken room one step down). Walls reach down to the lower floor on either side, and
            an opening between floors of different heights gets a step (see :class:`Door`).
        floor_holes / ceiling_holes: world (xmin, ymin, xmax, ymax) rectangles cut out of the
            room's floor / ceiling quad (a stairwell); they must lie inside the room's bounds.
        openings: windows and doors in the room's walls (:class:`Opening`).
    """

    name: str
    bounds: tuple[float, float, float, float]
    floor: str = "wood"
    wall_color: tuple[int, int, int] = (232, 228, 218)
    items: tuple[Item, ...] = ()
    pictures: tuple[Picture, ...] = ()
    template: str | None = None
    lights: int = 2
    floor_dz: float = 0.0
    floor_holes: tuple[tuple[float, float, float, float], ...] = ()
    ceiling_holes: tuple[tuple[float, float, float, float], ...] = ()
    openings: tuple[Opening, ...] = ()


@dataclass(frozen=True)
class Door:
    """An opening (no door leaf, no glass) in the wall shared by rooms ``a`` and ``b``.

    ``at`` is the fraction along the shared wall segment of the opening centre (default 0.5);
    ``width`` defaults to 0.95 m and ``height`` to 2.1 m (a lintel closes the wall above; a
    height of at least the ceiling height leaves the opening open to the ceiling). When the two
    rooms' floors differ (``RoomSpec.floor_dz``), a step fills the opening below the higher floor:
    a box on the lower room's half of the wall, its riser flush with the lower room's wall faces.
    """

    a: str
    b: str
    at: float = 0.5
    width: float = 0.95
    height: float = 2.1


@dataclass(frozen=True)
class Layout:
    """A whole interior (or one storey of a building): rooms, doors, wall thickness (0.1 m),
    ceiling height (2.7 m, above ``floor_z``) and ``floor_z``, the height of the storey's floor
    (world metres; room floors are at ``floor_z + RoomSpec.floor_dz``)."""

    name: str
    description: str
    rooms: tuple[RoomSpec, ...]
    doors: tuple[Door, ...] = ()
    wall_thickness: float = 0.1
    ceiling_height: float = 2.7
    twins: tuple[tuple[str, str], ...] = field(default=())
    floor_z: float = 0.0

    @property
    def floor_area(self) -> float:
        """Sum of room footprints in m^2 (on wall centre lines)."""
        return float(sum((r.bounds[2] - r.bounds[0]) * (r.bounds[3] - r.bounds[1]) for r in self.rooms))


@dataclass(frozen=True)
class Building:
    """A multi-storey built-in: one :class:`Layout` per storey (ascending ``floor_z``).

    ``rooms`` and ``floor_area`` cover all storeys, so the catalogue lists it like a layout.
    """

    name: str
    description: str
    storeys: tuple[Layout, ...]
    slab_thickness: float

    @property
    def rooms(self) -> tuple[RoomSpec, ...]:
        return tuple(r for s in self.storeys for r in s.rooms)

    @property
    def floor_area(self) -> float:
        """Sum of the room footprints of all storeys, m^2 (on wall centre lines)."""
        return float(sum(s.floor_area for s in self.storeys))


# ----------------------------------------------------------------------------------------------
# helpers for writing layouts


HALF_WALL = 0.05  # half of the default wall thickness
WALL_GAP = 0.02  # furniture stands this far from the wall surface


def wall_item(kind: str, room_size: tuple[float, float], wall: str, along: float, variant: int = 0) -> Item:
    """An item standing against wall ``N/S/E/W`` of a room of size (width, depth), facing inwards.

    ``along`` is the room-local coordinate of its centre along the wall (x for N/S, y for E/W).
    """
    w, d = room_size
    depth = FURNITURE[kind][2]
    off = HALF_WALL + WALL_GAP + depth / 2
    if wall == "N":
        return Item(kind, along, d - off, 0.0, variant)
    if wall == "S":
        return Item(kind, along, off, 180.0, variant)
    if wall == "E":
        return Item(kind, w - off, along, -90.0, variant)
    if wall == "W":
        return Item(kind, off, along, 90.0, variant)
    raise ValueError(f"wall must be N, S, E or W, not {wall!r}")


def workstation(x: float, y: float, yaw_deg: float) -> tuple[Item, ...]:
    """Desk + monitor + chair; desk centre (x, y) room-local, the user sits on the desk's front side."""
    a = np.radians(yaw_deg)
    dx, dy = 0.65 * np.sin(a), -0.65 * np.cos(a)  # chair in front of the desk
    return (
        Item("desk", x, y, yaw_deg),
        Item("monitor", x, y, yaw_deg),
        Item("chair", round(x + dx, 4), round(y + dy, 4), yaw_deg + 180.0),
    )


def chairs_around(x: float, y: float, half_depth: float, xs: tuple[float, ...]) -> tuple[Item, ...]:
    """Chairs on both long sides of a table centred at (x, y), facing it."""
    out = []
    for cx in xs:
        out.append(Item("chair", x + cx, y - half_depth - 0.3, 180.0))
        out.append(Item("chair", x + cx, y + half_depth + 0.3, 0.0))
    return tuple(out)


def desk_cluster(x: float, y: float, xs: tuple[float, ...]) -> tuple[Item, ...]:
    """Workstations in facing pairs about the line y: for each offset dx in ``xs``, one at
    (x + dx, y - 0.35) facing -y and one at (x + dx, y + 0.35) facing +y."""
    out: list[Item] = []
    for dx in xs:
        out += workstation(x + dx, y - 0.35, 0.0)
        out += workstation(x + dx, y + 0.35, 180.0)
    return tuple(out)
