"""Walls of a procedural interior: thin slabs along the rooms' wall centre lines, pillars at
the junctions, door openings with lintels, and a step where the floors beside an opening differ.

World frame: z up, metres. A wall line is ``("h", y)`` (a wall along x at y) or ``("v", x)``
(a wall along y at x), its coordinate rounded to 0.1 mm (:func:`round_line`); a door opening
spans [start, end] metres along its line (:func:`door_span`). Walls are ``layout.wall_thickness``
thick and reach from the lowest floor beside them (a sunken room's ``floor_dz``) to the ceiling,
``floor_z + ceiling_height``. Each wall face takes the paint of the room it faces (the exterior
material outside). A room's :class:`~.layout.Opening` (window, door, glass door) cuts a hole from
its sill to its top, filled by :func:`build_openings`. Used by
:func:`markerplace.scene.builtin.procedural.add_layout`; every quad is labelled (``"wall"``, ``"step"``,
``"window"``, ``"door"``, :meth:`~.meshkit.MeshBuilder.labelled`).
"""

from __future__ import annotations

import numpy as np

from markerplace.scene.builtin.layout import Door, Layout, Opening, RoomSpec
from markerplace.scene.builtin.meshkit import AXES, Material, MeshBuilder, add_box

__all__ = ["round_line", "door_span", "door_gaps", "opening_span", "opening_spans", "build_walls", "build_openings"]

FRAME = 0.05  # window and glass door frame members: width, metres
FRAME_DEPTH = 0.07  # their depth across the wall, metres
LEAF = 0.04  # door leaf thickness, metres (centred in the wall: 3 cm behind each 0.1 m wall's faces)


def round_line(v: float) -> float:
    """A wall-line coordinate rounded to 0.1 mm, so lines of neighbouring rooms compare equal."""
    return round(float(v), 4)


def _wall_lines(rooms: tuple[RoomSpec, ...]):
    """Merged wall intervals per line: {("h", y): [(x0, x1), ...], ("v", x): [(y0, y1), ...]}."""
    lines: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for r in rooms:
        x0, y0, x1, y1 = (round_line(v) for v in r.bounds)
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


def door_span(layout: Layout, door: Door) -> tuple[str, float, float, float]:
    """Where ``door`` opens: (orient, line, start, end).

    ``orient`` is ``"h"`` for a wall along x at y = ``line`` or ``"v"`` for a wall along y at
    x = ``line`` (world metres, ``line`` rounded to 0.1 mm); the opening spans [start, end] along
    the wall. Raises ValueError when the rooms share no wall long enough for the opening.
    """
    rooms = {r.name: r for r in layout.rooms}
    a, b = rooms[door.a].bounds, rooms[door.b].bounds
    if abs(a[2] - b[0]) < 1e-6 or abs(b[2] - a[0]) < 1e-6:
        x = a[2] if abs(a[2] - b[0]) < 1e-6 else a[0]
        lo, hi = max(a[1], b[1]), min(a[3], b[3])
        key = ("v", round_line(x))
    elif abs(a[3] - b[1]) < 1e-6 or abs(b[3] - a[1]) < 1e-6:
        y = a[3] if abs(a[3] - b[1]) < 1e-6 else a[1]
        lo, hi = max(a[0], b[0]), min(a[2], b[2])
        key = ("h", round_line(y))
    else:
        raise ValueError(f"door {door.a}-{door.b}: the rooms do not share a wall")
    margin = door.width / 2 + layout.wall_thickness
    if hi - lo < 2 * margin:
        raise ValueError(f"door {door.a}-{door.b}: shared wall too short for a {door.width} m opening")
    c = np.clip(lo + door.at * (hi - lo), lo + margin, hi - margin)
    return key[0], key[1], float(c - door.width / 2), float(c + door.width / 2)


def door_gaps(layout: Layout) -> dict[tuple[str, float], list[tuple[float, float, float]]]:
    """Door openings per wall line: (start, end, height) along the line."""
    gaps: dict[tuple[str, float], list[tuple[float, float, float]]] = {}
    for d in layout.doors:
        orient, line, g0, g1 = door_span(layout, d)
        gaps.setdefault((orient, line), []).append((g0, g1, d.height))
    return gaps


