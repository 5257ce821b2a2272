"""Free space of one storey at eye level, and the camera locations in it.

Obstacles are the model's horizontal cross-sections at a few heights around the storey's eye
level (``slice_offsets`` metres from the eye-level plane ``floor + height``), rasterized on the
floor map's grid: walls, glass, shelves, door frames. Several cuts close thin gaps in a scanned
wall that one cut would slip through. Free cells are cells inside the building at eye level
(:func:`markerplace.plan.discretize.floorplan.eye_level_support`: floor or furniture below, a ceiling above)
that no cut covers; as in the paper's single cut, a desk below eye level is free space (but no
camera stands on it).

Leaks through scan holes are cut off the way a person is: the free region is opened by
``passage_radius`` (cells closer than that to non-free space cannot be passed, then the
passable part grows back by the same radius), so a doorway connects rooms and a 20 cm hole
in a wall does not. The passable pieces kept are the one holding ``start`` when given, else
every piece of at least ``min_region_area``.

Camera locations are lattice points ``grid_spacing`` apart in the kept free region, at least
``clearance`` from non-free cells and with room for the camera under the ceiling; each stands
``height`` above its local floor (a sunken room's cameras are lower).

This is the paper's occupancy-grid discretization made robust to scans: a flood of the
occupancy grid instead of simulated range scans (which cannot tell a hole in a wall from a
doorway). Hand-written on numpy/OpenCV/SciPy morphology: no library of the field does it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from markerplace.plan.discretize.floorplan import StoreyFloor
from markerplace.plan.discretize.grid import Grid

log = logging.getLogger(__name__)

__all__ = ["Sections", "StoreySpace", "obstacle_mask", "free_space", "open_fractions", "camera_locations"]

_SHIFT = 4  # cv2 fixed-point bits


class Sections:
    """Horizontal cross-sections of a triangle mesh."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import trimesh

        self.mesh = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
        z = np.asarray(vertices, dtype=float)[np.asarray(faces, dtype=np.int64), 2]
        self.zlo = z.min(axis=1) if len(z) else np.zeros(0)
        self.zhi = z.max(axis=1) if len(z) else np.zeros(0)

    def at(self, z: float) -> tuple[np.ndarray, np.ndarray]:
        """(S, 2, 2) xy segments where the plane at height ``z`` cuts the mesh, (S,) face indices."""
        from trimesh.intersections import mesh_plane

        cand = np.flatnonzero((self.zlo <= z) & (self.zhi >= z))
        if len(cand) == 0:
            return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64)
        segs, faces = mesh_plane(self.mesh, plane_normal=[0, 0, 1], plane_origin=[0, 0, z],
                                 return_faces=True, local_faces=cand)
        segs = np.asarray(segs, dtype=float).reshape(-1, 2, 3)[:, :, :2]
        faces = np.asarray(faces, dtype=np.int64).reshape(-1)
        keep = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) > 1e-9
        return segs[keep], faces[keep]


def obstacle_mask(grid: Grid, sections: Sections, heights) -> tuple[np.ndarray, list[int]]:
    """(H, W) bool cells crossed by the cross-sections at ``heights``, and the segment count of each."""
    import cv2

    mask = np.zeros(grid.shape, dtype=np.uint8)
    n = []
    for z in heights:
        seg, _ = sections.at(float(z))
        n.append(len(seg))
        if len(seg):
            pts = np.round(grid.to_px(seg) * (1 << _SHIFT)).astype(np.int32)
            cv2.polylines(mask, list(pts.reshape(-1, 2, 1, 2)), False, 1, thickness=1, lineType=cv2.LINE_8, shift=_SHIFT)
    return mask.astype(bool), n


@dataclass(frozen=True, eq=False)
class StoreySpace:
    """Free space of one storey.

    Attributes:
        free: (H, W) bool, the kept free region.
        occupancy: (H, W) int8: 0 free (kept), 1 obstacle at eye level, -1 anything else.
        unreached: list of (area m^2, centre xy) of floor regions of at least 1 m^2 outside the
            kept region (behind a gap narrower than a person, or not connected to ``start``).
        free_area: area of the kept free region, m^2.
    """

    free: np.ndarray
    occupancy: np.ndarray
    unreached: list
    free_area: float


