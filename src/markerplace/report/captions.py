"""Where a tag goes, in words a person with a ladder and a tape measure can follow, measured on
the model.

For each placed tag: the storey, which wall it hangs on and which way it faces, the height of
its centre above the floor at the foot of that wall (the floor the installer stands on, never
furniture: the caller gives it, from the plan's floor map), and the distance along the wall
from its centre to the nearest *reference* on either side, measured with rays on the model
(:class:`markerplace.scene.raycast.RayCaster`):

* ``corner``: something crosses the wall (the next wall, a cupboard built in from floor to
  ceiling);
* ``door edge``: the wall stops from the floor to above the tag's height and goes on above (a
  doorway);
* ``wall end``: the wall stops at every height (an outside corner, the end of a partition or of
  the surface the tag is on, a floor-to-ceiling opening).

Every distance runs along the wall plane (the wall surface fitted behind the tag), so a tape held
flat on the wall at the tag's height and one along the floor line read the same number:
furniture standing in front of the wall does not end it (the along-wall rays run at the floor
line, at the tag's height and near the ceiling, and a corner is where all of them stop), and a
door edge must be open at the floor line and at the tag's height alike (a window or a niche
at tag height only is no reference). A picture or panel on the wall does not end it either.

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

__all__ = ["COMPASS", "WallEnd", "TagPlace", "facing_label", "facing_name", "wall_side", "wall_frame",
           "ceiling_above", "wall_end", "describe_tag", "REFERENCE_KINDS"]

COMPASS = (("east", "+x"), ("north-east", "+x+y"), ("north", "+y"), ("north-west", "-x+y"),
           ("west", "-x"), ("south-west", "-x-y"), ("south", "-y"), ("south-east", "+x-y"))
"""The eight sectors, counter-clockwise from +x: (name, axes)."""

REFERENCE_KINDS = ("corner", "door edge", "wall end", "none")
"""What a distance along the wall is measured to (see the module docstring); ``none``: nothing
within :data:`MAX_RANGE`."""

FRONT_OFFSET = 0.05
"""Rays along the wall run this far in front of its surface, metres (above a tag's 4 mm lift,
below a door frame's usual depth)."""
FLOOR_LINE = 0.10
"""The floor-line rays run this far above the floor, metres (over a skirting board)."""
HEAD_HEIGHT = 2.3
"""The top rays run this far above the floor (above a door's head), or 0.1 m under the ceiling
when that is lower, metres."""
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


def facing_name(normal: np.ndarray) -> str:
    """The compass sector a tag with wall normal ``normal`` faces, e.g. ``"west"``."""
    return COMPASS[_sector(np.asarray(normal, float)[:2])][0]


def wall_side(normal: np.ndarray) -> str:
    """Which wall of its room a tag facing ``normal`` hangs on: the opposite sector, e.g. a tag
    facing west is on the ``"east"`` wall."""
    return COMPASS[(_sector(np.asarray(normal, float)[:2]) + 4) % 8][0]


WALL_FIT_TOL = 0.01
"""Metres: wall hits this far off the fitted line are kept (things hung on the wall stand off it
by more, a scan's wall is flat to within it)."""


def wall_frame(caster, position: np.ndarray, normal: np.ndarray, half_width: float = 0.4,
               samples: int = 17) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The wall behind a tag, fitted to the model: (3,) point on the surface behind the centre,
    (3,) unit horizontal normal (towards the room, same side as ``normal``) and (3,) unit
    tangent (the viewer's right, = up x normal).

    Rays towards the wall from ``FRONT_OFFSET`` in front of it at ``samples`` points within
    ``half_width`` of the centre; a line fitted to the hits in xy gives the wall's direction (a
    scan's normal may be a few degrees off, which would make a 10 m probe drift into or away from
    the wall), refitted without the hits more than :data:`WALL_FIT_TOL` off it (a picture or a
    socket beside the tag would tilt the line, and the tilted line would run into the wall and
    be taken for a corner). Falls back to ``normal`` when fewer than 3 rays hit.
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
        keep = np.ones(len(pts), dtype=bool)
        for _ in range(3):  # a picture or a switch beside the tag stands off the wall: fit without it
            centre = pts[keep].mean(axis=0)
            _, _, vt = np.linalg.svd(pts[keep] - centre)
            off = np.abs((pts - centre) @ vt[1])
            new_keep = off <= max(WALL_FIT_TOL, 2.5 * float(np.median(off[keep])))
            if new_keep.sum() < 3 or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        tan = vt[0] if np.dot(vt[0], t[:2]) >= 0 else -vt[0]
        t = np.array([tan[0], tan[1], 0.0])
        n = np.cross(t, [0.0, 0.0, 1.0])  # up x n = t  <=>  n = t x up
        n /= np.linalg.norm(n)
        centre = pts[keep].mean(axis=0)
        along = float(np.dot(p[:2] - centre, t[:2]))
        on_wall = np.array([centre[0] + along * t[0], centre[1] + along * t[1], p[2]])
    else:
        d0, _ = caster.first_hits(p[None] + 0.3 * n[None], -n[None], max_t=0.6)
        on_wall = p - (d0[0] - 0.3) * n if np.isfinite(d0[0]) else p.copy()
    return on_wall, n, t


def ceiling_above(caster, point: np.ndarray) -> float:
    """Height (world z, metres) of the first surface straight above ``point`` (3,), inf when none
    within 20 m."""
    p = np.asarray(point, float)
    t, _ = caster.first_hits(p[None], np.array([[0.0, 0.0, 1.0]]), max_t=20.0)
    return float(p[2] + t[0])


def probe_heights(floor_z: float, tag_z: float, ceiling_z: float) -> tuple[float, float, float]:
    """(floor line, tag, top) heights of the along-wall rays, world metres (module docstring)."""
    top = min(floor_z + HEAD_HEIGHT, ceiling_z - 0.1)
    return floor_z + FLOOR_LINE, float(tag_z), float(max(top, tag_z))


@dataclass(frozen=True)
class WallEnd:
    """The nearest reference along the wall on one side of a tag.

    Attributes:
        distance: metres along the wall plane from the tag centre (inf when nothing within range).
        kind: one of :data:`REFERENCE_KINDS`.
    """

    distance: float
    kind: str

    def words(self, surface: str = "wall") -> str:
        """``"corner"``, ``"door edge"``, ``"end of the wall"`` (of the ``surface`` the tag is on)
        or ``"nothing within 15 m"``."""
        return {"corner": "corner", "door edge": "door edge", "wall end": f"end of the {surface}"}.get(
            self.kind, f"nothing within {MAX_RANGE:g} m")


def _open_run(missing: np.ndarray, gap: int) -> int:
    """Index of the first probe that starts a run of ``gap`` missing probes (or of missing probes
    up to the end), -1 when none."""
    runs = np.convolve(missing.astype(int), np.ones(gap, int), mode="full")[gap - 1:]
    need = np.minimum(gap, len(missing) - np.arange(len(missing)))
    start = np.flatnonzero(missing & (runs >= need))
    return int(start[0]) if len(start) else -1


def wall_end(caster, on_wall: np.ndarray, normal: np.ndarray, direction: np.ndarray, floor_z: float,
             ceiling_z: float = np.inf, max_range: float = MAX_RANGE) -> WallEnd:
    """The nearest corner, door edge or wall end from ``on_wall`` (3,), the wall surface behind
    the tag centre, along ``direction`` (unit, horizontal), measured along the wall plane.

    Rays ``FRONT_OFFSET`` in front of the wall along ``direction`` at the floor line, the tag's
    height and the top height (:func:`probe_heights`) find a corner where all three stop (the
    farthest of their hits: furniture stops only some). Probes every ``STEP`` towards the wall
    find where no surface is left within ``DEPTH`` behind that line, for at least ``MIN_GAP``, at
    the floor line and at the tag's height alike (located to a millimetre by bisection): a door
    edge when the wall goes on at the top height there, else a wall end. The nearer of the corner
    and the opening wins.

    Args:
        caster: :class:`~markerplace.scene.raycast.RayCaster` of the scene.
        on_wall: (3,) point on the wall surface at the tag's height; normal: (3,) horizontal unit
            wall normal (towards the room).
        direction: (3,) unit horizontal direction along the wall.
        floor_z: the floor at the foot of the wall, world metres; ceiling_z: the ceiling above it.
    """
    p = np.asarray(on_wall, float)
    n = np.asarray(normal, float)
    d = np.asarray(direction, float)
    heights = probe_heights(floor_z, p[2], ceiling_z)
    fronts = np.array([[p[0] + FRONT_OFFSET * n[0], p[1] + FRONT_OFFSET * n[1], h] for h in heights])
    hits, _ = caster.first_hits(fronts, np.tile(d, (3, 1)), max_t=max_range)
    corner = float(np.max(hits))  # inf when any height runs free
    reach = float(min(corner, max_range))
    s = np.arange(0.0, reach, STEP)

    def open_at(ss: np.ndarray, level: int) -> np.ndarray:
        starts = fronts[level][None] + ss[:, None] * d[None]
        w, _ = caster.first_hits(starts, np.tile(-n, (len(ss), 1)), max_t=FRONT_OFFSET + DEPTH)
        return ~np.isfinite(w)

    if len(s):
        both = open_at(s, 0) & open_at(s, 1)
        k = _open_run(both, int(np.ceil(MIN_GAP / STEP)))
        if k >= 0:
            lo, hi = (s[k - 1], s[k]) if k > 0 else (0.0, 0.0)
            for _ in range(8 if hi > lo else 0):  # bisect between the last wall and the first opening
                mid = np.array([0.5 * (lo + hi)])
                lo, hi = (lo, mid[0]) if (open_at(mid, 0) & open_at(mid, 1))[0] else (mid[0], hi)
            edge = 0.5 * (lo + hi)
            above = heights[2] > p[2] + 0.2 and not open_at(np.array([edge + 0.5 * MIN_GAP]), 2)[0]
            return WallEnd(float(edge), "door edge" if above else "wall end")
    if np.isfinite(corner):
        return WallEnd(corner, "corner")
    return WallEnd(np.inf, "none")


@dataclass(frozen=True)
class TagPlace:
    """Everything the instructions say about one tag (metres, world frame of the caster).

    Attributes:
        facing: e.g. ``"west (-x)"`` (:func:`facing_label`).
        wall: e.g. ``"east"`` (:func:`wall_side`).
        height: tag centre above ``floor_z``.
        floor_z: the floor at the foot of the wall under the tag (the installer's floor).
        left, right: the nearest references on the viewer's left and right (:class:`WallEnd`).
        normal, tangent: (3,) fitted wall normal and the viewer's right along the wall.
        on_wall: (3,) point on the wall surface behind the tag centre.
        surface: what the tag is on (``"wall"`` unless the plan says otherwise).
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
    surface: str = "wall"

    @property
    def nearest(self) -> tuple[str, WallEnd]:
        """(``"left"`` or ``"right"``, its :class:`WallEnd`): the nearer reference."""
        return ("left", self.left) if self.left.distance <= self.right.distance else ("right", self.right)

    def end_point(self, side: str) -> np.ndarray | None:
        """(3,) the reference on ``side`` (``"left"``/``"right"``) on the wall at tag height, None
        when there is none."""
        end = self.left if side == "left" else self.right
        if not np.isfinite(end.distance):
            return None
        sign = -1.0 if side == "left" else 1.0
        return self.on_wall + sign * end.distance * self.tangent

    def reference_point(self) -> np.ndarray | None:
        """(3,) the nearer reference on the wall at tag height (None when neither was found)."""
        return self.end_point(self.nearest[0])

    def distance_words(self) -> str:
        """E.g. ``"0.40 m from the door edge on its right; 3.05 m from the corner on its left"``:
        the nearer reference first."""
        side, end = self.nearest
        other_side, other = ("right", self.right) if side == "left" else ("left", self.left)
        if not np.isfinite(end.distance):
            return f"no corner or door edge within {MAX_RANGE:g} m on either side"
        text = f"{end.distance:.2f} m from the {end.words(self.surface)} on its {side}"
        if np.isfinite(other.distance):
            text += f"; {other.distance:.2f} m from the {other.words(self.surface)} on its {other_side}"
        return text


def describe_tag(caster, position: np.ndarray, normal: np.ndarray, floor_z: float) -> TagPlace:
    """Measure one tag on the model: facing, wall, height above the floor under it, and the
    nearest references on both sides (see the module docstring for the conventions).

    Args:
        caster: :class:`~markerplace.scene.raycast.RayCaster` of the scene.
        position: (3,) tag centre, metres.
        normal: (3,) wall normal towards the room.
        floor_z: the floor at the foot of the wall under the tag, world metres (the plan's floor
            map there: tag centres stand ``--height`` above it).
    """
    on_wall, n, t = wall_frame(caster, position, normal)
    ceiling = ceiling_above(caster, on_wall + 0.1 * n)
    left = wall_end(caster, on_wall, n, -t, floor_z, ceiling)
    right = wall_end(caster, on_wall, n, t, floor_z, ceiling)
    return TagPlace(facing_label(n), wall_side(n), float(position[2] - floor_z), float(floor_z), left, right,
                    n, t, on_wall)
