"""Procedural interiors: build a textured :class:`Scene` from a :class:`Layout` description.

World frame: z up, metres, floor at z = 0. A layout is a set of axis-aligned room rectangles whose
edges are wall centre lines, doors between pairs of rooms, and per-room furniture and pictures in
room-local coordinates (metres from the room's (xmin, ymin) corner), so two rooms with the same
contents are identical up to a translation.

Geometry is made of boxes and quads only (:mod:`.meshkit`). Parts are grouped by material
(texture + colour), so a whole scene is a few dozen :class:`MeshPart` and repeated items share one
texture array. Furniture builders, their local frame and the palette live in :mod:`.furniture`.
"""

from __future__ import annotations

import logging
import zlib
from dataclasses import dataclass, field

import numpy as np

from . import textures as tx
from .furniture import FLOORS, FURNITURE, MAX_FREE_HEIGHT, TALL_AGAINST_WALL, palette, texture_fns
from .meshkit import AXES, Material, MeshBuilder, add_box
from .types import Room, Scene

__all__ = [
    "FURNITURE", "Door", "Item", "Layout", "Material", "MeshBuilder", "Picture", "RoomSpec",
    "add_box", "build_scene", "validate_layout",
]

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------------------------
# layout description


@dataclass(frozen=True)
class Item:
    """A piece of furniture. ``kind`` is a key of :data:`FURNITURE`; (x, y) its footprint centre in
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
        z_center: height of the picture centre (default 1.5 m, eye level).
    """

    wall: str
    along: float
    width: float
    image: str
    z_center: float = 1.5


@dataclass(frozen=True)
class RoomSpec:
    """A room: footprint (xmin, ymin, xmax, ymax) on wall centre lines, floor and wall finish.

    Attributes:
        floor: ``"wood"``, ``"tiles"``, ``"carpet"`` or ``"wood_dark"``.
        wall_color: RGB 0-255 paint colour of its walls (inside faces).
        items / pictures: contents in room-local coordinates.
        template: rooms with the same template get identical seeded jitter (twins).
        lights: number of ceiling light panels.
    """

    name: str
    bounds: tuple[float, float, float, float]
    floor: str = "wood"
    wall_color: tuple[int, int, int] = (232, 228, 218)
    items: tuple[Item, ...] = ()
    pictures: tuple[Picture, ...] = ()
    template: str | None = None
    lights: int = 2


@dataclass(frozen=True)
class Door:
    """An opening (no door leaf, no glass) in the wall shared by rooms ``a`` and ``b``.

    ``at`` is the fraction along the shared wall segment of the opening centre (default 0.5);
    ``width`` defaults to 0.95 m and ``height`` to 2.1 m (a lintel closes the wall above).
    """

    a: str
    b: str
    at: float = 0.5
    width: float = 0.95
    height: float = 2.1


@dataclass(frozen=True)
class Layout:
    """A whole interior: rooms, doors, wall thickness (0.1 m) and ceiling height (2.7 m)."""

    name: str
    description: str
    rooms: tuple[RoomSpec, ...]
    doors: tuple[Door, ...] = ()
    wall_thickness: float = 0.1
    ceiling_height: float = 2.7
    twins: tuple[tuple[str, str], ...] = field(default=())

    @property
    def floor_area(self) -> float:
        """Sum of room footprints in m^2 (on wall centre lines)."""
        return float(sum((r.bounds[2] - r.bounds[0]) * (r.bounds[3] - r.bounds[1]) for r in self.rooms))


# ----------------------------------------------------------------------------------------------
# walls


def _r(v: float) -> float:
    return round(float(v), 4)


def _wall_lines(rooms: tuple[RoomSpec, ...]):
    """Merged wall intervals per line: {("h", y): [(x0, x1), ...], ("v", x): [(y0, y1), ...]}."""
    lines: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for r in rooms:
        x0, y0, x1, y1 = (_r(v) for v in r.bounds)
        lines.setdefault(("h", y0), []).append((x0, x1))
        lines.setdefault(("h", y1), []).append((x0, x1))
        lines.setdefault(("v", x0), []).append((y0, y1))
        lines.setdefault(("v", x1), []).append((y0, y1))
    merged = {}
    for key, ivs in lines.items():
        ivs = sorted(ivs)
        out = [list(ivs[0])]
        for a, b in ivs[1:]:
            if a <= out[-1][1] + 1e-9:
                out[-1][1] = max(out[-1][1], b)
            else:
                out.append([a, b])
        merged[key] = [tuple(iv) for iv in out]
    return merged