def opening_span(layout: Layout, room: RoomSpec, op: Opening) -> tuple[str, float, float, float, float, float]:
    """Where a room's :class:`~.layout.Opening` is: (orient, line, start, end, z_bottom, z_top),
    world metres (``orient``/``line`` as :func:`door_span`; z of the hole's sill and top)."""
    x0, y0, x1, y1 = room.bounds
    orient, line, base = {"N": ("h", y1, x0), "S": ("h", y0, x0), "E": ("v", x1, y0), "W": ("v", x0, y0)}[op.wall]
    zf = layout.floor_z + room.floor_dz
    c = base + op.along
    return orient, round_line(line), float(c - op.width / 2), float(c + op.width / 2), zf + op.sill, zf + op.top


def opening_spans(layout: Layout) -> dict[tuple[str, float], list[tuple[float, float, float, float, Opening]]]:
    """The rooms' openings per wall line: (start, end, z_bottom, z_top, opening)."""
    out: dict[tuple[str, float], list] = {}
    for room in layout.rooms:
        for op in room.openings:
            orient, line, g0, g1, za, zb = opening_span(layout, room, op)
            out.setdefault((orient, line), []).append((g0, g1, za, zb, op))
    return out


def _room_at(rooms: tuple[RoomSpec, ...], x: float, y: float) -> RoomSpec | None:
    for r in rooms:
        x0, y0, x1, y1 = r.bounds
        if x0 < x < x1 and y0 < y < y1:
            return r
    return None


def build_walls(mb: MeshBuilder, layout: Layout, pal: dict, wall_mats: dict[str, Material]) -> None:
    """Walls as thin slabs between junction pillars, with door openings, lintels and steps.

    Slabs and pillars reach from the lowest floor of the rooms beside them up to the ceiling
    (``floor_z + ceiling_height``); an opening between rooms whose floors differ gets a step.
    A room's windows and doors (:class:`~.layout.Opening`) leave a hole from their sill to their
    top (a sill face below a window); :func:`build_openings` fills it. Labelled ``"wall"``
    (steps ``"step"``).
    """
    with mb.labelled("wall"):
        _build_walls(mb, layout, pal, wall_mats)


