"""Procedural interiors: build a textured :class:`Scene` from a :class:`Layout` description.

World frame: z up, metres, the floor at the layout's ``floor_z`` (0 for the single-storey
built-ins; one layout per storey for a building, see :mod:`.house`). A layout is a set of
axis-aligned room rectangles whose edges are wall centre lines, doors between pairs of rooms,
and per-room furniture and pictures in room-local coordinates (metres from the room's
(xmin, ymin) corner), so two rooms with the same contents are identical up to a translation.

Geometry is made of boxes and quads only (:mod:`.meshkit`). Parts are grouped by label and
material (texture + colour), so a whole scene is a few dozen to a few hundred :class:`MeshPart`
and repeated items share one texture array. Labels say what each part is, truthfully: ``wall``,
``floor``, ``ceiling``, ``light``, ``step``, ``window``, ``door``, ``picture``, ``whiteboard``
and each furniture item's kind (``bookshelf``, ``wardrobe``, ``tv``, ...); they become
``MeshPart.names`` (:mod:`markerplace.scene.semantics` keeps tags off all but walls). Walls, door openings and steps are built by :mod:`.walls`; furniture builders,
their local frame and the palette live in :mod:`.furniture`; the layout dataclasses in
:mod:`.layout`. Here: floors, ceilings, lights, furniture and pictures of each room, layout
validation and assembly. Rooms may sit lower than their storey (``floor_dz``, a sunken room:
walls reach down to it and openings towards it get a step) and have holes in their floor or
ceiling (a stairwell).
"""

from __future__ import annotations

import logging
import zlib

import numpy as np

from markerplace.scene.builtin import textures as tx
from markerplace.scene.builtin.furniture import FLOORS, FURNITURE, MAX_FREE_HEIGHT, TALL_AGAINST_WALL, palette, texture_fns
from markerplace.scene.builtin.layout import OPENING_KINDS, Layout, RoomSpec
from markerplace.scene.builtin.meshkit import Material, MeshBuilder, add_box
from markerplace.scene.builtin.walls import build_openings, build_walls, door_gaps, opening_spans, round_line
from markerplace.scene.types import Room, Scene

__all__ = ["add_layout", "build_scene", "layout_rooms", "subtract_rects", "validate_layout", "wall_material"]

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------------------------
# rooms: floors, ceilings, lights, furniture, pictures


def subtract_rects(rect, holes) -> list[tuple[float, float, float, float]]:
    """Cover of ``rect`` minus ``holes`` by axis-aligned rectangles, all (xmin, ymin, xmax, ymax).

    Each hole cuts every rectangle it overlaps into up to four pieces (the strips below and above
    it across the full width, then the strips left and right of it).
    """
    rects = [tuple(rect)]
    for hx0, hy0, hx1, hy1 in holes:
        out = []
        for x0, y0, x1, y1 in rects:
            if hx0 >= x1 or hx1 <= x0 or hy0 >= y1 or hy1 <= y0:
                out.append((x0, y0, x1, y1))
                continue
            my0, my1 = max(y0, hy0), min(y1, hy1)
            pieces = [(x0, y0, x1, my0), (x0, my1, x1, y1), (x0, my0, max(x0, hx0), my1), (min(x1, hx1), my0, x1, my1)]
            out += [r for r in pieces if r[2] - r[0] > 1e-9 and r[3] - r[1] > 1e-9]
        rects = out
    return rects