def _door_gaps(layout: Layout) -> dict[tuple[str, float], list[tuple[float, float, float]]]:
    """Door openings per wall line: (start, end, height) along the line."""
    rooms = {r.name: r for r in layout.rooms}
    gaps: dict[tuple[str, float], list[tuple[float, float, float]]] = {}
    for d in layout.doors:
        a, b = rooms[d.a].bounds, rooms[d.b].bounds
        if abs(a[2] - b[0]) < 1e-6 or abs(b[2] - a[0]) < 1e-6:
            x = a[2] if abs(a[2] - b[0]) < 1e-6 else a[0]
            lo, hi = max(a[1], b[1]), min(a[3], b[3])
            key = ("v", _r(x))
        elif abs(a[3] - b[1]) < 1e-6 or abs(b[3] - a[1]) < 1e-6:
            y = a[3] if abs(a[3] - b[1]) < 1e-6 else a[1]
            lo, hi = max(a[0], b[0]), min(a[2], b[2])
            key = ("h", _r(y))
        else:
            raise ValueError(f"door {d.a}-{d.b}: the rooms do not share a wall")
        margin = d.width / 2 + layout.wall_thickness
        if hi - lo < 2 * margin:
            raise ValueError(f"door {d.a}-{d.b}: shared wall too short for a {d.width} m opening")
        c = np.clip(lo + d.at * (hi - lo), lo + margin, hi - margin)
        gaps.setdefault(key, []).append((c - d.width / 2, c + d.width / 2, d.height))
    return gaps


def _room_at(rooms: tuple[RoomSpec, ...], x: float, y: float) -> RoomSpec | None:
    for r in rooms:
        x0, y0, x1, y1 = r.bounds
        if x0 < x < x1 and y0 < y < y1:
            return r
    return None


def _build_walls(mb: MeshBuilder, layout: Layout, pal: dict, wall_mats: dict[str, Material]) -> None:
    """Walls as thin slabs between junction pillars, with door openings and lintels."""
    t = layout.wall_thickness
    H = layout.ceiling_height
    ht = t / 2
    nodes = {(_r(x), _r(y)) for r in layout.rooms for x in (r.bounds[0], r.bounds[2]) for y in (r.bounds[1], r.bounds[3])}
    gaps = _door_gaps(layout)

    def side_mat(px: float, py: float) -> Material:
        room = _room_at(layout.rooms, px, py)
        return wall_mats[room.name] if room is not None else pal["exterior"]

    def slab(orient: str, c: float, a: float, b: float, z0: float, z1: float, caps: tuple[bool, bool]):
        # slab along the line between a and b (a < b), across [c - ht, c + ht], height [z0, z1]
        if orient == "h":
            lo, hi = np.array([a, c - ht, z0]), np.array([b, c + ht, z1])
            sides = {"+y": side_mat((a + b) / 2, c + 0.2), "-y": side_mat((a + b) / 2, c - 0.2)}
            ends = ("-x", "+x")
        else:
            lo, hi = np.array([c - ht, a, z0]), np.array([c + ht, b, z1])
            sides = {"+x": side_mat(c + 0.2, (a + b) / 2), "-x": side_mat(c - 0.2, (a + b) / 2)}
            ends = ("-y", "+y")
        mats = dict(sides)
        for end, cap in zip(ends, caps):
            if cap:
                mats[end] = pal["trim"]
        skip = ("+z", "-z") if z0 == 0.0 else ("+z",)
        if z0 > 0:
            mats["-z"] = pal["trim"]
        add_box(mb, lo, hi, mats, None, skip=skip)

    for (orient, c), intervals in _wall_lines(layout.rooms).items():
        on_line = sorted({(n[0] if orient == "h" else n[1]) for n in nodes if (n[1] if orient == "h" else n[0]) == c})
        line_gaps = sorted(gaps.get((orient, c), []))
        for a, b in intervals:
            cuts = [p for p in on_line if a - 1e-9 <= p <= b + 1e-9]
            for p, q in zip(cuts[:-1], cuts[1:]):
                # piece between two junctions, shortened to leave room for the pillars
                start, start_cap = p + ht, False
                for g0, g1, gh in line_gaps:
                    if g0 >= p and g1 <= q:
                        if g0 < start + 1e-6:
                            raise ValueError(f"door opening at {orient}={c} overlaps a wall junction")
                        slab(orient, c, start, g0, 0.0, H, (start_cap, True))
                        slab(orient, c, g0, g1, gh, H, (False, False))
                        start, start_cap = g1, True
                if q - ht > start + 1e-6:
                    slab(orient, c, start, q - ht, 0.0, H, (start_cap, False))
    for x, y in sorted(nodes):
        lo, hi = np.array([x - ht, y - ht, 0.0]), np.array([x + ht, y + ht, H])
        mats = {f: side_mat(x + 0.2 * n[0], y + 0.2 * n[1]) for f, (n, _) in AXES.items() if f[1] != "z"}
        # a pillar face towards a wall slab is hidden; its room test may hit either side: fine
        add_box(mb, lo, hi, mats, None, skip=("+z", "-z"))


