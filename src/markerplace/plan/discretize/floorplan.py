"""Where people can stand on one storey: its floor map, and which eye-level cells lie inside the
building.

The standable surfaces and the storey floor heights come from :mod:`markerplace.plan.discretize.storeys`
(vertical rays through the whole model); walls come from horizontal cross-sections
(:mod:`markerplace.plan.discretize.freespace`).

A storey's floor map
--------------------
A storey with floor height F owns the standable surfaces within ``band`` of F: steps, a sunken
room, thresholds and ramps belong to it. Within the band:

1. cells need a ceiling when the storey has one over most of its floor (the ceiling mask is
   closed by ``ceiling_hole_fill`` first, so scan holes in a ceiling do not cut a room); this
   keeps free space inside the building when walls have holes, glass or open windows;
2. small holes in the floor (scan dropouts: nothing at all above them up to eye level) are
   filled by a closing of ``floor_hole_fill``;
3. *plateaus* are dropped: connected patches of even height whose border mostly drops to lower
   floor of the same storey (bed and sofa tops, low tables), while a sunken room's border steps
   up and is kept;
4. what remains must be reachable from the storey's main floor by steps of at most
   ``max_step`` between neighbouring cells.

The result per storey is a floor-height map (NaN where nobody stands) and the headroom above
it. Hand-written because no library of the field derives walkable floors of one storey from
a multi-storey mesh; the ray casting itself is Embree's.

Frames: world z up, metres. Grid cell (r, c) has centre ``(x0 + (c + .5) res, y0 + (r + .5) res)``
(:class:`~markerplace.plan.discretize.grid.Grid`); heights are world z, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplace.plan.discretize.grid import Grid
from markerplace.plan.discretize.storeys import FloorConfig, Surfaces
from markerplace.scene.raycast import RayCaster

__all__ = ["StoreyFloor", "storey_floor", "eye_level_support"]


@dataclass(frozen=True, eq=False)
class StoreyFloor:
    """Floor map of one storey on the column grid.

    Attributes:
        floor_z: the storey's floor height, world metres.
        height: (H, W) float64 local floor height where a person stands, NaN elsewhere.
        headroom: (H, W) float32 air above it, metres (NaN elsewhere).
        ceilings: whether the storey has ceilings (and cells were required to have one).
        band_area: standable area within the band before the ceiling/plateau/step rules, m^2.
    """

    floor_z: float
    height: np.ndarray
    headroom: np.ndarray
    ceilings: bool
    band_area: float

    @property
    def mask(self) -> np.ndarray:
        return np.isfinite(self.height)


def _disk(radius_cells: float) -> np.ndarray:
    r = int(np.ceil(radius_cells))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return ((xx * xx + yy * yy) <= radius_cells * radius_cells + 1e-9).astype(np.uint8)


def _close(mask: np.ndarray, radius_cells: float) -> np.ndarray:
    import cv2

    if radius_cells < 1:
        return mask
    k = _disk(radius_cells)
    pad = k.shape[0]
    m = np.pad(mask.astype(np.uint8), pad)
    m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, k)
    return m[pad:-pad, pad:-pad].astype(bool)


def _neighbour_edges(valid: np.ndarray, h: np.ndarray, max_dh: float) -> tuple[np.ndarray, np.ndarray]:
    """4-neighbour pairs (flat indices) of valid cells whose heights differ by at most ``max_dh``."""
    H, W = valid.shape
    idx = np.arange(H * W).reshape(H, W)
    a_list, b_list = [], []
    for (sa, sb) in (((slice(None), slice(0, W - 1)), (slice(None), slice(1, W))),
                     ((slice(0, H - 1), slice(None)), (slice(1, H), slice(None)))):
        ok = valid[sa] & valid[sb] & (np.abs(h[sa] - h[sb]) <= max_dh)
        a_list.append(idx[sa][ok])
        b_list.append(idx[sb][ok])
    return np.concatenate(a_list), np.concatenate(b_list)


def _components(n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n, n))
    return connected_components(g, directed=False)[1]


def storey_floor(surfaces: Surfaces, floor_z: float, ceilings: bool, config: FloorConfig = FloorConfig()) -> StoreyFloor:
    """The floor map of the storey whose floor is at ``floor_z`` (see the module docstring)."""
    from scipy.ndimage import distance_transform_edt

    g = surfaces.grid
    H, W = g.shape
    cell_area = g.res ** 2
    sel = np.abs(surfaces.z - floor_z) <= config.band
    cells, z, head = surfaces.cell[sel], surfaces.z[sel], surfaces.headroom[sel]
    # one surface per cell: the one closest to the floor height
    order = np.lexsort((np.abs(z - floor_z), cells))
    cells, z, head = cells[order], z[order], head[order]
    first = np.r_[True, cells[1:] != cells[:-1]]
    cells, z, head = cells[first], z[first], head[first]
    h = np.full(H * W, np.nan)
    hr = np.full(H * W, np.nan)
    h[cells] = z
    hr[cells] = head
    band_area = float(len(cells) * cell_area)
    valid = np.isfinite(h)
    if ceilings:
        has_ceiling = np.zeros(H * W, bool)
        has_ceiling[cells] = np.isfinite(head) & (head <= config.max_ceiling)
        has_ceiling = _close(has_ceiling.reshape(H, W), config.ceiling_hole_fill / g.res).ravel()
        valid &= has_ceiling
    h = h.reshape(H, W)
    hr = hr.reshape(H, W)
    valid = valid.reshape(H, W)
    h[~valid] = np.nan
    # fill small holes: height and headroom of the nearest valid cell
    # only where nothing at all stands between the band and eye level (furniture is no hole)
    something = np.zeros(H * W, bool)
    up_to_eye = (surfaces.z > floor_z + config.band) & (surfaces.z < floor_z + config.band + 1.5)
    something[surfaces.cell[up_to_eye]] = True
    filled = _close(valid, config.floor_hole_fill / g.res) & ~valid & ~something.reshape(H, W)
    if filled.any() and valid.any():
        _, (ri, ci) = distance_transform_edt(~valid, return_indices=True)
        h[filled] = h[ri[filled], ci[filled]]
        hr[filled] = hr[ri[filled], ci[filled]]
        valid = valid | filled
    h[~valid] = np.nan
    hr[~valid] = np.nan
    if valid.any():
        valid = _drop_plateaus(valid, h, floor_z, config)
        valid = _reachable(valid, h, floor_z, config)
        h = _even_out(valid, h, config)
    h[~valid] = np.nan
    hr[~valid] = np.nan
    return StoreyFloor(float(floor_z), h, hr.astype(np.float32), bool(ceilings), band_area)


def _drop_plateaus(valid: np.ndarray, h: np.ndarray, floor_z: float, config: FloorConfig) -> np.ndarray:
    """Remove even patches whose border mostly drops down to lower valid cells (furniture tops)."""
    H, W = valid.shape
    n = H * W
    hh = np.where(valid, h, np.nan)
    a, b = _neighbour_edges(valid, hh, config.even_tol)
    label = np.where(valid, _components(n, a, b).reshape(H, W), -1)
    border = np.zeros(n)
    drop = np.zeros(n)
    for (sa, sb) in (((slice(None), slice(0, W - 1)), (slice(None), slice(1, W))),
                     ((slice(0, H - 1), slice(None)), (slice(1, H), slice(None)))):
        la, lb, ha, hb = label[sa], label[sb], hh[sa], hh[sb]
        for l_self, l_other, h_self, h_other in ((la, lb, ha, hb), (lb, la, hb, ha)):
            m = (l_self != l_other) & (l_self >= 0)
            down = (l_other[m] >= 0) & (h_other[m] < h_self[m] - config.even_tol)
            border += np.bincount(l_self[m], minlength=n)
            drop += np.bincount(l_self[m], weights=down.astype(float), minlength=n)
    lab = label[valid]
    count = np.bincount(lab, minlength=n)
    mean_h = np.bincount(lab, weights=hh[valid], minlength=n) / np.maximum(count, 1)
    frac = drop / np.maximum(border, 1)
    # a patch at the storey's own floor height is never a plateau
    plateau = (frac > config.plateau_drop) & (np.abs(mean_h - floor_z) > 0.1)
    return valid & ~np.where(label >= 0, plateau[np.maximum(label, 0)], False)


def _reachable(valid: np.ndarray, h: np.ndarray, floor_z: float, config: FloorConfig) -> np.ndarray:
    """Valid cells reachable from the main floor (within 0.1 m of ``floor_z``) by small steps."""
    H, W = valid.shape
    hh = np.where(valid, h, np.nan)
    a, b = _neighbour_edges(valid, hh, config.max_step)
    label = _components(H * W, a, b).reshape(H, W)
    seeds = valid & (np.abs(hh - floor_z) <= 0.1)
    keep = np.zeros(H * W, bool)
    keep[np.unique(label[seeds])] = True
    return valid & keep[label]


def _even_out(valid: np.ndarray, h: np.ndarray, config: FloorConfig) -> np.ndarray:
    """Floor heights with scan noise removed: an even patch takes its median height (to 1 mm);
    sloped patches (ramps) keep their per-cell heights."""
    H, W = valid.shape
    hh = np.where(valid, h, np.nan)
    a, b = _neighbour_edges(valid, hh, config.even_tol)
    label = np.where(valid, _components(H * W, a, b).reshape(H, W), -1)
    out = hh.copy()
    lab = label[valid]
    vals = hh[valid]
    order = np.argsort(lab, kind="stable")
    lab_s, vals_s = lab[order], vals[order]
    starts = np.r_[0, np.flatnonzero(np.diff(lab_s)) + 1]
    ends = np.r_[starts[1:], len(lab_s)]
    med = np.empty(len(starts))
    spread = np.empty(len(starts))
    for i, (s, e) in enumerate(zip(starts, ends)):
        v = vals_s[s:e]
        med[i] = np.median(v)
        spread[i] = np.percentile(v, 95) - np.percentile(v, 5) if e - s > 2 else 0.0
    even = spread <= 0.04
    per_label = np.full(int(lab_s.max()) + 1 if len(lab_s) else 0, np.nan)
    per_label[lab_s[starts[even]]] = np.round(med[even], 3)
    smooth = per_label[np.maximum(label, 0)]
    use = valid & np.isfinite(smooth)
    out[use] = smooth[use]
    return out


def eye_level_support(rc: RayCaster, grid: Grid, floor: StoreyFloor, eye: float, orientation: str = "up",
                      config: FloorConfig = FloorConfig(), batch: int = 2_000_000) -> np.ndarray:
    """(H, W) bool: cells of a storey that are inside the building, in the open, at eye level.

    Something (floor or furniture) lies below the eye-level plane ``eye`` within the storey
    (not the void of a scan hole or a lower storey); when the storey has ceilings, a ceiling
    lies above (closed by ``ceiling_hole_fill``); and the eye-level point is not inside a closed
    solid (at least four of six axis rays from it first hit a face from its back; skipped for
    ``mixed`` windings).
    Cells under furniture are not standable but they are free at eye level, as in the paper's
    single cut: clearance is kept from walls, not from a desk.
    """
    n = grid.H * grid.W
    below = np.zeros(n, bool)
    above = np.zeros(n, bool)
    inside_solid = np.zeros(n, bool)
    lo = floor.floor_z - config.band
    sign = {"up": 1.0, "flipped": -1.0}.get(orientation, 0.0)
    down, up = np.array([0.0, 0.0, -1.0]), np.array([0.0, 0.0, 1.0])
    for s in range(0, n, batch):
        idx = np.arange(s, min(n, s + batch))
        r, c = np.divmod(idx, grid.W)
        o = np.column_stack([grid.centres(r, c), np.full(len(idx), eye)])
        t, f_down = rc.first_hits(o, np.tile(down, (len(idx), 1)), eye - lo)
        below[idx] = np.isfinite(t)
        t, f_up = rc.first_hits(o, np.tile(up, (len(idx), 1)), config.max_ceiling)
        above[idx] = np.isfinite(t)
        if sign:
            # inside a closed solid every face around is seen from its back; one wrongly wound
            # ceiling is not enough: ask six directions, inside when four or more say so
            maybe = np.flatnonzero((f_up >= 0) & (sign * rc.face_normal[np.maximum(f_up, 0), 2] > 0))
            if len(maybe):
                inside_solid[idx[maybe]] = _back_votes(rc, o[maybe], sign) >= 4
    support = below.reshape(grid.shape)
    if floor.ceilings:
        support &= _close(above.reshape(grid.shape), config.ceiling_hole_fill / grid.res)
    return (support | floor.mask) & ~inside_solid.reshape(grid.shape)


def _back_votes(rc: RayCaster, points: np.ndarray, sign: float) -> np.ndarray:
    """(M,) how many of six axis rays from each point first hit a face from its back side."""
    votes = np.zeros(len(points), np.int64)
    for d in np.vstack([np.eye(3), -np.eye(3)]):
        _, f = rc.first_hits(points, np.tile(d, (len(points), 1)))
        hit = f >= 0
        votes[hit] += (sign * (rc.face_normal[f[hit]] @ d) > 0)
    return votes