def free_space(grid: Grid, support: np.ndarray, obstacle: np.ndarray, *, passage_radius: float,
               min_region_area: float, start: np.ndarray | None = None) -> StoreySpace:
    """The kept free region of a storey (see the module docstring).

    Args:
        grid: the floor map's grid.
        support: (H, W) bool cells inside the building at eye level
            (:func:`markerplace.plan.discretize.floorplan.eye_level_support`).
        obstacle: (H, W) bool eye-level obstacles.
        passage_radius: half the narrowest passage a person takes, metres.
        min_region_area: without ``start``, pieces smaller than this (m^2) are dropped.
        start: (2,) world xy: keep only the piece holding it (or nearest within a cell).
    """
    from scipy.ndimage import distance_transform_edt, label

    cell_area = grid.res ** 2
    free0 = support & ~obstacle
    clear = distance_transform_edt(free0) * grid.res
    passable = clear >= passage_radius
    lab, n = label(passable, structure=np.ones((3, 3), bool))
    keep = np.zeros(n + 1, bool)
    if n:
        if start is not None:
            r, c, inside = grid.cell(np.asarray(start, float)[None])
            if inside[0]:
                win = max(1, int(round(passage_radius / grid.res)) + 1)
                r0, r1 = max(0, r[0] - win), min(grid.H, r[0] + win + 1)
                c0, c1 = max(0, c[0] - win), min(grid.W, c[0] + win + 1)
                ids = lab[r0:r1, c0:c1]
                if (ids > 0).any():
                    rr, cc = np.nonzero(ids > 0)
                    k = np.argmin((rr + r0 - r[0]) ** 2 + (cc + c0 - c[0]) ** 2)
                    keep[ids[rr[k], cc[k]]] = True
        else:
            # area of each piece once grown back by the passage radius
            grown_lab = _grow_labels(lab, passage_radius / grid.res, free0)
            area = np.bincount(grown_lab.ravel(), minlength=n + 1) * cell_area
            keep[1:] = area[1:] >= min_region_area
    kept = keep[lab]
    if kept.any():
        free = free0 & (distance_transform_edt(~kept) * grid.res <= passage_radius + 0.5 * grid.res)
    else:
        free = np.zeros_like(free0)
    occupancy = np.full(grid.shape, -1, dtype=np.int8)
    occupancy[obstacle] = 1
    occupancy[free] = 0
    # floor regions left out, for the log
    rest_lab, m = label(free0 & ~free, structure=np.ones((3, 3), bool))
    unreached = []
    if m:
        areas = np.bincount(rest_lab.ravel(), minlength=m + 1) * cell_area
        for i in np.flatnonzero(areas >= 1.0):
            if i == 0:
                continue
            rr, cc = np.nonzero(rest_lab == i)
            unreached.append((float(areas[i]), grid.centres(np.array([rr.mean()]), np.array([cc.mean()]))[0]))
        unreached.sort(key=lambda t: -t[0])
    return StoreySpace(free, occupancy, unreached, float(free.sum() * cell_area))