def _overlaps(a, b) -> bool:
    """True when the open rectangles a and b (xmin, ymin, xmax, ymax) intersect."""
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _build_room_shell(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict) -> None:
    x0, y0, x1, y1 = room.bounds
    zf = layout.floor_z + room.floor_dz
    H = layout.floor_z + layout.ceiling_height
    tex, rep = FLOORS[room.floor]
    floor = Material(f"floor_{room.floor}", tex, repeat=rep)
    # floor quads (up) and ceiling quads (down) around any holes, UVs in room-local metres so twin
    # rooms match
    w, d = x1 - x0, y1 - y0
    for a0, b0, a1, b1 in subtract_rects(room.bounds, room.floor_holes):
        c_floor = np.array([[a0, b0, zf], [a1, b0, zf], [a1, b1, zf], [a0, b1, zf]], dtype=float)
        uv = np.array([[a0 - x0, b0 - y0], [a1 - x0, b0 - y0], [a1 - x0, b1 - y0], [a0 - x0, b1 - y0]], dtype=float)
        with mb.labelled("floor"):
            mb.quad(floor, c_floor, uv / rep, (0, 0, 1))
    for a0, b0, a1, b1 in subtract_rects(room.bounds, room.ceiling_holes):
        c_ceil = np.array([[a0, b1, H], [a1, b1, H], [a1, b0, H], [a0, b0, H]], dtype=float)
        uv_c = np.array([[a0 - x0, b1 - y0], [a1 - x0, b1 - y0], [a1 - x0, b0 - y0], [a0 - x0, b0 - y0]], dtype=float)
        with mb.labelled("ceiling"):
            mb.quad(pal["ceiling"], c_ceil, uv_c / pal["ceiling"].repeat, (0, 0, -1))
    # ceiling light panels on a regular grid, none over a ceiling hole
    n = room.lights
    if n > 0:
        cols = max(1, int(round(np.sqrt(n * w / d))))
        rows = max(1, int(np.ceil(n / cols)))
        for i in range(cols):
            for j in range(rows):
                cx = x0 + (i + 0.5) * w / cols
                cy = y0 + (j + 0.5) * d / rows
                if any(_overlaps((cx - 0.3, cy - 0.6, cx + 0.3, cy + 0.6), h) for h in room.ceiling_holes):
                    continue
                with mb.labelled("light"):
                    add_box(mb, (cx - 0.3, cy - 0.6, H - 0.02), (cx + 0.3, cy + 0.6, H - 0.001), pal["light"], None,
                            skip=("+z",))


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
        T = (yaw, np.array([x0 + item.x + jx, y0 + item.y + jy, layout.floor_z + room.floor_dz]))
        with mb.labelled(item.kind):
            fn(mb, pal, T, rng, item.variant)


def _build_pictures(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict, bank: tx.TextureBank) -> None:
    x0, y0, x1, y1 = room.bounds
    ht = layout.wall_thickness / 2
    zf = layout.floor_z + room.floor_dz
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
            "N": (0.0, np.array([x0 + pic.along, y1 - ht, zf])),
            "S": (np.pi, np.array([x0 + pic.along, y0 + ht, zf])),
            "E": (-np.pi / 2, np.array([x1 - ht, y0 + pic.along, zf])),
            "W": (np.pi / 2, np.array([x0 + ht, y0 + pic.along, zf])),
        }
        yaw, t = wall_pos[pic.wall]
        z = pic.z_center
        frame = pal["trim"] if pic.image == "whiteboard" else pal["frame"]
        with mb.labelled("whiteboard" if pic.image == "whiteboard" else "picture"):
            add_box(mb, (-w / 2 - border, -gap - depth, z - h / 2 - border), (w / 2 + border, -gap, z + h / 2 + border),
                    frame, (yaw, t), skip=("+y",))
            add_box(mb, (-w / 2, -gap - depth - 0.002, z - h / 2), (w / 2, -gap - depth, z + h / 2), {"-y": mat}, (yaw, t),
                    skip=())


# ----------------------------------------------------------------------------------------------
# validation and assembly