def _build_walls(mb: MeshBuilder, layout: Layout, pal: dict, wall_mats: dict[str, Material]) -> None:
    t = layout.wall_thickness
    zf = layout.floor_z
    H = zf + layout.ceiling_height
    ht = t / 2
    nodes = {(round_line(x), round_line(y)) for r in layout.rooms for x in (r.bounds[0], r.bounds[2]) for y in (r.bounds[1], r.bounds[3])}
    gaps = door_gaps(layout)

    def side_mat(px: float, py: float) -> Material:
        room = _room_at(layout.rooms, px, py)
        return wall_mats[room.name] if room is not None else pal["exterior"]

    def floors(*points) -> list[float]:
        # floor_dz of the rooms containing the points (the outside has none)
        return [room.floor_dz for room in (_room_at(layout.rooms, px, py) for px, py in points) if room is not None]

    def slab(orient: str, c: float, a: float, b: float, z0: float, z1: float, caps: tuple[bool, bool], bottom: float,
             top: bool = False):
        # slab along the line between a and b (a < b), across [c - ht, c + ht], height [z0, z1];
        # ``bottom`` is the lowest floor beside it (its underside there is hidden)
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
        skip = ("-z",) if z0 == bottom else ()
        if not top:
            skip += ("+z",)
        else:
            mats["+z"] = pal["trim"]  # a window sill
        if z0 > bottom:
            mats["-z"] = pal["trim"]
        add_box(mb, lo, hi, mats, None, skip=skip)

    def step(orient: str, c: float, a: float, b: float, dz_minus: float, dz_plus: float):
        # a step filling the opening [a, b] below the higher floor, on the lower side's half
        low_plus = dz_plus < dz_minus
        across = (c, c + ht) if low_plus else (c - ht, c)
        z0, z1 = zf + min(dz_minus, dz_plus), zf + max(dz_minus, dz_plus)
        axis = "y" if orient == "h" else "x"
        riser = ("+" if low_plus else "-") + axis
        if orient == "h":
            lo, hi = np.array([a, across[0], z0]), np.array([b, across[1], z1])
        else:
            lo, hi = np.array([across[0], a, z0]), np.array([across[1], b, z1])
        add_box(mb, lo, hi, {riser: pal["trim"], "+z": pal["trim"]}, None, skip=("-z",))

    holes = opening_spans(layout)
    for (orient, c), intervals in _wall_lines(layout.rooms).items():
        on_line = sorted({(n[0] if orient == "h" else n[1]) for n in nodes if (n[1] if orient == "h" else n[0]) == c})
        # doorways (z_bottom None: down to the floors, a step between them) and openings
        line_gaps = sorted([(g0, g1, None, gh) for g0, g1, gh in gaps.get((orient, c), [])]
                           + [(g0, g1, za, zb) for g0, g1, za, zb, _ in holes.get((orient, c), [])])
        for a, b in intervals:
            cuts = [p for p in on_line if a - 1e-9 <= p <= b + 1e-9]
            for p, q in zip(cuts[:-1], cuts[1:]):
                # piece between two junctions, shortened to leave room for the pillars; it has one
                # room (or the outside) on each side
                m = (p + q) / 2
                minus, plus = ((m, c - 0.2), (m, c + 0.2)) if orient == "h" else ((c - 0.2, m), (c + 0.2, m))
                dzs = floors(minus, plus)
                bottom = zf + min(dzs, default=0.0)
                start, start_cap = p + ht, False
                for g0, g1, za, gh in line_gaps:
                    if g0 >= p and g1 <= q:
                        if g0 < start + 1e-6:
                            raise ValueError(f"door opening at {orient}={c} overlaps a wall junction or another opening")
                        slab(orient, c, start, g0, bottom, H, (start_cap, True), bottom)
                        if za is None:  # a doorway between two rooms
                            z_head = zf + max(dzs, default=0.0) + gh
                            if z_head < H - 1e-9:
                                slab(orient, c, g0, g1, z_head, H, (False, False), bottom)
                            (dz_minus,), (dz_plus,) = floors(minus), floors(plus)
                            if dz_minus != dz_plus:
                                with mb.labelled("step"):
                                    step(orient, c, g0, g1, dz_minus, dz_plus)
                        else:  # a window or door of one room: wall below its sill and above its top
                            if za > bottom + 1e-9:
                                slab(orient, c, g0, g1, bottom, za, (False, False), bottom, top=True)
                            if gh < H - 1e-9:
                                slab(orient, c, g0, g1, gh, H, (False, False), bottom)
                        start, start_cap = g1, True
                if q - ht > start + 1e-6:
                    slab(orient, c, start, q - ht, bottom, H, (start_cap, False), bottom)
    for x, y in sorted(nodes):
        bottom = zf + min(floors(*((x + sx, y + sy) for sx in (-0.2, 0.2) for sy in (-0.2, 0.2))), default=0.0)
        lo, hi = np.array([x - ht, y - ht, bottom]), np.array([x + ht, y + ht, H])
        mats = {f: side_mat(x + 0.2 * n[0], y + 0.2 * n[1]) for f, (n, _) in AXES.items() if f[1] != "z"}
        # a pillar face towards a wall slab is hidden; its room test may hit either side: fine
        add_box(mb, lo, hi, mats, None, skip=("+z", "-z"))