def open_fractions(rc, grid: Grid, free: np.ndarray, eye: float, *, reach: float, rays: int = 24,
                   spacing: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How open to the outside each connected piece of ``free`` is at eye level.

    From cells of each piece (a lattice ``spacing`` apart, at least one cell per piece),
    ``rays`` horizontal rays at height ``eye``; a ray that hits nothing within ``reach`` metres
    leaves the model. Inside a room almost every ray ends on a wall (a glassless window lets a
    few out); on a strip under the eaves, a porch or a balcony about half of them or more leave.

    Args:
        rc: the model's :class:`~markerplace.scene.raycast.RayCaster`.
        grid: the floor map's grid.
        free: (H, W) bool free cells.
        eye: eye-level height, metres.
        reach: ray length, metres.
        rays: directions per sample, evenly spaced in yaw.
        spacing: distance between sample cells, metres.

    Returns:
        (H, W) int32 piece labels (0 outside ``free``; 8-connected), (N + 1,) float64 fraction
        of rays leaving per label (index 0 unused, 0.0), (N + 1,) float64 area per label, m^2.
    """
    from scipy.ndimage import label

    lab, n = label(free, structure=np.ones((3, 3), bool))
    frac = np.zeros(n + 1)
    area = np.bincount(lab.ravel(), minlength=n + 1) * grid.res ** 2
    if n == 0:
        return lab, frac, area
    step = max(1, int(round(spacing / grid.res)))
    rr, cc = np.nonzero(lab)
    on_lattice = (rr % step == 0) & (cc % step == 0)
    ids = lab[rr, cc]
    pick = on_lattice | ~np.isin(ids, np.unique(ids[on_lattice]))  # a piece off the lattice: all its cells
    rr, cc, ids = rr[pick], cc[pick], ids[pick]
    ang = 2 * np.pi * np.arange(rays) / rays
    dirs = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(rays)])
    origins = np.column_stack([grid.centres(rr, cc), np.full(len(rr), eye)])
    t, _ = rc.first_hits(np.repeat(origins, rays, axis=0), np.tile(dirs, (len(rr), 1)), reach)
    leaves = ~np.isfinite(t).reshape(-1, rays)
    frac[1:] = np.bincount(ids, weights=leaves.mean(axis=1), minlength=n + 1)[1:] / np.maximum(
        np.bincount(ids, minlength=n + 1)[1:], 1)
    return lab, frac, area


def _grow_labels(lab: np.ndarray, radius_cells: float, within: np.ndarray) -> np.ndarray:
    """Labels spread to cells within ``radius_cells`` of their piece, inside ``within``."""
    from scipy.ndimage import distance_transform_edt

    dist, (ri, ci) = distance_transform_edt(lab == 0, return_indices=True)
    grown = lab[ri, ci]
    return np.where(within & (dist <= radius_cells + 0.5), grown, 0)


def camera_locations(grid: Grid, floor: StoreyFloor, free: np.ndarray, *, grid_spacing: float,
                     clearance: float, height: float, stand_radius: float = 0.1, rc=None,
                     floor_tol: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Camera locations of a storey: (L, 2) world xy on the lattice ``(i + 1/2) grid_spacing``, (L,) z.

    A location is a lattice point in ``free`` with standable floor (``floor.mask``: not a
    table) within ``stand_radius`` around it, at least ``clearance`` metres from non-free cells,
    and, with the ray engine ``rc``, its floor straight below (within ``floor_tol``: no thin
    furniture part between grid rays), with headroom above ``height``
    + 0.1 m; its z is its local floor plus ``height``.
    Ordered row-major (y, then x).
    """
    from scipy.ndimage import distance_transform_edt

    # lattice anchored at the world origin, (i + 1/2) * grid_spacing: the same for any model of the building
    i0, i1 = np.floor(grid.x0 / grid_spacing - 0.5), np.ceil((grid.x0 + grid.W * grid.res) / grid_spacing - 0.5)
    j0, j1 = np.floor(grid.y0 / grid_spacing - 0.5), np.ceil((grid.y0 + grid.H * grid.res) / grid_spacing - 0.5)
    gx, gy = np.meshgrid((np.arange(i0, i1 + 1) + 0.5) * grid_spacing, (np.arange(j0, j1 + 1) + 0.5) * grid_spacing)
    pts = np.column_stack([gx.ravel(), gy.ravel()])
    clear = distance_transform_edt(free) * grid.res
    stand = distance_transform_edt(floor.mask) * grid.res  # room for the person's feet
    r, c, inside = grid.cell(pts)
    ok = (inside & free[r, c] & (stand[r, c] >= stand_radius) & (clear[r, c] >= clearance)
          & (floor.headroom[r, c] >= height + 0.1))
    pts, r, c = pts[ok], r[ok], c[ok]
    z = floor.height[r, c].astype(np.float64) + height
    if rc is not None and len(pts):  # exactly below the camera, its floor (no thin furniture part)
        t, _ = rc.first_hits(np.column_stack([pts, z]), np.tile([0.0, 0.0, -1.0], (len(pts), 1)), height + 1.0)
        on_floor = np.abs(t - height) <= floor_tol
        pts, z = pts[on_floor], z[on_floor]
    return pts, z
