"""Candidate marker poses: wall spots at eye level that face free space and hold a flat tag.

Per storey, every camera location takes a virtual 360-degree range scan at its eye level
(``scan_rays`` horizontal rays on the ray engine, up to ``max_scan_range``): the scan points on
near-vertical surfaces (|n_z| < ``max_normal_z``) whose front (a point ``front_offset`` in front
of the wall) is in the storey's free region are the wall spots, facing the scanning camera. As
in the paper they are downsampled uniformly along the perimeter of the free space
(``marker_spacing`` apart unless their normals differ by more than ``normal_diff_deg``) and
each tag stands ``height`` above the local floor in front of it. Rules a person would apply
remove spots, counted per rule:

* ``glass``: the wall there is transparent (:attr:`markerplace.scene.types.MeshPart.transparent`);
* ``does not fit``: the tag and its white border (``tag_border`` of the size per side) do not
  lie flat on one surface (within ``flatness_tol``): a corner, a door opening, an edge, a
  surface smaller than the tag, or something in front of the wall.

Counts are of the uniformly spaced spots (first pass, no rules); the chosen candidates (second
pass) replace a removed spot by the next one along the wall that passes. A third rule, no
camera pose sees the tag, needs rendered depth and is applied by the planner.

Frames: world z up, metres; normals are horizontal unit vectors towards the free space.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .floorplan import StoreyFloor
from .grid import Grid
from ..scene.raycast import RayCaster

log = logging.getLogger(__name__)

__all__ = ["CandidateConfig", "WallCandidates", "wall_candidates", "tag_fits"]

UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class CandidateConfig:
    """Settings of candidate marker poses.

    Attributes:
        height: tag centre above the local floor, metres (eye level).
        marker_spacing: candidates are at least this far apart (metres) unless their normals
            differ by more than ``normal_diff_deg`` degrees.
        normal_diff_deg: see ``marker_spacing``.
        tag_size: edge of the black square that must fit flat, metres.
        tag_border: white border around it that must be flat too, as a fraction of
            ``tag_size`` per side (0.25: the rendered tag's 2-bit quiet zone).
        flatness_tol: every sampled point of the tag square within this of the plane, metres.
        max_normal_z: |n_z| of a wall's face below this (near-vertical).
        scan_rays: rays per 360-degree scan.
        max_scan_range: range of a scan ray, metres.
        front_offset: the point this far in front of a wall spot must be free, metres.
    """

    height: float = 1.5
    marker_spacing: float = 1.0
    normal_diff_deg: float = 30.0
    tag_size: float = 0.4
    tag_border: float = 0.25
    flatness_tol: float = 0.02
    max_normal_z: float = 0.2
    scan_rays: int = 720
    max_scan_range: float = 10.0
    front_offset: float = 0.15


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
        removed: spots removed per rule (``glass``, ``does not fit``) and ``spots`` in all.
    """

    position: np.ndarray
    normal: np.ndarray
    storey: np.ndarray
    arclength: np.ndarray
    perimeter_length: float
    removed: dict = field(default_factory=dict)


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


def tag_fits(rc: RayCaster, centers: np.ndarray, normals: np.ndarray, config: CandidateConfig,
             opaque: np.ndarray | None = None, n_side: int = 7, standoff: float = 0.3) -> np.ndarray:
    """(M,) bool: a tag of ``tag_size`` plus border centred at each (M, 3) point lies flat.

    Short rays along -normal from ``standoff`` in front of the wall, over an n_side x n_side
    grid of the tag square plus border, must all hit (an opaque face, when ``opaque`` (F,) is
    given) within ``flatness_tol`` of the plane through the centre, and the sample origins must
    be reachable from the point in front of the centre (a ray starting inside a perpendicular
    wall would otherwise hide an inner corner).
    """
    M = len(centers)
    if M == 0:
        return np.zeros(0, dtype=bool)
    h = config.tag_size * (0.5 + config.tag_border)
    a = np.linspace(-h, h, n_side)
    A, B = (v.ravel() for v in np.meshgrid(a, a))
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    x = np.cross(np.tile(UP, (M, 1)), n)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.tile(UP, (M, 1))
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


def _space_out(xy: np.ndarray, n2: np.ndarray, spacing: float, cos_diff: float,
               accept: Callable[[np.ndarray], np.ndarray], batch: int = 32) -> list[int]:
    """Greedy uniform downsampling in the given order: keep a point unless a kept point with a
    similar normal is closer than ``spacing``; ``accept(indices) -> bool`` is asked in batches
    and a refused point does not block its neighbours."""
    kept: list[int] = []
    i, P = 0, len(xy)
    while i < P:
        idx: list[int] = []
        KX, KN = xy[kept].reshape(-1, 2), n2[kept].reshape(-1, 2)
        while i < P and len(idx) < batch:
            if len(KX) and np.any((np.linalg.norm(KX - xy[i], axis=1) < spacing) & (KN @ n2[i] >= cos_diff)):
                i += 1
                continue
            if idx and np.any((np.linalg.norm(xy[idx] - xy[i], axis=1) < spacing) & (n2[idx] @ n2[i] >= cos_diff)):
                break  # decided after this batch is accepted or refused
            idx.append(i)
            i += 1
        if not idx:
            continue
        ok = accept(np.asarray(idx))
        for k, good in zip(idx, ok):
            if not good:
                continue
            if kept and np.any((np.linalg.norm(xy[kept] - xy[k], axis=1) < spacing) & (n2[kept] @ n2[k] >= cos_diff)):
                continue
            kept.append(k)
    return kept


def _storey_spots(rc: RayCaster, grid: Grid, floor: StoreyFloor, free: np.ndarray, locations: np.ndarray,
                  config: CandidateConfig):
    """Wall spots of one storey ordered along its perimeter: xy, n2, z, face, arclength, length."""
    from scipy.spatial import cKDTree

    empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0), np.zeros(0, np.int64), np.zeros(0))
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
    z = grid.lookup(floor.height, front, np.nan) + config.height
    ok = np.isfinite(z)
    return hxy[ok], n2[ok], z[ok], face[ok], s[ok], per_len


