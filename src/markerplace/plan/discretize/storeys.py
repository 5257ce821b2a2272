"""Storeys of a model from vertical rays: the standable surfaces of every grid column, and the
floor heights they form.

Vertical rays on a regular xy grid (one per cell) are cast down through the whole model with
the ray engine (:class:`markerplace.scene.raycast.RayCaster`), keeping every surface each ray crosses.
A *standable surface* is a near-horizontal surface (face |n_z| >= ``min_floor_nz``, either face
side: scans have inconsistent normals) with at least ``headroom`` metres of air above it up to
the next surface. Its *ceiling* is that next surface when it is at most ``max_ceiling`` above.
Walls are invisible to vertical rays; they come from horizontal cross-sections
(:mod:`markerplace.plan.discretize.freespace`).

Storeys
-------
Standable area under a ceiling is histogrammed by height. The heaviest height is the first
storey's floor; more floors are taken in order of area when they hold at least
``min_storey_area`` (and ``min_storey_frac`` of the largest) and lie ``min_storey_separation``
from every floor already taken, so table, bed and stair tops never become storeys. Standable
area without a ceiling (roof tops, terrain around the building, an open-top model, a storey
whose ceiling a scan missed) then adds storeys only where walls cross its eye level.

The floor map of one storey is built from these surfaces by :mod:`markerplace.plan.discretize.floorplan`.

Frames: world z up, metres. Grid cell (r, c) has centre ``(x0 + (c + .5) res, y0 + (r + .5) res)``
(:class:`~markerplace.plan.discretize.grid.Grid`); heights are world z, metres.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Callable

import numpy as np

from markerplace.plan.discretize.grid import Grid
from markerplace.scene.raycast import RayCaster

log = logging.getLogger(__name__)

__all__ = ["FloorConfig", "Surfaces", "cast_columns", "find_storeys"]


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
