"""Where a tag goes, in words a person with a ladder can follow, measured on the model.

For each placed tag: the storey, which wall it hangs on and which way it faces, the height of
its centre above the local floor, and the distance along the wall from its centre to the
nearest corner or edge of the wall (a door, an opening, an outside corner) on either side,
measured with rays on the model (:class:`markerplace.scene.raycast.RayCaster`).

Direction convention (used by the HTML report and documented there): the model's axes are
named like a map seen from above, **+x = east, +y = north** (so -x = west, -y = south; "north"
is the model's +y axis, not magnetic north, and "up" on the report's top-down maps). A tag
*faces* the direction of its wall normal (towards the people who look at it, the marker's +z
axis); it hangs *on* the wall on the opposite side of the room: a tag facing west (-x) is on
the east wall. Eight compass sectors of 45 degrees each. "Left" and "right" are as seen by a
person standing in front of the tag looking at it (the marker's -x and +x axes).

Frames: world z up, metres (whatever frame the ray caster's vertices are in).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["COMPASS", "WallEnd", "TagPlace", "facing_label", "wall_side", "local_floor_z", "wall_frame",
           "wall_end", "describe_tag"]

COMPASS = (("east", "+x"), ("north-east", "+x+y"), ("north", "+y"), ("north-west", "-x+y"),
           ("west", "-x"), ("south-west", "-x-y"), ("south", "-y"), ("south-east", "+x-y"))
"""The eight sectors, counter-clockwise from +x: (name, axes)."""

FRONT_OFFSET = 0.05
"""Rays along the wall run this far in front of its surface, metres (above a tag's 4 mm lift,
below a door frame's usual depth)."""
STEP = 0.01
"""Spacing of the wall probes along the wall, metres."""
DEPTH = 0.3
"""A probe that finds no surface within this behind the wall's front line sees an opening,
metres (a door, the end of the wall; a window's glass is a surface). A smaller step of the
surface (a picture, a panel, a shallow recess) does not end the wall."""
MIN_GAP = 0.10
"""An opening counts only when it is at least this long, metres: small holes in a scan do not
end a wall."""
MAX_RANGE = 15.0
"""Farthest corner or edge looked for on each side, metres."""


def _sector(direction_xy: np.ndarray) -> int:
    angle = np.degrees(np.arctan2(direction_xy[1], direction_xy[0]))
    return int(np.round(angle / 45.0)) % 8


def facing_label(normal: np.ndarray) -> str:
    """Where a tag with wall normal ``normal`` (3,) or (2,) looks: e.g. ``"west (-x)"``, or
    ``"north-east (+x+y, 52 deg)"`` when more than 1 degree off the sector's axis (angle
    counter-clockwise from +x, in [0, 360))."""
    n = np.asarray(normal, float)[:2]
    name, axes = COMPASS[_sector(n)]
    angle = np.degrees(np.arctan2(n[1], n[0])) % 360.0
    off = abs((angle - 45.0 * _sector(n) + 180.0) % 360.0 - 180.0)
    return f"{name} ({axes})" if off <= 1.0 else f"{name} ({axes}, {angle:.0f} deg)"


def wall_side(normal: np.ndarray) -> str:
    """Which wall of its room a tag facing ``normal`` hangs on: the opposite sector, e.g. a tag
    facing west is on the ``"east"`` wall."""
    return COMPASS[(_sector(np.asarray(normal, float)[:2]) + 4) % 8][0]


def local_floor_z(caster, position: np.ndarray, normal: np.ndarray, storey_floor: float,
                  reach: float = 0.6) -> float:
    """Height of the floor in front of a tag, world metres.

    Vertical rays down from points 0.3-1.2 m in front of the tag (at its height); the first
    surface each one meets, when within ``reach`` of ``storey_floor`` (a step, a sunken room), is
    a floor candidate and the lowest one wins (furniture stands higher than the floor). Without
    any: ``storey_floor``.
    """
    p = np.asarray(position, float)
    n = np.asarray(normal, float).copy()
    n[2] = 0.0
    n /= max(np.linalg.norm(n), 1e-12)
    starts = p[None] + np.array([0.3, 0.5, 0.8, 1.2])[:, None] * n[None]
    t, _ = caster.first_hits(starts, np.tile([0.0, 0.0, -1.0], (len(starts), 1)), max_t=p[2] - storey_floor + reach)
    z = starts[:, 2] - t
    z = z[np.isfinite(z) & (np.abs(z - storey_floor) <= reach)]
    return float(z.min()) if len(z) else float(storey_floor)


def wall_frame(caster, position: np.ndarray, normal: np.ndarray, half_width: float = 0.4,
               samples: int = 17) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The wall behind a tag, fitted to the model: (3,) point on the surface behind the centre,
    (3,) unit horizontal normal (towards the room, same side as ``normal``) and (3,) unit
    tangent (the viewer's right, = up x normal).

    Rays towards the wall from ``FRONT_OFFSET`` in front of it at ``samples`` points within
    ``half_width`` of the centre; a line fitted to the hits in xy gives the wall's direction (a
    scan's normal may be a few degrees off, which would make a 10 m probe drift into or away from
    the wall). Falls back to ``normal`` when fewer than 3 rays hit.
    """
    p = np.asarray(position, float)
    n = np.asarray(normal, float).copy()
    n[2] = 0.0
    n /= max(np.linalg.norm(n), 1e-12)
    t = np.cross([0.0, 0.0, 1.0], n)
    s = np.linspace(-half_width, half_width, samples)
    starts = p[None] + s[:, None] * t[None] + 0.3 * n[None]
    dist, _ = caster.first_hits(starts, np.tile(-n, (samples, 1)), max_t=0.6)
    ok = np.isfinite(dist)
    if ok.sum() >= 3:
        pts = starts[ok, :2] - dist[ok, None] * n[None, :2]
        centre = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - centre)
        tan = vt[0] if np.dot(vt[0], t[:2]) >= 0 else -vt[0]
        t = np.array([tan[0], tan[1], 0.0])
        n = np.cross(t, [0.0, 0.0, 1.0])  # up x n = t  <=>  n = t x up
        n /= np.linalg.norm(n)
        along = float(np.dot(p[:2] - centre, t[:2]))
        on_wall = np.array([centre[0] + along * t[0], centre[1] + along * t[1], p[2]])
    else:
        d0, _ = caster.first_hits(p[None] + 0.3 * n[None], -n[None], max_t=0.6)
        on_wall = p - (d0[0] - 0.3) * n if np.isfinite(d0[0]) else p.copy()
    return on_wall, n, t


@dataclass(frozen=True)
class WallEnd:
    """The end of a wall on one side of a tag.

    Attributes:
        distance: metres from the tag centre along the wall (inf when nothing within range).
        kind: ``"corner"`` (something across the wall: the next wall, a cupboard), ``"edge"``
            (the wall stops: a door, an opening, an outside corner) or ``"none"``.
    """

    distance: float
    kind: str

    def words(self) -> str:
        """``"corner"``, ``"edge of its surface"`` or ``"nothing within 15 m"``."""
        return {"corner": "corner", "edge": "edge of its surface"}.get(self.kind, f"nothing within {MAX_RANGE:g} m")


def wall_end(caster, on_wall: np.ndarray, normal: np.ndarray, direction: np.ndarray,
             max_range: float = MAX_RANGE) -> WallEnd:
    """The nearest corner or edge from ``on_wall`` along ``direction`` (unit, horizontal).

    A ray ``FRONT_OFFSET`` in front of the wall along ``direction`` finds a corner (anything
    standing across the wall). Probes every ``STEP`` towards the wall find where no surface is
    left within ``DEPTH`` behind that line for at least ``MIN_GAP`` (a door, an opening, the end
    of the wall; located to a millimetre by bisection); whichever is nearer wins.
    """
    p = np.asarray(on_wall, float)
    n = np.asarray(normal, float)
    d = np.asarray(direction, float)
    front = p + FRONT_OFFSET * n
    corner, _ = caster.first_hits(front[None], d[None], max_t=max_range)
    reach = float(min(corner[0], max_range))
    s = np.arange(0.0, reach, STEP)
    starts = front[None] + s[:, None] * d[None]
    w, _ = caster.first_hits(starts, np.tile(-n, (len(s), 1)), max_t=FRONT_OFFSET + DEPTH)
    missing = ~np.isfinite(w)
    gap = int(np.ceil(MIN_GAP / STEP))
    # an opening starts at the first probe that begins a run of `gap` missing probes (or runs to `reach`)
    runs = np.convolve(missing.astype(int), np.ones(gap, int), mode="full")[gap - 1:]
    need = np.minimum(gap, len(s) - np.arange(len(s)))
    start = np.flatnonzero(missing & (runs >= need))
    if len(start) and s[start[0]] < reach:
        lo, hi = (s[start[0] - 1], s[start[0]]) if start[0] > 0 else (0.0, 0.0)
        for _ in range(8 if hi > lo else 0):  # bisect between the last hit and the first miss
            mid = 0.5 * (lo + hi)
            t_mid, _ = caster.first_hits((front + mid * d)[None], -n[None], max_t=FRONT_OFFSET + DEPTH)
            lo, hi = (mid, hi) if np.isfinite(t_mid[0]) else (lo, mid)
        return WallEnd(float(0.5 * (lo + hi)), "edge")
    if np.isfinite(corner[0]):
        return WallEnd(float(corner[0]), "corner")
    return WallEnd(np.inf, "none")


@dataclass(frozen=True)
class TagPlace:
    """Everything the caption says about one tag (metres, world frame of the caster).

    Attributes:
        facing: e.g. ``"west (-x)"`` (:func:`facing_label`).
        wall: e.g. ``"east"`` (:func:`wall_side`).
        height: tag centre above the local floor.
        floor_z: the local floor's height.
        left, right: the wall's ends on the viewer's left and right (:class:`WallEnd`).
        normal, tangent: (3,) fitted wall normal and the viewer's right along the wall.
        on_wall: (3,) point on the wall surface behind the tag centre.
    """

    facing: str
    wall: str
    height: float
    floor_z: float
    left: WallEnd
    right: WallEnd
    normal: np.ndarray
    tangent: np.ndarray
    on_wall: np.ndarray

    @property
    def nearest(self) -> tuple[str, WallEnd]:
        """(``"left"`` or ``"right"``, its :class:`WallEnd`): the nearer end of the wall."""
        return ("left", self.left) if self.left.distance <= self.right.distance else ("right", self.right)

    def reference_point(self) -> np.ndarray | None:
        """(3,) the nearer corner or edge on the wall at tag height (None when neither was found)."""
        side, end = self.nearest
        if not np.isfinite(end.distance):
            return None
        sign = -1.0 if side == "left" else 1.0
        return self.on_wall + sign * end.distance * self.tangent

    def distance_words(self) -> str:
        """E.g. ``"0.40 m from the edge of its surface on its right (a door, an opening, the end
        of the wall or of furniture); 3.05 m from the corner on its left"``: the nearer end
        first."""
        side, end = self.nearest
        other_side, other = ("right", self.right) if side == "left" else ("left", self.left)
        if not np.isfinite(end.distance):
            return f"no corner or wall edge within {MAX_RANGE:g} m on either side"
        text = f"{end.distance:.2f} m from the {end.words()} on its {side}"
        if end.kind == "edge":
            text += " (a door, an opening, the end of the wall or of furniture)"
        if np.isfinite(other.distance):
            text += f"; {other.distance:.2f} m from the {other.words()} on its {other_side}"
        return text


def describe_tag(caster, position: np.ndarray, normal: np.ndarray, storey_floor: float) -> TagPlace:
    """Measure one tag on the model: facing, wall, height above the local floor, and the wall's
    ends on both sides (see the module docstring for the conventions).

    Args:
        caster: :class:`~markerplace.scene.raycast.RayCaster` of the scene.
        position: (3,) tag centre, metres.
        normal: (3,) wall normal towards the room.
        storey_floor: floor height of the tag's storey, metres (the local floor is searched
            within 0.6 m of it).
    """
    on_wall, n, t = wall_frame(caster, position, normal)
    floor = local_floor_z(caster, position, n, storey_floor)
    left = wall_end(caster, on_wall, n, -t)
    right = wall_end(caster, on_wall, n, t)
    return TagPlace(facing_label(normal), wall_side(normal), float(position[2] - floor), floor, left, right,
                    n, t, on_wall)