def validate_layout(layout: Layout) -> None:
    """Raise ValueError when furniture leaves its room, blocks a door, stands over a floor hole,
    or is too tall off the walls, when a floor/ceiling hole leaves its room, when a picture
    overlaps a door or window, or when a window or door leaves its wall or overlaps a doorway."""
    rooms = {r.name: r for r in layout.rooms}
    for d in layout.doors:
        if d.a not in rooms or d.b not in rooms:
            raise ValueError(f"door {d.a}-{d.b}: unknown room")
    gaps = door_gaps(layout)
    holes = opening_spans(layout)
    ht = layout.wall_thickness / 2
    for room in layout.rooms:
        x0, y0, x1, y1 = room.bounds
        for hx0, hy0, hx1, hy1 in room.floor_holes + room.ceiling_holes:
            if not (x0 <= hx0 < hx1 <= x1 and y0 <= hy0 < hy1 <= y1):
                raise ValueError(f"{layout.name}/{room.name}: hole {(hx0, hy0, hx1, hy1)} leaves the room")
        for pic in room.pictures:
            orient, line, base = {"N": ("h", y1, x0), "S": ("h", y0, x0), "E": ("v", x1, y0), "W": ("v", x0, y0)}[pic.wall]
            lo, hi = base + pic.along - pic.width / 2 - 0.05, base + pic.along + pic.width / 2 + 0.05
            span = (x0, x1) if orient == "h" else (y0, y1)
            if lo < span[0] + layout.wall_thickness or hi > span[1] - layout.wall_thickness:
                raise ValueError(f"{layout.name}/{room.name}: picture {pic.image} on wall {pic.wall} leaves the wall")
            for g0, g1, _ in gaps.get((orient, round_line(line)), []):
                if hi > g0 - 0.1 and lo < g1 + 0.1:
                    raise ValueError(f"{layout.name}/{room.name}: picture {pic.image} on wall {pic.wall} overlaps a door")
            for g0, g1, *_ in holes.get((orient, round_line(line)), []):
                if hi > g0 - 0.1 and lo < g1 + 0.1:
                    raise ValueError(f"{layout.name}/{room.name}: picture {pic.image} on wall {pic.wall} overlaps a "
                                     "window or door")
        for op in room.openings:
            if op.kind not in OPENING_KINDS or op.wall not in ("N", "S", "E", "W"):
                raise ValueError(f"{layout.name}/{room.name}: opening {op} has an unknown kind or wall")
            orient, line, base = {"N": ("h", y1, x0), "S": ("h", y0, x0), "E": ("v", x1, y0), "W": ("v", x0, y0)}[op.wall]
            span = (x0, x1) if orient == "h" else (y0, y1)
            lo, hi = base + op.along - op.width / 2, base + op.along + op.width / 2
            if lo < span[0] + layout.wall_thickness or hi > span[1] - layout.wall_thickness:
                raise ValueError(f"{layout.name}/{room.name}: {op.kind} on wall {op.wall} leaves the wall")
            if not 0 <= op.sill < op.top < layout.ceiling_height:
                raise ValueError(f"{layout.name}/{room.name}: {op.kind} on wall {op.wall}: need 0 <= sill < top < "
                                 "the ceiling height")
            for g0, g1, _ in gaps.get((orient, round_line(line)), []):
                if hi > g0 - 0.1 and lo < g1 + 0.1:
                    raise ValueError(f"{layout.name}/{room.name}: {op.kind} on wall {op.wall} overlaps a doorway")
        for item in room.items:
            _, w, d, h = FURNITURE[item.kind]
            yaw = np.radians(item.yaw_deg)
            c, s = abs(np.cos(yaw)), abs(np.sin(yaw))
            hw, hd = (w * c + d * s) / 2, (w * s + d * c) / 2
            cx, cy = x0 + item.x, y0 + item.y
            if item.kind != "monitor" and (cx - hw < x0 + ht - 1e-6 or cx + hw > x1 - ht + 1e-6 or cy - hd < y0 + ht - 1e-6 or cy + hd > y1 - ht + 1e-6):
                raise ValueError(f"{layout.name}/{room.name}: {item.kind} at ({item.x}, {item.y}) leaves the room")
            if any(_overlaps((cx - hw, cy - hd, cx + hw, cy + hd), hole) for hole in room.floor_holes):
                raise ValueError(f"{layout.name}/{room.name}: {item.kind} at ({item.x}, {item.y}) stands over a floor hole")
            if h > MAX_FREE_HEIGHT and item.kind not in TALL_AGAINST_WALL and item.kind not in ("monitor", "tv_stand"):
                raise ValueError(f"{layout.name}/{room.name}: {item.kind} is taller than {MAX_FREE_HEIGHT} m")
            if item.kind in TALL_AGAINST_WALL:
                near = min(cx - hw - x0, x1 - cx - hw, cy - hd - y0, y1 - cy - hd)
                if near > ht + 0.05:
                    raise ValueError(f"{layout.name}/{room.name}: tall {item.kind} must stand against a wall")
            door_spans = {key: list(glist) for key, glist in gaps.items()}
            for key, hlist in holes.items():  # doors with a leaf need the same clearance; windows do not
                door_spans.setdefault(key, []).extend((g0, g1, 0.0) for g0, g1, _, _, op in hlist if op.kind != "window")
            for (orient, line), glist in door_spans.items():
                for g0, g1, _ in glist:
                    # keep 0.6 m clear on both sides of each opening
                    if orient == "v":
                        hit = abs(cx - line) < hw + 0.6 and cy + hd > g0 and cy - hd < g1
                    else:
                        hit = abs(cy - line) < hd + 0.6 and cx + hw > g0 and cx - hw < g1
                    if hit and item.kind != "rug":
                        raise ValueError(f"{layout.name}/{room.name}: {item.kind} at ({item.x}, {item.y}) blocks a door")