def wall_candidates(rc: RayCaster, face_transparent: np.ndarray, grid: Grid, storeys: list, config: CandidateConfig
                    ) -> WallCandidates:
    """Candidate marker poses of every storey (see the module docstring).

    Args:
        rc: the ray engine on the whole model.
        face_transparent: (F,) bool per face of ``rc``.
        grid: the floor maps' grid.
        storeys: one ``(floor, free, locations)`` per storey: its
            :class:`~markerplace.plan.floorplan.StoreyFloor`, (H, W) bool free region and (L, 3)
            camera positions (eye level).
        config: settings.
    """
    opaque = ~np.asarray(face_transparent, dtype=bool)
    cos_diff = np.cos(np.radians(config.normal_diff_deg))
    pos, nrm, sto, arc = [], [], [], []
    removed = {"spots": 0, "glass": 0, "does not fit": 0}
    offset = 0.0
    for k, (floor, free, locations) in enumerate(storeys):
        xy, n2, z, face, s, per_len = _storey_spots(rc, grid, floor, free, np.asarray(locations, float).reshape(-1, 3), config)
        P = np.column_stack([xy, z])
        N = np.column_stack([n2, np.zeros(len(n2))])

        verdict = np.full(len(P), -1, np.int8)  # -1 not tested yet, 0 refused, 1 accepted

        def rules(idx: np.ndarray) -> np.ndarray:
            todo = idx[verdict[idx] < 0]
            good = opaque[face[todo]]
            if good.any():
                good[good] = tag_fits(rc, P[todo[good]], N[todo[good]], config, opaque)
            verdict[todo] = good
            return verdict[idx] == 1

        nominal = np.asarray(_space_out(xy, n2, config.marker_spacing, cos_diff, lambda idx: np.ones(len(idx), bool)), int)
        glass = ~opaque[face[nominal]]
        fits = rules(nominal)
        removed["spots"] += len(nominal)
        removed["glass"] += int(glass.sum())
        removed["does not fit"] += int((~glass & ~fits).sum())
        chosen = np.asarray(_space_out(xy, n2, config.marker_spacing, cos_diff, rules), int)
        pos.append(P[chosen])
        nrm.append(N[chosen])
        sto.append(np.full(len(chosen), k, np.int64))
        arc.append(s[chosen] + offset)
        offset += per_len
    if not pos:
        return WallCandidates(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0), 0.0, removed)
    return WallCandidates(np.concatenate(pos), np.concatenate(nrm), np.concatenate(sto), np.concatenate(arc),
                          float(offset), removed)
