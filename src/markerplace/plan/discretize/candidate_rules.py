"""The rules that decide whether a wall spot may carry a tag: the settings
(:class:`CandidateConfig`), what each face of the model is (:class:`SurfaceLabels`, from the
parts' names and glass), whether a tag lies flat there (:func:`tag_fits`) and what the
geometry around it says (:func:`surface_shape`: standing off the wall, set into an opening,
a column). :mod:`markerplace.plan.discretize.wall_candidates` applies them in the order of :data:`RULES`.

Frames: world z up, metres; normals are horizontal unit vectors towards the free space.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplace.errors import UserError
from markerplace.markers import DEFAULT_TAG_SIZE
from markerplace.scene.raycast import RayCaster
from markerplace.scene.semantics import CATEGORIES, PartKind, classify
from markerplace.settings import OCCUPANCY_CELL, setting

__all__ = ["ALLOWABLE", "GEOMETRIC", "RULES", "CandidateConfig", "SurfaceLabels", "rule_words", "surface_shape",
           "tag_fits"]

UP = np.array([0.0, 0.0, 1.0])

GEOMETRIC = {"off-wall": "a surface standing off the wall that does not reach the ceiling (a picture, screen or "
                         "cupboard front nobody named)",
             "in-opening": "a panel set back into a wall opening (a door leaf or window nobody named)"}
ALLOWABLE: dict[str, str] = {**CATEGORIES, **GEOMETRIC}
"""What ``plan --allow`` can allow: the name categories, then the geometric rules."""
RULES = ("glass", *CATEGORIES, "does not fit", *GEOMETRIC)
"""The rules in the order they are applied and counted."""


def rule_words(rule: str, tag_size: float) -> str:
    """How the log and the report name the spots a rule removed (after their count)."""
    return {"glass": "on glass", "does not fit": f"where a {tag_size:g} m tag does not fit flat",
            "off-wall": "standing off the wall", "in-opening": "in a wall opening"}.get(rule, f"on {rule}")


def parse_allow(text: str | None) -> tuple[str, ...]:
    """``--allow``: comma list of :data:`ALLOWABLE` keys (``doors,furniture``); ``none`` or empty:
    nothing. Raises UserError for an unknown one."""
    if text is None:
        return ()
    items = [t.strip().lower() for t in str(text).split(",") if t.strip()]
    if items == ["none"]:
        return ()
    unknown = [t for t in items if t not in ALLOWABLE]
    if unknown:
        raise UserError(f"--allow {text!r}: unknown {', '.join(map(repr, unknown))}; choose from "
                        f"{', '.join(ALLOWABLE)} (comma-separated)")
    return tuple(dict.fromkeys(items))


@dataclass(frozen=True)
class CandidateConfig:
    """Settings of candidate marker poses (``plan --config``: the ``[discretize.candidates]`` table).

    The eye level (tag centres above the local floor) is the discretization's ``height`` and the
    tag size is the placement's ``tag_size``: both are passed to :func:`tag_fits` and
    :func:`~markerplace.plan.discretize.wall_candidates.wall_candidates`, never copied here.

    Attributes:
        marker_spacing: candidates are at least this far apart (metres) unless their normals
            differ by more than ``normal_diff_deg`` degrees.
        normal_diff_deg: see ``marker_spacing``.
        tag_border: white border around the black square that must be flat too, as a fraction
            of the tag size per side (0.25: the rendered tag's 2-bit quiet zone).
        flatness_tol: every sampled point of the tag square within this of the plane, metres.
        max_normal_z: |n_z| of a wall's face below this (near-vertical).
        scan_rays: rays per 360-degree scan.
        max_scan_range: range of a scan ray, metres.
        front_offset: the point this far in front of a wall spot must be free, metres.
        open_front: nothing may stand within this of the tag's face, over the whole tag and its
            border, metres (default 0.6: a tag half hidden behind the end of a wardrobe, or in a
            gap a person cannot stand in front of, is no spot anybody would pick).
        allow: keys of :data:`ALLOWABLE` whose spots stay candidates (default none: tags only
            on walls and columns).
        edge_step: a jump of more than this (metres) in the depth of the surface, within
            ``2 * profile_step``, ends it (the geometric rules; a picture 2 cm off the wall).
        profile_step: spacing of the depth samples of the geometric rules, metres.
        side_reach: how far left and right of the tag the geometric rules look, metres.
        max_standoff: a surface standing off the wall by more than this is not hung on it
            (``off-wall``), metres (a wardrobe is 0.6 m deep).
        max_reveal: a panel set back by more than this is not in a wall opening
            (``in-opening``), metres (the depth of a door's or window's reveal).
        ceiling_margin: a surface reaching within this of the ceiling reaches it, metres.
    """

    marker_spacing: float = setting(1.0, flag="--marker-spacing", bounds=(OCCUPANCY_CELL, 100.0), units="m",
                                    help="minimum spacing of candidate marker poses on a wall, metres",
                                    hint=f"the spacing of candidate markers in metres, e.g. 1.0 (not finer than "
                                         f"{OCCUPANCY_CELL:g} m)")
    normal_diff_deg: float = 30.0
    tag_border: float = 0.25
    flatness_tol: float = 0.02
    max_normal_z: float = 0.2
    scan_rays: int = 720
    max_scan_range: float = 10.0
    front_offset: float = 0.15
    open_front: float = 0.6
    allow: tuple[str, ...] = setting((), flag="--allow", metavar="CATEGORIES", convert=parse_allow, shown_default="none",
                                     help=lambda: "let tags go on these too, comma-separated: " + ", ".join(ALLOWABLE)
                                     + "; by default tags go only on walls and columns (named from the model's part "
                                       "names, IFC classes, transparency and geometry; see docs/cli.md)",
                                     doc=lambda: "let tags go on these too, comma-separated (see \"Where tags may go\" "
                                     "below): " + ", ".join(f"`{a}`" for a in ALLOWABLE) + "; by default tags go on "
                                     "walls and columns only. Changes the candidates, so the stages after the "
                                     "discretization run again")
    edge_step: float = 0.01
    profile_step: float = 0.02
    side_reach: float = 1.2
    max_standoff: float = 0.8
    max_reveal: float = 0.45
    ceiling_margin: float = 0.1


@dataclass(frozen=True, eq=False)
class SurfaceLabels:
    """What each face of the ray engine's mesh is, from the scene's parts.

    Attributes:
        face_part: (F,) part index of each face.
        transparent: (P,) bool per part (glass).
        kind: (P,) :class:`~markerplace.scene.semantics.PartKind` per part (from its names).
        name: (P,) part names.
    """

    face_part: np.ndarray
    transparent: np.ndarray
    kind: tuple
    name: tuple

    @classmethod
    def from_scene(cls, scene) -> "SurfaceLabels":
        """Labels of a :class:`~markerplace.scene.types.Scene` (faces as :meth:`Scene.geometry`)."""
        return cls(scene.face_part(), np.array([bool(p.transparent) for p in scene.parts], bool),
                   tuple(classify(p.names) for p in scene.parts), tuple(p.name for p in scene.parts))

    @classmethod
    def plain(cls, face_transparent: np.ndarray) -> "SurfaceLabels":
        """Labels of an unnamed mesh: one part per face, transparent where given."""
        t = np.asarray(face_transparent, bool)
        return cls(np.arange(len(t)), t, tuple(PartKind() for _ in t), tuple("" for _ in t))


def _tag_frame(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tag's frame for (M, 3) near-vertical wall normals: unit n, y = world up projected on
    the wall and x = y x n (the right of a viewer facing the wall), each (M, 3). For horizontal
    normals (the mesh plan's) y is world up exactly."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    y = np.tile(UP, (len(n), 1)) - n[:, 2:3] * n
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, n)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return n, x, y


def tag_fits(rc: RayCaster, centers: np.ndarray, normals: np.ndarray, config: CandidateConfig,
             opaque: np.ndarray | None = None, n_side: int = 7, tag_size: float = DEFAULT_TAG_SIZE) -> np.ndarray:
    """(M,) bool: a tag of ``tag_size`` (black-square edge, metres) plus border centred at each (M, 3) point lies flat, with
    ``open_front`` of open space in front of all of it.

    Rays along -normal from ``standoff = open_front`` in front of the wall, over an n_side x n_side
    grid of the tag square plus border, must all hit (a face that may carry a tag, when
    ``opaque`` (F,) bool is given: not glass, not a category that is not allowed) within
    ``flatness_tol`` of the plane through the centre, and the sample origins must be reachable
    from the point in front of the centre (a ray starting inside a perpendicular wall would
    otherwise hide an inner corner).
    """
    M = len(centers)
    if M == 0:
        return np.zeros(0, dtype=bool)
    standoff = float(config.open_front)
    h = tag_size * (0.5 + config.tag_border)
    a = np.linspace(-h, h, n_side)
    A, B = (v.ravel() for v in np.meshgrid(a, a))
    n, x, y = _tag_frame(normals)
    o = centers[:, None] + A[None, :, None] * x[:, None] + B[None, :, None] * y[:, None] + standoff * n[:, None]
    d = np.repeat(-n[:, None], len(A), axis=1)
    t, f = rc.first_hits(o.reshape(-1, 3), d.reshape(-1, 3), standoff + 0.3)
    t, f = t.reshape(M, -1), f.reshape(M, -1)
    ok = np.all(np.isfinite(t), axis=1)
    if opaque is not None:
        ok &= np.all(np.where(f >= 0, opaque[np.maximum(f, 0)], False), axis=1)
    front = centers + standoff * n
    off = o - front[:, None]
    length = np.linalg.norm(off, axis=2)
    lat = length > 1e-9
    rows = np.repeat(np.arange(M)[:, None], len(A), axis=1)[lat]
    tl, _ = rc.first_hits(front[rows], off[lat] / length[lat][:, None], length[lat])
    blocked = np.isfinite(tl)
    ok &= ~np.bincount(rows[blocked], minlength=M).astype(bool)
    dev = np.where(np.isfinite(t), np.abs(t - standoff), np.inf)
    return ok & np.all(dev <= config.flatness_tol, axis=1)


def _profile_edge(r: np.ndarray, count: np.ndarray, config: CandidateConfig, look: int = 10) -> dict[str, np.ndarray]:
    """Where a depth profile ends and what lies beyond.

    Args:
        r: (M, K) depth behind the tag's plane (metres; inf: nothing) at samples ``profile_step``
            apart going away from the tag centre (column 0 at the centre).
        count: (M,) number of valid samples per row (the rest are ignored).

    Returns:
        (M,) arrays: ``reached`` bool, no edge before the last valid sample; ``run`` metres from
        the centre to the edge; ``away`` bool, within ``look`` samples beyond the edge a
        surface lies behind the tag's surface by more than ``edge_step`` or nothing does
        within reach; ``deeper`` bool, the same with a surface at most ``max_standoff`` behind;
        ``shallower`` bool, not ``away`` and a surface lies at most ``max_reveal`` in front of
        it; ``end_away`` bool, the last valid sample is behind the surface before the edge by
        more than ``edge_step`` (or nothing is there).
    """
    from scipy.ndimage import median_filter

    M, K = r.shape
    rows, idx = np.arange(M), np.arange(K)
    last = np.maximum(count - 1, 0)
    r = np.where(idx[None] < count[:, None], r, r[rows, last][:, None])  # hold the last valid sample
    big = 1e3  # nothing within reach: a large depth, so that differences stay finite
    rf = median_filter(np.where(np.isfinite(r), r, big), size=(1, 5), mode="nearest")
    jump = np.zeros((M, K), bool)
    jump[:, 2:] = np.abs(rf[:, 2:] - rf[:, :-2]) > config.edge_step
    jump &= idx[None] < count[:, None]
    reached = ~jump.any(axis=1)
    e = np.where(reached, last, np.argmax(jump, axis=1))
    ref = rf[rows, np.maximum(e - 2, 0)]
    win = np.clip(e[:, None] + np.arange(look)[None], 0, K - 1)
    beyond = np.where(win < count[:, None], rf[rows[:, None], win] - ref[:, None], 0.0)
    away = np.any(beyond > config.edge_step, axis=1) & ~reached
    deeper = np.any((beyond > config.edge_step) & (beyond <= config.max_standoff), axis=1) & ~reached
    shallower = np.any((beyond < -config.edge_step) & (beyond >= -config.max_reveal), axis=1) & ~away & ~reached
    end_away = (rf[rows, last] - ref > config.edge_step) & ~reached
    return {"reached": reached, "run": e * config.profile_step, "away": away, "deeper": deeper,
            "shallower": shallower, "end_away": end_away}


def surface_shape(rc: RayCaster, centers: np.ndarray, normals: np.ndarray, floor_z: np.ndarray,
                  config: CandidateConfig, standoff: float = 0.3) -> dict[str, np.ndarray]:
    """The geometric rules for (M, 3) tag centres on surfaces with (M, 3) horizontal normals.

    Depth profiles (rays along -normal from ``standoff`` in front, ``profile_step`` apart) go
    from the centre up to the ceiling (found by a ray up from a point in front of the spot;
    ``ceiling_margin`` short of it), down to the floor (``floor_z`` (M,), world metres) and
    ``side_reach`` to the left and right; each ends where the depth jumps by more than
    ``edge_step`` (:func:`_profile_edge`).

    Returns:
        ``off-wall`` (M,) bool: going up, the surface ends below the ceiling with a surface
        behind it, and that stays so up to the ceiling (a picture or a cupboard in front of a
        wall) or the surface also ends so on its left, right or lower side (a picture on a wall
        under a lower ceiling part); or, under a ceiling, it ends going up with nothing behind
        it up to the ceiling (the side of a fridge; not a wall of a roofless scan); ``in-opening`` (M,) bool:
        going up, left and right it ends at surfaces in front of it (a door leaf in its
        opening); ``column`` (M,) bool: it reaches the ceiling, ends on both sides with surfaces
        behind it and is narrower than 1.2 m.
    """
    M = len(centers)
    if M == 0:
        z = np.zeros(0, bool)
        return {"off-wall": z, "in-opening": z, "column": z}
    n, x, up = _tag_frame(normals)
    step = config.profile_step
    front = centers + 0.1 * n
    t_up, _ = rc.first_hits(front, np.tile(UP, (M, 1)), 3.0)
    top = np.where(np.isfinite(t_up), t_up, 1.5) - config.ceiling_margin
    bottom = np.maximum(centers[:, 2] - np.asarray(floor_z, float) - 0.05, 0.0)
    reach = standoff + config.max_standoff + 0.05

    def profile(direction: np.ndarray, length: np.ndarray) -> dict[str, np.ndarray]:
        K = int(np.ceil(max(float(length.max()), step) / step)) + 1
        u = np.arange(K) * step
        o = centers[:, None] + u[None, :, None] * direction[:, None] + standoff * n[:, None]
        t, _ = rc.first_hits(o.reshape(-1, 3), np.repeat(-n, K, axis=0), reach)
        count = np.minimum(np.floor(length / step).astype(int) + 1, K)
        return _profile_edge(t.reshape(M, K) - standoff, count, config)

    top_, low = profile(up, top), profile(-up, bottom)
    left, right = profile(-x, np.full(M, config.side_reach)), profile(x, np.full(M, config.side_reach))
    # a surface with the wall behind its top edge; or, under a ceiling, one that ends in mid-air
    # (a roofless scan's walls end with nothing above them: still walls)
    roofed = np.isfinite(t_up)
    off_wall = ((top_["deeper"] & (top_["end_away"] | left["deeper"] | right["deeper"] | low["deeper"]))
                | (roofed & top_["away"] & top_["end_away"]))
    in_opening = top_["shallower"] & left["shallower"] & right["shallower"]
    column = top_["reached"] & left["deeper"] & right["deeper"] & (left["run"] + right["run"] < 1.2)
    return {"off-wall": off_wall, "in-opening": in_opening, "column": column}