# ----------------------------------------------------------------------------------------------
# rooms: floors, ceilings, lights, furniture, pictures


def _build_room_shell(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict) -> None:
    x0, y0, x1, y1 = room.bounds
    H = layout.ceiling_height
    tex, rep = FLOORS[room.floor]
    floor = Material(f"floor_{room.floor}", tex, repeat=rep)
    # floor quad (up) and ceiling quad (down), UVs in room-local metres so twin rooms match
    w, d = x1 - x0, y1 - y0
    c_floor = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], dtype=float)
    uv = np.array([[0, 0], [w, 0], [w, d], [0, d]], dtype=float)
    mb.quad(floor, c_floor, uv / rep, (0, 0, 1))
    c_ceil = np.array([[x0, y1, H], [x1, y1, H], [x1, y0, H], [x0, y0, H]], dtype=float)
    uv_c = np.array([[0, d], [w, d], [w, 0], [0, 0]], dtype=float)
    mb.quad(pal["ceiling"], c_ceil, uv_c / pal["ceiling"].repeat, (0, 0, -1))
    # ceiling light panels on a regular grid
    n = room.lights
    if n > 0:
        cols = max(1, int(round(np.sqrt(n * w / d))))
        rows = max(1, int(np.ceil(n / cols)))
        for i in range(cols):
            for j in range(rows):
                cx = x0 + (i + 0.5) * w / cols
                cy = y0 + (j + 0.5) * d / rows
                add_box(mb, (cx - 0.3, cy - 0.6, H - 0.02), (cx + 0.3, cy + 0.6, H - 0.001), pal["light"], None, skip=("+z",))


def _template_rng(seed: int, room: RoomSpec) -> np.random.Generator:
    key = room.template or room.name
    return np.random.default_rng([seed & 0xFFFFFFFF, zlib.crc32(key.encode())])


def _build_furniture(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict, seed: int) -> None:
    rng = _template_rng(seed, room)
    x0, y0 = room.bounds[0], room.bounds[1]
    for item in room.items:
        if item.kind not in FURNITURE:
            raise ValueError(f"unknown furniture kind {item.kind!r}")
        fn = FURNITURE[item.kind][0]
        yaw = np.radians(item.yaw_deg)
        jx = jy = 0.0
        if item.kind == "chair":  # chairs are never pushed in exactly the same way
            yaw += rng.uniform(-0.35, 0.35)
            jx, jy = rng.uniform(-0.06, 0.06, 2)
        T = (yaw, np.array([x0 + item.x + jx, y0 + item.y + jy, 0.0]))
        fn(mb, pal, T, rng, item.variant)


def _build_pictures(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict, bank: tx.TextureBank) -> None:
    x0, y0, x1, y1 = room.bounds
    ht = layout.wall_thickness / 2
    for pic in room.pictures:
        key = f"pic:{pic.image}"
        if pic.image == "whiteboard":
            fn, args = tx.solid, ((246, 246, 244),)
        elif pic.image.startswith("art:"):
            fn, args = tx.abstract_art, (256, 320)
        else:
            fn, args = tx.framed_photo, (pic.image, 384)
        mb.texture_fns.setdefault(key, (fn, args))
        img = bank.get(key, fn, *args)
        aspect = img.shape[1] / img.shape[0]
        w = pic.width
        h = w / aspect if pic.image != "whiteboard" else min(1.1, w * 0.5)
        mat = Material(key, key, repeat=None)
        # picture in a local frame facing -y, then turned onto the wall
        gap, depth, border = 0.015, 0.025, 0.025
        wall_pos = {
            "N": (0.0, np.array([x0 + pic.along, y1 - ht, 0.0])),
            "S": (np.pi, np.array([x0 + pic.along, y0 + ht, 0.0])),
            "E": (-np.pi / 2, np.array([x1 - ht, y0 + pic.along, 0.0])),
            "W": (np.pi / 2, np.array([x0 + ht, y0 + pic.along, 0.0])),
        }
        yaw, t = wall_pos[pic.wall]
        z = pic.z_center
        frame = pal["trim"] if pic.image == "whiteboard" else pal["frame"]
        add_box(mb, (-w / 2 - border, -gap - depth, z - h / 2 - border), (w / 2 + border, -gap, z + h / 2 + border), frame, (yaw, t), skip=("+y",))
        add_box(mb, (-w / 2, -gap - depth - 0.002, z - h / 2), (w / 2, -gap - depth, z + h / 2), {"-y": mat}, (yaw, t), skip=())


# ----------------------------------------------------------------------------------------------
# validation and assembly


