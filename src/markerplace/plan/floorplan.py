"""Where people can stand: storeys and per-storey floor maps of a model, from vertical rays.

Vertical rays on a regular xy grid (one per cell) are cast down through the whole model with
the ray engine (:class:`markerplace.scene.raycast.RayCaster`), keeping every surface each ray crosses.
A *standable surface* is a near-horizontal surface (face |n_z| >= ``min_floor_nz``, either face
side: scans have inconsistent normals) with at least ``headroom`` metres of air above it up to
the next surface. Its *ceiling* is that next surface when it is at most ``max_ceiling`` above.
Walls are invisible to vertical rays; they come from horizontal cross-sections
(:mod:`markerplace.plan.freespace`).

Storeys
-------
Standable area under a ceiling is histogrammed by height. The heaviest height is the first
storey's floor; more floors are taken in order of area when they hold at least
``min_storey_area`` (and ``min_storey_frac`` of the largest) and lie ``min_storey_separation``
from every floor already taken, so table, bed and stair tops never become storeys. Standable
area without a ceiling (roof tops, terrain around the building, an open-top model, a storey
whose ceiling a scan missed) then adds storeys only where walls cross its eye level.

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

Frames: world z up, metres. Grid cell (r, c) has centre ``(x0 + (c + .5) res, y0 + (r + .5) res)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..scene.raycast import RayCaster

log = logging.getLogger(__name__)

__all__ = ["Grid", "FloorConfig", "Surfaces", "StoreyFloor", "cast_columns", "find_storeys", "storey_floor",
           "eye_level_support"]


@dataclass(frozen=True)
class Grid:
    """A regular xy grid: ``H`` rows from ``y0`` up, ``W`` columns from ``x0``, cells of ``res`` metres."""

    x0: float
    y0: float
    res: float
    H: int
    W: int

    @classmethod
    def covering(cls, lo: np.ndarray, hi: np.ndarray, res: float, margin: float = 0.5) -> "Grid":
        """The grid of cell size ``res`` covering the xy box [lo, hi] plus ``margin`` metres,
        its corner on a multiple of ``res`` (two models of one building share cells)."""
        lo = np.floor((np.asarray(lo, dtype=float)[:2] - margin) / res) * res
        hi = np.asarray(hi, dtype=float)[:2] + margin
        return cls(float(lo[0]), float(lo[1]), float(res), int(np.ceil((hi[1] - lo[1]) / res)),
                   int(np.ceil((hi[0] - lo[0]) / res)))

    @property
    def shape(self) -> tuple[int, int]:
        return (self.H, self.W)

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World xy -> continuous pixel coordinates (col, row) with cell centres at integers."""
        xy = np.asarray(xy, dtype=float)
        return np.stack([(xy[..., 0] - self.x0) / self.res - 0.5, (xy[..., 1] - self.y0) / self.res - 0.5], axis=-1)

    def cell(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside) integer cells of (M, 2) world xy points (clipped into the grid)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            c = np.floor((xy[:, 0] - self.x0) / self.res)
            r = np.floor((xy[:, 1] - self.y0) / self.res)
        inside = (c >= 0) & (c < self.W) & (r >= 0) & (r < self.H)
        c = np.clip(np.nan_to_num(c), 0, self.W - 1).astype(np.int64)
        r = np.clip(np.nan_to_num(r), 0, self.H - 1).astype(np.int64)
        return r, c, inside

    def centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(M, 2) world xy of cell centres."""
        return np.column_stack([self.x0 + (np.asarray(cols) + 0.5) * self.res,
                                self.y0 + (np.asarray(rows) + 0.5) * self.res])

    def lookup(self, image: np.ndarray, xy: np.ndarray, outside=0):
        """(M,) values of an (H, W) image at world xy points (``outside`` where off the grid)."""
        r, c, inside = self.cell(xy)
        return np.where(inside, image[r, c], outside)


@dataclass(frozen=True)
class FloorConfig:
    """How floors and storeys are found (see the module docstring).

    Attributes:
        headroom: air above a standable surface, metres.
        max_ceiling: a surface above counts as a ceiling up to this far, metres.
        min_floor_nz: |n_z| of a standable surface's face (0.85: slopes up to ~32 deg).
        band: a storey owns standable surfaces within this of its floor height, metres.
        max_step: largest height change between neighbouring cells a person steps over, metres.
        min_storey_area: a storey's floor holds at least this much standable area, m^2.
        min_storey_frac: ... and at least this fraction of the largest storey's.
        min_storey_separation: storey floors are at least this far apart in z, metres.
        ceiling_hole_fill: holes in a ceiling narrower than twice this are closed, metres.
        floor_hole_fill: holes in a floor narrower than twice this are filled, metres.
        even_tol: neighbouring cells within this height difference belong to one even patch, metres.
        plateau_drop: a patch whose border drops to lower floor on more than this fraction is a
            plateau (furniture top), not floor.
        max_cells: the column grid is coarsened above this many cells (memory), a warning says so.
    """

    headroom: float = 1.8
    max_ceiling: float = 10.0
    min_floor_nz: float = 0.85
    band: float = 0.5
    max_step: float = 0.3
    min_storey_area: float = 4.0
    min_storey_frac: float = 0.05
    min_storey_separation: float = 2.0
    ceiling_hole_fill: float = 0.5
    floor_hole_fill: float = 0.1
    even_tol: float = 0.03
    plateau_drop: float = 0.5
    max_cells: int = 8_000_000


@dataclass(frozen=True, eq=False)
class Surfaces:
    """Standable surfaces of every column of a grid.

    Attributes:
        grid: the column grid.
        cell: (K,) flat cell index (row * W + col) of each standable surface.
        z: (K,) height, world metres.
        headroom: (K,) air above it up to the next surface, metres (inf: nothing above).
        orientation: ``up`` (floors face up), ``flipped`` (the mesh's normals point into its
            solids) or ``mixed`` (no consistent winding: both sides of a face count).
    """

    grid: Grid
    cell: np.ndarray
    z: np.ndarray
    headroom: np.ndarray
    orientation: str = "up"

    def has_ceiling(self, max_ceiling: float) -> np.ndarray:
        return np.isfinite(self.headroom) & (self.headroom <= max_ceiling)


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


def cast_columns(rc: RayCaster, grid: Grid, config: FloorConfig = FloorConfig(), batch: int = 1_000_000) -> Surfaces:
    """Standable surfaces under every cell centre of ``grid`` (see the module docstring).

    Either side of a face counts (a floor may be a single sheet wound either way). The winding
    of the mesh is voted by the area of these surfaces that have something above them (a
    column's top surface may be a roof, front side up, or a bare ceiling, back side up): floors
    seen from the front mean ``up``, from the back ``flipped``, no clear majority ``mixed``.
    :func:`eye_level_support` uses it to tell the inside of closed solids.
    """
    if rc.num_faces == 0:
        return Surfaces(grid, np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    zmax = float(rc.vertices[:, 2].max()) + 1.0
    zmin = float(rc.vertices[:, 2].min()) - 1.0
    parts = []
    n = grid.H * grid.W
    for s in range(0, n, batch):
        idx = np.arange(s, min(n, s + batch))
        r, c = np.divmod(idx, grid.W)
        o = np.column_stack([grid.centres(r, c), np.full(len(idx), zmax)])
        ray, t, face = rc.all_hits(o, np.tile([0.0, 0.0, -1.0], (len(idx), 1)), zmax - zmin)
        if len(ray) == 0:
            continue
        z = zmax - t
        same = np.r_[False, ray[1:] == ray[:-1]]
        # one surface per 1 cm (shared edges and double-sided thin sheets report twice)
        dup = same & (np.r_[np.inf, z[:-1] - z[1:]] < 0.01)
        ray, z, face = ray[~dup], z[~dup], face[~dup]
        same = np.r_[False, ray[1:] == ray[:-1]]
        head = np.where(same, np.r_[np.inf, z[:-1]], np.inf) - z
        nz = rc.face_normal[face, 2]
        cand = (np.abs(nz) >= config.min_floor_nz) & (head >= config.headroom)
        parts.append((idx[ray[cand]], z[cand], head[cand], nz[cand] > 0))
    if not parts:
        return Surfaces(grid, np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    cell, z, head, front = (np.concatenate(v) for v in zip(*parts))
    voters = np.isfinite(head)
    up = float(front[voters].mean()) if voters.any() else 1.0
    if up >= 0.8:
        orientation = "up"
    elif up <= 0.2:
        orientation = "flipped"
        log.warning("floors: face normals point into the solids (%.0f %% of floor area seen from the back); "
                    "reading the mesh with flipped normals", 100 * (1 - up))
    else:
        orientation = "mixed"
        log.warning("floors: face normals are inconsistent (%.0f %% of floor area seen from the front); "
                    "the inside of closed furniture cannot be told from open space", 100 * up)
    return Surfaces(grid, cell, z, head, orientation)


def _peaks(z: np.ndarray, cell_area: float, bin_w: float = 0.05, radius: float = 0.15) -> list[tuple[float, float]]:
    """Heights holding most standable area, heaviest first: (floor z to 1 mm, area m^2)."""
    if len(z) == 0:
        return []
    lo = np.floor(z.min() / bin_w) * bin_w
    bins = np.floor((z - lo) / bin_w).astype(np.int64)
    remaining = np.bincount(bins) * cell_area
    centres = lo + (np.arange(len(remaining)) + 0.5) * bin_w
    peaks = []
    for _ in range(64):
        b = int(np.argmax(remaining))
        if remaining[b] <= 0:
            break
        fz = round(float(np.median(z[np.abs(z - centres[b]) <= radius])), 3) + 0.0  # no -0.0
        peaks.append((fz, float((np.abs(z - fz) <= radius).sum() * cell_area)))
        gone = np.abs(centres - fz) <= radius + bin_w
        gone[b] = True
        remaining[gone] = 0.0
    return peaks


def find_storeys(surfaces: Surfaces, config: FloorConfig = FloorConfig(),
                 has_walls: Callable[[float, float], bool] | None = None) -> tuple[list[float], list[bool]]:
    """Floor heights of the storeys (ascending, world metres) and whether each has ceilings.

    Floors under a ceiling come first (heaviest first, each ``min_storey_separation`` from the
    others); then floors without a ceiling (an open-top model, a storey whose ceiling a scan
    missed) when ``has_walls(floor z, area)`` says walls cross their eye level, which a roof top
    or the terrain around a building lacks (or, for terrain, it lies too close to a storey).
    """
    if len(surfaces.z) == 0:
        return [], []
    cell_area = surfaces.grid.res ** 2
    ceil = surfaces.has_ceiling(config.max_ceiling)
    floors: list[tuple[float, bool]] = []
    largest = 0.0
    for with_ceiling in (True, False):
        sel = ceil if with_ceiling else ~ceil
        for fz, a in _peaks(surfaces.z[sel], cell_area):
            if a < config.min_storey_area or a < config.min_storey_frac * largest:
                continue
            if any(abs(fz - g) < config.min_storey_separation for g, _ in floors):
                continue
            if not with_ceiling and has_walls is not None and not has_walls(fz, a):
                continue
            largest = max(largest, a)
            floors.append((fz, with_ceiling))
    floors.sort()
    return [f for f, _ in floors], [c for _, c in floors]


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