def build_openings(mb: MeshBuilder, layout: Layout, pal: dict) -> None:
    """Fill the rooms' openings (:class:`~.layout.Opening`; holes cut by :func:`build_walls`).

    A ``window`` gets a frame (``FRAME`` wide members, ``FRAME_DEPTH`` deep, centred in the
    wall) around a glass pane on the wall's centre plane; a ``glass_door`` the same from the
    floor; a ``door`` an opaque leaf ``LEAF`` thick centred in the wall, with a handle on each
    side. Labelled ``"window"`` / ``"door"``.
    """
    t = layout.wall_thickness
    for (orient, c), spans in opening_spans(layout).items():
        for g0, g1, za, zb, op in spans:
            def box(a0, a1, u0, u1, z0, z1, mats, skip=("-z",)):
                # a box spanning [a0, a1] along the line, [c + u0, c + u1] across it, [z0, z1] high
                lo = (a0, c + u0, z0) if orient == "h" else (c + u0, a0, z0)
                hi = (a1, c + u1, z1) if orient == "h" else (c + u1, a1, z1)
                add_box(mb, lo, hi, mats, None, skip=skip)

            if op.kind == "door":
                with mb.labelled("door"):
                    box(g0, g1, -LEAF / 2, LEAF / 2, za, zb, pal["door"], skip=())
                    along = g1 - 0.08 if op.width > 0.3 else (g0 + g1) / 2
                    for side in (-1, 1):  # handles 1.0 m up, 8 cm from the edge
                        u = side * LEAF / 2
                        box(along - 0.06, along + 0.06, min(u, u + side * 0.05), max(u, u + side * 0.05),
                            za + 0.98, za + 1.02, pal["metal"], skip=())
                continue
            label = "window" if op.kind == "window" else "door"
            frame, glass, fd = pal["glass_frame"], pal["glass"], min(FRAME_DEPTH, t) / 2
            with mb.labelled(label):
                if op.kind == "window":
                    box(g0, g1, -fd, fd, za, za + FRAME, frame)
                box(g0, g1, -fd, fd, zb - FRAME, zb, frame, skip=("+z",))
                box(g0, g0 + FRAME, -fd, fd, za, zb - FRAME, frame, skip=("-z", "+z"))
                box(g1 - FRAME, g1, -fd, fd, za, zb - FRAME, frame, skip=("-z", "+z"))
                z0 = za + (FRAME if op.kind == "window" else 0.0)
                p0, p1, z1 = g0 + FRAME, g1 - FRAME, zb - FRAME
                if orient == "h":
                    corners, n = np.array([[p0, c, z0], [p1, c, z0], [p1, c, z1], [p0, c, z1]]), (0.0, -1.0, 0.0)
                else:
                    corners, n = np.array([[c, p0, z0], [c, p1, z0], [c, p1, z1], [c, p0, z1]]), (1.0, 0.0, 0.0)
                uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
                mb.quad(glass, corners, uv, n)


def add_slab_edges(mb: MeshBuilder, footprint: tuple[float, float, float, float], hole: tuple[float, float, float, float],
                   z0: float, z1: float, half_thickness: float, exterior: Material, stair_wall: Material,
                   trim: Material, arrival: str, rise: float) -> None:
    """Slab edges between two storeys of a built-in building, from ``z0`` (the ceiling below) to
    ``z1`` (the upper floor), metres: a band continuing the exterior wall faces around
    ``footprint`` (xmin, ymin, xmax, ymax on the walls' centre lines), and the four faces of the
    stair opening ``hole`` (xmin, ymin, xmax, ymax) continuing the stair room's walls. The
    ``arrival`` edge of the opening (``"-x"``, ``"-y"``, ``"+x"`` or ``"+y"``) is the stair's last
    riser: ``rise`` metres high below the upper floor, in ``trim``; it is added first."""
    x0, y0, x1, y1 = footprint
    ht = half_thickness
    band = {"-y": (x0 - ht, y0 - ht, x1 + ht, y0 + ht), "+y": (x0 - ht, y1 - ht, x1 + ht, y1 + ht),
            "-x": (x0 - ht, y0 - ht, x0 + ht, y1 + ht), "+x": (x1 - ht, y0 - ht, x1 + ht, y1 + ht)}
    for face, (a0, b0, a1, b1) in band.items():
        add_box(mb, (a0, b0, z0), (a1, b1, z1), {face: exterior}, None, skip=())
    hx0, hy0, hx1, hy1 = hole
    # each face of the opening is the one inward-looking face of a box just outside that edge
    edges = {"-y": ((hx0, hy0 - ht), (hx1, hy0), "+y"), "-x": ((hx0 - ht, hy0), (hx0, hy1), "+x"),
             "+y": ((hx0, hy1), (hx1, hy1 + ht), "-y"), "+x": ((hx1, hy0), (hx1 + ht, hy1), "-x")}
    for edge in [arrival] + [e for e in edges if e != arrival]:
        (a0, b0), (a1, b1), face = edges[edge]
        bottom, material = (z1 - rise, trim) if edge == arrival else (z0, stair_wall)
        add_box(mb, (a0, b0, bottom), (a1, b1, z1), {face: material}, None, skip=())
