"""Candidate marker poses: wall spots at eye level that face free space, hold a flat tag and are
on structure that stays (a wall or a column, not a window, a door, a picture or a bookcase).

Per storey, every camera location takes a virtual 360-degree range scan at its eye level
(``scan_rays`` horizontal rays on the ray engine, up to ``max_scan_range``): the scan points on
near-vertical surfaces (|n_z| < ``max_normal_z``) whose front (a point ``front_offset`` in front
of the wall) is in the storey's free region are the wall spots, facing the scanning camera. As
in the paper they are downsampled uniformly along the perimeter of the free space
(``marker_spacing`` apart unless their normals differ by more than ``normal_diff_deg``) and
each tag stands ``height`` above the local floor in front of it. Rules a person would apply
remove spots, each spot counted under the first rule that removes it, in this order
(:data:`RULES`):

* ``glass``: the surface is transparent (:attr:`markerplace.scene.types.MeshPart.transparent`);
  never allowed.
* a category the part's names put it in (:mod:`markerplace.scene.semantics`: ``doors``,
  ``windows``, ``curtains``, ``mirrors``, ``screens``, ``furniture``, ``pictures``), unless
  the category is in ``allow``;
* ``does not fit``: the tag and its white border (``tag_border`` of the size per side) do not
  lie flat (within ``flatness_tol``) on surfaces that may carry it: a corner, a door opening, an
  edge, a surface smaller than the tag, something in front of the wall, or part of the square
  on glass or a category not allowed;
* ``off-wall`` (geometry; for parts no name puts in a category): the surface stands off the
  wall plane and does not reach the ceiling: going up from the tag it ends below the ceiling
  with the wall behind it (or nothing) up to the ceiling, or it ends so also on its left, right
  or lower side (a picture, a mirror, a screen, a cupboard front or a fridge's side nobody
  named);
* ``in-opening`` (geometry): the surface is set back into the wall: going up, left and right
  it ends at a surface up to ``max_reveal`` in front of it (a door leaf or a window panel in its
  opening, nobody named).

``allow`` lifts the categories and the two geometric rules it names. Counts are of the
uniformly spaced spots (first pass, no rules), so they add up: spots = the removed of every rule
+ those that pass. The chosen candidates (second pass) are those that pass, less any crowded out
by the next, plus the next spot along the wall that passes for each removed one (a picture
moves the tag beside it), so the candidates = pass - crowded + added. A last rule, no camera pose
sees the tag, needs rendered depth and is applied by the planner.

Each candidate records what it is on (:attr:`WallCandidates.surface`: ``"wall"``,
``"column"``, or for an allowed category e.g. ``"bookshelf front"``, ``"door"``) and the name of
the mesh part (:attr:`WallCandidates.part`).

The settings and the rules themselves live in :mod:`markerplace.plan.discretize.candidate_rules`.

Frames: world z up, metres; normals are horizontal unit vectors towards the free space.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from markerplace.markers import DEFAULT_TAG_SIZE
from markerplace.plan.discretize.candidate_rules import ALLOWABLE, GEOMETRIC, RULES, CandidateConfig, SurfaceLabels, surface_shape, tag_fits
from markerplace.plan.discretize.floorplan import StoreyFloor
from markerplace.plan.discretize.grid import Grid
from markerplace.plan.discretize.spacing import space_out as _space_out
from markerplace.scene.raycast import RayCaster
from markerplace.scene.semantics import CATEGORIES, PartKind

log = logging.getLogger(__name__)

__all__ = ["WallCandidates", "wall_candidates"]


@dataclass(frozen=True, eq=False)
class WallCandidates:
    """Candidate marker poses of all storeys, ordered by storey then along the perimeter.

    Attributes:
        position: (C, 3) tag centres, world metres.
        normal: (C, 3) unit horizontal wall normals towards the free space.
        storey: (C,) index of the storey (into the list given) of each candidate.
        arclength: (C,) position along the free-space perimeters (storeys' loops
            concatenated), metres.
        perimeter_length: total length of those loops, metres.
        removed: the first pass's counts: ``spots`` in all, the spots removed per rule of
            :data:`RULES` and ``pass``; and of the second pass ``crowded`` (passing spots
            crowded out) and ``added`` (spots beside removed ones): candidates = pass -
            crowded + added.
        surface: (C,) what each candidate is on: ``"wall"``, ``"column"``, or for an allowed
            category e.g. ``"bookshelf front"``.
        part: (C,) the name of the mesh part under each candidate's centre.
    """

    position: np.ndarray
    normal: np.ndarray
    storey: np.ndarray
    arclength: np.ndarray
    perimeter_length: float
    removed: dict = field(default_factory=dict)
    surface: np.ndarray = field(default_factory=lambda: np.zeros(0, str))
    part: np.ndarray = field(default_factory=lambda: np.zeros(0, str))


def perimeter(free: np.ndarray, grid: Grid, min_length: float = 0.5) -> tuple[np.ndarray, np.ndarray, float]:
    """Boundary loops of a free region: (P, 2) points, (P,) arclength, total length (metres)."""
    import cv2

    contours, _ = cv2.findContours(free.astype(np.uint8), cv2.RETR_LIST, cv2.CHAIN_APPROX_NONE)
    pts, arc, total = [], [], 0.0
    for cnt in contours:
        p = cnt.reshape(-1, 2).astype(float)  # (col, row)
        xy = np.column_stack([grid.x0 + (p[:, 0] + 0.5) * grid.res, grid.y0 + (p[:, 1] + 0.5) * grid.res])
        if len(xy) < 3:
            continue
        d = np.linalg.norm(np.diff(np.vstack([xy, xy[:1]]), axis=0), axis=1)
        length = float(d.sum())
        if length < min_length:
            continue
        pts.append(xy)
        arc.append(total + np.r_[0.0, np.cumsum(d[:-1])])
        total += length
    if not pts:
        return np.zeros((0, 2)), np.zeros(0), 0.0
    return np.vstack(pts), np.concatenate(arc), total


def _scan_points(rc: RayCaster, origins: np.ndarray, config: CandidateConfig, batch_rays: int = 2_000_000):
    """Horizontal 360-degree scans from (L, 3) origins: hit xy (P, 2), face (P,), origin xy (P, 2)."""
    R = config.scan_rays
    ang = 2 * np.pi * np.arange(R) / R
    dirs = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(R)])
    per = max(1, batch_rays // R)
    hit_xy, faces, org = [], [], []
    for s in range(0, len(origins), per):
        o = np.repeat(origins[s:s + per], R, axis=0)
        d = np.tile(dirs, (len(origins[s:s + per]), 1))
        t, f = rc.first_hits(o, d, config.max_scan_range)
        hit = f >= 0
        hit_xy.append((o[hit] + d[hit] * t[hit, None])[:, :2])
        faces.append(f[hit])
        org.append(o[hit, :2])
    if not hit_xy:
        return np.zeros((0, 2)), np.zeros(0, np.int64), np.zeros((0, 2))
    return np.concatenate(hit_xy), np.concatenate(faces), np.concatenate(org)


def _storey_spots(rc: RayCaster, grid: Grid, floor: StoreyFloor, free: np.ndarray, locations: np.ndarray,
                  config: CandidateConfig, height: float):
    """Wall spots of one storey ordered along its perimeter: xy, n2, z, face, arclength, floor z, length."""
    from scipy.spatial import cKDTree

    empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    per_xy, per_arc, per_len = perimeter(free, grid)
    if len(locations) == 0 or per_len == 0:
        return (*empty, per_len)
    hxy, face, oxy = _scan_points(rc, locations, config)
    n3 = rc.face_normal[face]
    vertical = (np.abs(n3[:, 2]) < config.max_normal_z) & (np.linalg.norm(n3[:, :2], axis=1) > 1e-6)
    hxy, face, oxy, n2 = hxy[vertical], face[vertical], oxy[vertical], n3[vertical, :2]
    n2 = n2 / np.linalg.norm(n2, axis=1, keepdims=True)
    n2[np.einsum("ij,ij->i", n2, oxy - hxy) < 0] *= -1
    front = hxy + config.front_offset * n2
    in_free = grid.lookup(free, front, False).astype(bool)
    hxy, face, n2, front = hxy[in_free], face[in_free], n2[in_free], front[in_free]
    # one spot per cell and normal octant (first seen wins: deterministic)
    r, c, _ = grid.cell(hxy)
    octant = np.floor((np.arctan2(n2[:, 1], n2[:, 0]) + np.pi) / (np.pi / 4)).astype(np.int64) % 8
    _, first = np.unique((r * grid.W + c) * 8 + octant, return_index=True)
    first = np.sort(first)
    hxy, face, n2, front = hxy[first], face[first], n2[first], front[first]
    dist, j = cKDTree(per_xy).query(hxy)
    near = dist <= 0.3
    hxy, face, n2, front, s = hxy[near], face[near], n2[near], front[near], per_arc[j[near]]
    order = np.lexsort((hxy[:, 1], hxy[:, 0], s))
    hxy, face, n2, front, s = hxy[order], face[order], n2[order], front[order], s[order]
    fz = grid.lookup(floor.height, front, np.nan)
    z = fz + height
    ok = np.isfinite(z)
    return hxy[ok], n2[ok], z[ok], face[ok], s[ok], fz[ok], per_len


def _surface_phrase(kind: PartKind, geometric: str | None, column: bool) -> str:
    """What a candidate is on, for the report and placement.json."""
    if kind.category in CATEGORIES:
        return f"{kind.noun} front" if kind.category == "furniture" else kind.noun
    if geometric == "off-wall":
        return "surface standing off the wall"
    if geometric == "in-opening":
        return "panel in a wall opening"
    return "column" if column or kind.noun == "column" else "wall"


def wall_candidates(rc: RayCaster, labels: SurfaceLabels | np.ndarray, grid: Grid, storeys: list,
                    config: CandidateConfig, height: float = 1.5, tag_size: float = DEFAULT_TAG_SIZE) -> WallCandidates:
    """Candidate marker poses of every storey (see the module docstring).

    Args:
        rc: the ray engine on the whole model.
        labels: what each face of ``rc`` is (:class:`SurfaceLabels`), or (F,) bool per face:
            transparent (an unnamed mesh).
        grid: the floor maps' grid.
        storeys: one ``(floor, free, locations)`` per storey: its
            :class:`~markerplace.plan.discretize.floorplan.StoreyFloor`, (H, W) bool free region and (L, 3)
            camera positions (eye level).
        config: settings.
        height: tag centres above the local floor, metres (the discretization's eye level).
        tag_size: black-square edge of the tag that must fit flat, metres.
    """
    if not isinstance(labels, SurfaceLabels):
        labels = SurfaceLabels.plain(labels)
    unknown = sorted(set(config.allow) - set(ALLOWABLE))
    if unknown:
        raise ValueError(f"unknown allow categories {unknown}; known: {list(ALLOWABLE)}")
    allow = set(config.allow)
    P = len(labels.kind)
    cat = np.array([k.category for k in labels.kind] or [""], dtype=object)[:P]
    named = np.array([c in CATEGORIES for c in cat], bool)
    forbidden_part = named & ~np.array([c in allow for c in cat], bool)
    # per face: glass, or a part whose name is a category not allowed, never carries a tag
    part_ok = ~labels.transparent & ~forbidden_part
    face_ok = part_ok[labels.face_part]
    cos_diff = np.cos(np.radians(config.normal_diff_deg))
    pos, nrm, sto, arc, surf, part_names = [], [], [], [], [], []
    removed = {"spots": 0, **{r: 0 for r in RULES}, "pass": 0, "crowded": 0, "added": 0}
    offset = 0.0
    geo_rules = [g for g in GEOMETRIC if g not in allow]
    for k, (floor, free, locations) in enumerate(storeys):
        xy, n2, z, face, s, fz, per_len = _storey_spots(rc, grid, floor, free,
                                                       np.asarray(locations, float).reshape(-1, 3), config,
                                                       height)
        Pt = np.column_stack([xy, z])
        N = np.column_stack([n2, np.zeros(len(n2))])
        part = labels.face_part[face] if len(face) else np.zeros(0, np.int64)
        reason = np.full(len(Pt), -1, np.int16)  # index into RULES; len(RULES): passes; -1 not tested yet
        shape_of: dict[int, str | None] = {}
        is_column = np.zeros(len(Pt), bool)

        def rules(idx: np.ndarray) -> np.ndarray:
            todo = idx[reason[idx] < 0]
            if len(todo):
                p = part[todo]
                why = np.full(len(todo), len(RULES), np.int16)
                why[labels.transparent[p]] = RULES.index("glass")
                for c in CATEGORIES:
                    hit = (why == len(RULES)) & (cat[p] == c) & (c not in allow)
                    why[hit] = RULES.index(c)
                go = np.flatnonzero(why == len(RULES))
                if len(go):
                    fits = tag_fits(rc, Pt[todo[go]], N[todo[go]], config, face_ok, tag_size=tag_size)
                    why[go[~fits]] = RULES.index("does not fit")
                    go = go[fits]
                unnamed = go[~named[p[go]]]
                if len(unnamed):
                    shape = surface_shape(rc, Pt[todo[unnamed]], N[todo[unnamed]], fz[todo[unnamed]], config)
                    is_column[todo[unnamed]] = shape["column"]
                    for g in GEOMETRIC:
                        hit = shape[g] & (why[unnamed] == len(RULES))
                        if g in geo_rules:
                            why[unnamed[hit]] = RULES.index(g)
                        else:
                            for i in todo[unnamed[hit]]:
                                shape_of[int(i)] = g
                reason[todo] = why
            return reason[idx] == len(RULES)

        nominal = np.asarray(_space_out(xy, n2, config.marker_spacing, cos_diff, lambda idx: np.ones(len(idx), bool)), int)
        passes = rules(nominal)
        removed["spots"] += len(nominal)
        for i, rule in enumerate(RULES):
            removed[rule] += int((reason[nominal] == i).sum())
        removed["pass"] += int(passes.sum())
        chosen = np.asarray(_space_out(xy, n2, config.marker_spacing, cos_diff, rules), int)
        passing = set(nominal[passes].tolist())
        kept = sum(1 for c in chosen.tolist() if c in passing)
        removed["crowded"] += int(passes.sum()) - kept
        removed["added"] += len(chosen) - kept
        pos.append(Pt[chosen])
        nrm.append(N[chosen])
        sto.append(np.full(len(chosen), k, np.int64))
        arc.append(s[chosen] + offset)
        surf += [_surface_phrase(labels.kind[part[c]], shape_of.get(int(c)), bool(is_column[c])) for c in chosen]
        part_names += [labels.name[part[c]] for c in chosen]
        offset += per_len
    if not pos or not sum(len(p) for p in pos):
        return WallCandidates(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0), float(offset),
                              removed, np.zeros(0, "<U1"), np.zeros(0, "<U1"))
    return WallCandidates(np.concatenate(pos), np.concatenate(nrm), np.concatenate(sto), np.concatenate(arc),
                          float(offset), removed, np.array(surf, dtype=str), np.array(part_names, dtype=str))