def wall_material(mb: MeshBuilder, color: tuple[int, int, int]) -> Material:
    """The painted-wall material of RGB 0-255 ``color`` (its texture registered in ``mb``)."""
    key = "wall_" + "_".join(str(c) for c in color)
    tex_key = f"paint_{key}"
    mb.texture_fns.setdefault(tex_key, (tx.painted_wall, (color,)))
    return Material(key, tex_key, repeat=2.0)


def add_layout(mb: MeshBuilder, layout: Layout, pal: dict[str, Material], seed: int) -> None:
    """Add the walls, floors, ceilings, lights, furniture and pictures of ``layout`` to ``mb``.

    Everything is placed at the layout's ``floor_z`` (one storey of a building); wall paint
    textures are registered in ``mb.texture_fns``. The layout is validated first.
    """
    validate_layout(layout)
    wall_mats = {room.name: wall_material(mb, room.wall_color) for room in layout.rooms}
    build_walls(mb, layout, pal, wall_mats)
    build_openings(mb, layout, pal)
    for room in layout.rooms:
        _build_room_shell(mb, layout, room, pal)
        _build_furniture(mb, layout, room, pal, seed)
        _build_pictures(mb, layout, room, pal, mb.bank)


def layout_rooms(layout: Layout) -> tuple[Room, ...]:
    """The :class:`Room` footprints of ``layout`` with their floor heights (world metres)."""
    return tuple(Room(r.name, tuple(float(v) for v in r.bounds), floor_z=layout.floor_z + r.floor_dz) for r in layout.rooms)


def build_scene(layout: Layout, seed: int = 0) -> Scene:
    """Build the textured :class:`Scene` of ``layout`` (deterministic in ``seed``).

    Returns a scene with read-only arrays, ``rooms`` set from the layout, ``floor_z`` (the
    layout's, 0.0 for the built-ins) and ``source = "builtin:<name>"``; ``meta`` holds ``twins``
    (pairs of identical rooms) and the ceiling height.
    """
    bank = tx.TextureBank(seed)
    mb = MeshBuilder(layout.name, bank, texture_fns())
    add_layout(mb, layout, palette(), seed)
    parts = mb.parts()
    rooms = layout_rooms(layout)
    meta = {"twins": [list(p) for p in layout.twins], "ceiling_height": layout.ceiling_height, "seed": int(seed)}
    log.debug("built %s: %d parts, %d faces, %d textures", layout.name, len(parts), sum(len(p.faces) for p in parts), len(bank))
    return Scene(name=layout.name, parts=tuple(parts), rooms=rooms, floor_z=float(layout.floor_z), source=f"builtin:{layout.name}", meta=meta)