def validate_layout(layout: Layout) -> None:
    """Raise ValueError when furniture leaves its room, blocks a door, or is too tall off the walls."""
    rooms = {r.name: r for r in layout.rooms}
    for d in layout.doors:
        if d.a not in rooms or d.b not in rooms:
            raise ValueError(f"door {d.a}-{d.b}: unknown room")
    gaps = _door_gaps(layout)
    ht = layout.wall_thickness / 2
    for room in layout.rooms:
        x0, y0, x1, y1 = room.bounds
        for pic in room.pictures:
            orient, line, base = {"N": ("h", y1, x0), "S": ("h", y0, x0), "E": ("v", x1, y0), "W": ("v", x0, y0)}[pic.wall]
            lo, hi = base + pic.along - pic.width / 2 - 0.05, base + pic.along + pic.width / 2 + 0.05
            span = (x0, x1) if orient == "h" else (y0, y1)
            if lo < span[0] + layout.wall_thickness or hi > span[1] - layout.wall_thickness:
                raise ValueError(f"{layout.name}/{room.name}: picture {pic.image} on wall {pic.wall} leaves the wall")
            for g0, g1, _ in gaps.get((orient, _r(line)), []):
                if hi > g0 - 0.1 and lo < g1 + 0.1:
                    raise ValueError(f"{layout.name}/{room.name}: picture {pic.image} on wall {pic.wall} overlaps a door")
        for item in room.items:
            _, w, d, h = FURNITURE[item.kind]
            yaw = np.radians(item.yaw_deg)
            c, s = abs(np.cos(yaw)), abs(np.sin(yaw))
            hw, hd = (w * c + d * s) / 2, (w * s + d * c) / 2
            cx, cy = x0 + item.x, y0 + item.y
            if item.kind != "monitor" and (cx - hw < x0 + ht - 1e-6 or cx + hw > x1 - ht + 1e-6 or cy - hd < y0 + ht - 1e-6 or cy + hd > y1 - ht + 1e-6):
                raise ValueError(f"{layout.name}/{room.name}: {item.kind} at ({item.x}, {item.y}) leaves the room")
            if h > MAX_FREE_HEIGHT and item.kind not in TALL_AGAINST_WALL and item.kind not in ("monitor", "tv_stand"):
                raise ValueError(f"{layout.name}/{room.name}: {item.kind} is taller than {MAX_FREE_HEIGHT} m")
            if item.kind in TALL_AGAINST_WALL:
                near = min(cx - hw - x0, x1 - cx - hw, cy - hd - y0, y1 - cy - hd)
                if near > ht + 0.05:
                    raise ValueError(f"{layout.name}/{room.name}: tall {item.kind} must stand against a wall")
            for (orient, line), glist in gaps.items():
                for g0, g1, _ in glist:
                    # keep 0.6 m clear on both sides of each opening
                    if orient == "v":
                        hit = abs(cx - line) < hw + 0.6 and cy + hd > g0 and cy - hd < g1
                    else:
                        hit = abs(cy - line) < hd + 0.6 and cx + hw > g0 and cx - hw < g1
                    if hit and item.kind != "rug":
                        raise ValueError(f"{layout.name}/{room.name}: {item.kind} at ({item.x}, {item.y}) blocks a door")


def build_scene(layout: Layout, seed: int = 0) -> Scene:
    """Build the textured :class:`Scene` of ``layout`` (deterministic in ``seed``).

    Returns a scene with read-only arrays, ``rooms`` set from the layout, ``floor_z = 0.0`` and
    ``source = "builtin:<name>"``; ``meta`` holds ``twins`` (pairs of identical rooms) and the
    ceiling height.
    """
    validate_layout(layout)
    bank = tx.TextureBank(seed)
    mb = MeshBuilder(layout.name, bank, texture_fns())
    pal = palette()
    wall_mats: dict[str, Material] = {}
    for room in layout.rooms:
        key = "wall_" + "_".join(str(c) for c in room.wall_color)
        tex_key = f"paint_{key}"
        mb.texture_fns.setdefault(tex_key, (tx.painted_wall, (room.wall_color,)))
        wall_mats[room.name] = Material(key, tex_key, repeat=2.0)
    _build_walls(mb, layout, pal, wall_mats)
    for room in layout.rooms:
        _build_room_shell(mb, layout, room, pal)
        _build_furniture(mb, layout, room, pal, seed)
        _build_pictures(mb, layout, room, pal, bank)
    parts = mb.parts()
    rooms = tuple(Room(r.name, tuple(float(v) for v in r.bounds)) for r in layout.rooms)
    meta = {"twins": [list(p) for p in layout.twins], "ceiling_height": layout.ceiling_height, "seed": int(seed)}
    log.debug("built %s: %d parts, %d faces, %d textures", layout.name, len(parts), sum(len(p.faces) for p in parts), len(bank))
    return Scene(name=layout.name, parts=tuple(parts), rooms=rooms, floor_z=0.0, source=f"builtin:{layout.name}", meta=meta)
