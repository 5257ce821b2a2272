"""Discretization (paper, Methods: "Discretization"): feasible camera poses and candidate markers.

A horizontal plane at ``floor + height`` (eye level) is cut through the model. Free space in the
plane is mapped like a 2D range scanner would map it: 360-degree depth scans in the plane, from
a start point and then from newly seen free space until no unseen space is reachable, fill an
occupancy grid. Feasible camera locations are grid-cell centres (``grid_spacing`` apart) that
are free, keep ``clearance`` from anything non-free, and stand on the level's floor (not on a
table). Each location gives ``num_yaws`` level camera poses. Candidate marker poses are scan
points on near-vertical surfaces, downsampled uniformly along the perimeter of the free space,
facing the surface normal, each checked to carry a flat tag of ``tag_size``.

Frames: world z up, metres (see :mod:`markerplace.geometry`). The occupancy grid has row 0 at
``grid_origin[1]`` and column 0 at ``grid_origin[0]`` (the lower-left corner), cells of
``grid_resolution`` metres; cell (r, c) has centre ``origin + ((c + .5) res, (r + .5) res)``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import geometry
from .errors import UserError
from .io_utils import write_npz

log = logging.getLogger(__name__)

__all__ = ["DiscretizeConfig", "Discretization", "discretize", "find_storeys", "save", "load"]


@dataclass(frozen=True)
class DiscretizeConfig:
    """Settings of the discretization stage.

    Attributes:
        height: plane height above the level's floor, metres (paper: eye level, 1.5).
        level: storey index; storeys are floor heights found from large upward-facing
            horizontal surfaces clustered by z (at least ``min_storey_separation`` apart);
            0 = lowest.
        start: (x, y) world metres where the first scan is taken, or None to choose one
            automatically (room centres when the scene knows its rooms, else the enclosed point
            with floor below and the largest clearance).
        grid_spacing: distance between camera locations, metres (paper: 0.5-0.7).
        clearance: minimum distance from a camera location to non-free space, metres.
        num_yaws: camera poses per location, yaw = 2 pi j / num_yaws (paper: 8).
        marker_spacing: candidate markers are at least this far apart (metres) unless their
            normals differ by more than ``normal_diff_deg``.
        normal_diff_deg: normals differing by more than this (degrees) count as different.
        tag_size: edge of the tag that must fit flat on the wall, metres.
        tag_border: white border around the black square that must be flat too, as a fraction
            of ``tag_size`` per side (0.25: the 2-bit quiet zone of the rendered 8-bit tag,
            see :mod:`markerplace.render.tags`).
        flatness_tol: tag corners (and the sampled square) on one plane within this, metres.
        max_normal_z: |n_z| of a candidate's surface normal must be below this (near-vertical).
        scan_rays: rays per 360-degree scan.
        max_scan_range: range of a scan ray, metres.
        resolution: occupancy cell size, metres.
        slab_offsets: extra plane offsets (metres) whose cross-sections also block rays, so thin
            gaps in the mesh at exactly the plane height do not leak.
        floor_tol: a location's first hit straight down must be within this of the floor, metres.
        max_scans: safety cap on the number of scans.
        frontier_radius: scans choose origins that see many unexplored boundary cells within
            this radius (metres); boundary cells within it are not pursued again afterwards.
        min_storey_separation: floors closer than this (metres) in z belong to one storey.
    """

    height: float = 1.5
    level: int = 0
    start: tuple[float, float] | None = None
    grid_spacing: float = 0.5
    clearance: float = 0.3
    num_yaws: int = 8
    marker_spacing: float = 1.0
    normal_diff_deg: float = 30.0
    tag_size: float = 0.4
    tag_border: float = 0.25
    flatness_tol: float = 0.02
    max_normal_z: float = 0.2
    scan_rays: int = 720
    max_scan_range: float = 30.0
    resolution: float = 0.05
    slab_offsets: tuple[float, ...] = (-0.05, 0.05)
    floor_tol: float = 0.05
    max_scans: int = 300
    frontier_radius: float = 1.5
    min_storey_separation: float = 2.0


@dataclass(frozen=True, eq=False)
class Discretization:
    """Feasible camera poses and candidate marker poses of one plane.

    Attributes:
        locations: (L, 2) camera locations, world xy metres.
        location_z: plane height (world z, metres) of all cameras and candidates.
        world_from_cam: (N, 4, 4) feasible camera poses, N = L * num_yaws, location-major
            (pose i is at location ``location_index[i]`` with yaw ``yaw[i]``).
        location_index: (N,) int64 index into ``locations``.
        yaw: (N,) radians, 2 pi j / num_yaws.
        candidate_world_from_marker: (C, 4, 4) candidate marker poses (tag centre on the wall,
            z = wall normal towards the free space), ordered by ``perimeter_arclength``.
        candidate_normal: (C, 3) unit horizontal wall normals (towards the free space).
        candidate_position: (C, 3) tag centres, world metres.
        perimeter_arclength: (C,) position of each candidate along the free-space perimeter,
            metres in [0, perimeter_length] (the perimeter loops concatenated).
        perimeter_length: total length of the free-space perimeter loops, metres.
        occupancy: (H, W) int8 grid: -1 unknown, 0 free, 1 occupied.
        grid_origin: (2,) world xy of the grid's lower-left corner, metres.
        grid_resolution: cell size, metres.
        floor_z: floor height of the level, world metres.
        storeys: (S,) floor heights of all storeys found, world metres, ascending.
        start: (2,) xy of the first scan.
        scan_origins: (K, 2) xy of all scans, in order.
    """

    locations: np.ndarray
    location_z: float
    world_from_cam: np.ndarray
    location_index: np.ndarray
    yaw: np.ndarray
    candidate_world_from_marker: np.ndarray
    candidate_normal: np.ndarray
    candidate_position: np.ndarray
    perimeter_arclength: np.ndarray
    perimeter_length: float
    occupancy: np.ndarray
    grid_origin: np.ndarray
    grid_resolution: float
    floor_z: float
    storeys: np.ndarray
    start: np.ndarray = field(default_factory=lambda: np.zeros(2))
    scan_origins: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @property
    def origin(self) -> np.ndarray:
        """Alias of :attr:`grid_origin`."""
        return self.grid_origin

    @property
    def resolution(self) -> float:
        """Alias of :attr:`grid_resolution`."""
        return self.grid_resolution

    @property
    def num_yaws(self) -> int:
        return int(len(self.world_from_cam) // max(len(self.locations), 1))


_ARRAY_FIELDS = ("locations", "world_from_cam", "location_index", "yaw", "candidate_world_from_marker",
                 "candidate_normal", "candidate_position", "perimeter_arclength", "occupancy", "grid_origin",
                 "storeys", "start", "scan_origins")
_SCALAR_FIELDS = ("location_z", "perimeter_length", "grid_resolution", "floor_z")


def save(d: Discretization, path: str | Path) -> None:
    """Write ``d`` to a compressed ``.npz`` (atomic, no pickled objects)."""
    arrays = {k: np.asarray(getattr(d, k)) for k in _ARRAY_FIELDS}
    arrays.update({k: np.asarray(float(getattr(d, k))) for k in _SCALAR_FIELDS})
    write_npz(path, **arrays)


def load(path: str | Path) -> Discretization:
    """Read a :class:`Discretization` written by :func:`save`."""
    with np.load(path, allow_pickle=False) as z:
        kw = {k: z[k] for k in _ARRAY_FIELDS}
        kw.update({k: float(z[k]) for k in _SCALAR_FIELDS})
    return Discretization(**kw)


# ----------------------------------------------------------------------------------------------
# mesh helpers


class _Mesh:
    """Triangles of a scene with per-face normals and bounding boxes, for ray queries."""

    def __init__(self, scene):
        V, F = scene.geometry()
        self.V, self.F = V, F
        self.tri = V[F]  # (F, 3, 3)
        n = np.cross(self.tri[:, 1] - self.tri[:, 0], self.tri[:, 2] - self.tri[:, 0])
        area2 = np.linalg.norm(n, axis=1)
        self.area = 0.5 * area2
        with np.errstate(invalid="ignore", divide="ignore"):
            self.normal = np.where(area2[:, None] > 0, n / np.maximum(area2, 1e-300)[:, None], 0.0)
        self.lo = self.tri.min(axis=1)
        self.hi = self.tri.max(axis=1)
        self._trimesh = None

    @property
    def trimesh(self):
        if self._trimesh is None:
            import trimesh

            self._trimesh = trimesh.Trimesh(vertices=self.V, faces=self.F, process=False)
        return self._trimesh

    def section(self, z: float) -> tuple[np.ndarray, np.ndarray]:
        """Cross-section with the plane at height z: (S, 2, 2) xy segments and (S,) face indices."""
        from trimesh.intersections import mesh_plane

        cand = np.flatnonzero((self.lo[:, 2] <= z) & (self.hi[:, 2] >= z))
        if len(cand) == 0:
            return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64)
        segs, faces = mesh_plane(self.trimesh, plane_normal=[0, 0, 1], plane_origin=[0, 0, z],
                                 return_faces=True, local_faces=cand)
        segs = np.asarray(segs, dtype=float).reshape(-1, 2, 3)[:, :, :2]
        faces = np.asarray(faces, dtype=np.int64).reshape(-1)
        keep = np.linalg.norm(segs[:, 1] - segs[:, 0], axis=1) > 1e-9
        return segs[keep], faces[keep]

    def first_hits(self, origins: np.ndarray, dirs: np.ndarray, max_t: float,
                   chunk: int = 256) -> tuple[np.ndarray, np.ndarray]:
        """First intersections of 3D rays with the mesh (both face sides).

        Args:
            origins: (M, 3) ray origins, world metres.
            dirs: (M, 3) unit directions.
            max_t: rays end at this distance, metres.

        Returns:
            (M,) hit distance (inf where none) and (M,) face index (-1 where none).
        """
        M = len(origins)
        t_best = np.full(M, np.inf)
        f_best = np.full(M, -1, dtype=np.int64)
        if M == 0:
            return t_best, f_best
        ends = origins + dirs * max_t
        r_lo = np.minimum(origins, ends) - 1e-9
        r_hi = np.maximum(origins, ends) + 1e-9
        for s in range(0, M, chunk):
            e = min(M, s + chunk)
            blo, bhi = r_lo[s:e].min(axis=0), r_hi[s:e].max(axis=0)
            faces = np.flatnonzero(np.all(self.lo <= bhi, axis=1) & np.all(self.hi >= blo, axis=1))
            if len(faces) == 0:
                continue
            ov = np.all(self.lo[faces][None] <= r_hi[s:e, None], axis=2) & np.all(self.hi[faces][None] >= r_lo[s:e, None], axis=2)
            ri, fi = np.nonzero(ov)
            if len(ri) == 0:
                continue
            ri = ri + s
            fi = faces[fi]
            t = _moller_trumbore(origins[ri], dirs[ri], self.tri[fi])
            ok = (t >= 0) & (t <= max_t)
            ri, fi, t = ri[ok], fi[ok], t[ok]
            order = np.lexsort((t, ri))
            ri, fi, t = ri[order], fi[order], t[order]
            first = np.r_[True, ri[1:] != ri[:-1]]
            t_best[ri[first]] = t[first]
            f_best[ri[first]] = fi[first]
        return t_best, f_best

    def down_hit_z(self, xy: np.ndarray, z: float, depth: float = 50.0) -> np.ndarray:
        """(M,) z of the first surface straight below (x, y, z) for (M, 2) points; -inf where none."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        o = np.column_stack([xy, np.full(len(xy), z)])
        d = np.tile([0.0, 0.0, -1.0], (len(xy), 1))
        t, _ = self.first_hits(o, d, depth)
        return np.where(np.isfinite(t), z - t, -np.inf)


def _moller_trumbore(o: np.ndarray, d: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Ray-triangle distances for paired (K, 3) rays and (K, 3, 3) triangles; -1 where missed."""
    eps = 1e-12
    e1 = tri[:, 1] - tri[:, 0]
    e2 = tri[:, 2] - tri[:, 0]
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > eps
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - tri[:, 0]
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = np.einsum("ij,ij->i", d, q) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    tol = 1e-9
    ok &= (u >= -tol) & (v >= -tol) & (u + v <= 1 + tol)
    return np.where(ok, t, -1.0)


def find_storeys(mesh: _Mesh, min_area_frac: float = 0.2, min_separation: float = 2.0,
                 gap: float = 0.1) -> list[float]:
    """Floor heights (world z, metres, ascending) of the storeys of a model.

    Upward-facing horizontal faces (n_z > 0.95) are clustered by z (a gap > ``gap`` metres
    splits clusters). A cluster is a floor when its area is at least ``min_area_frac`` of the
    largest cluster's and it lies ``min_separation`` above the previous floor (so table tops
    and steps do not count), and the model has geometry 1 m above it (a roof top is no floor).
    """
    up = np.flatnonzero((mesh.normal[:, 2] > 0.95) & (mesh.area > 0))
    if len(up) == 0:
        return []
    z = mesh.tri[up, :, 2].mean(axis=1)
    a = mesh.area[up]
    order = np.argsort(z, kind="stable")
    z, a = z[order], a[order]
    split = np.flatnonzero(np.diff(z) > gap) + 1
    groups = np.split(np.arange(len(z)), split)
    cz = np.array([_weighted_median(z[g], a[g]) for g in groups])  # rugs do not lift the floor
    ca = np.array([a[g].sum() for g in groups])
    floors: list[float] = []
    for zc, ac in zip(cz, ca):
        if ac < min_area_frac * ca.max():
            continue
        if floors and zc - floors[-1] < min_separation:
            continue
        if not np.any((mesh.lo[:, 2] <= zc + 1.0) & (mesh.hi[:, 2] >= zc + 1.0)):
            continue
        floors.append(float(zc))
    return floors


def _weighted_median(v: np.ndarray, w: np.ndarray) -> float:
    o = np.argsort(v, kind="stable")
    cw = np.cumsum(w[o])
    return float(v[o][np.searchsorted(cw, 0.5 * cw[-1])])


# ----------------------------------------------------------------------------------------------
# 2D scanning


def _cast_2d(origin: np.ndarray, dirs: np.ndarray, seg: np.ndarray, max_t: float,
             chunk: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """First hits of (R, 2) unit rays from ``origin`` (2,) against (S, 2, 2) segments.

    Returns (R,) distance (``max_t`` where none) and (R,) segment index (-1 where none).
    """
    R = len(dirs)
    t_best = np.full(R, float(max_t))
    s_best = np.full(R, -1, dtype=np.int64)
    if len(seg) == 0:
        return t_best, s_best
    a = seg[:, 0] - origin
    e = seg[:, 1] - seg[:, 0]
    # only segments within range
    near = np.minimum(np.linalg.norm(a, axis=1), np.linalg.norm(seg[:, 1] - origin, axis=1)) <= max_t + np.linalg.norm(e, axis=1)
    idx = np.flatnonzero(near)
    a, e = a[idx], e[idx]
    for s in range(0, R, chunk):
        d = dirs[s:s + chunk]
        denom = d[:, 0:1] * e[None, :, 1] - d[:, 1:2] * e[None, :, 0]  # cross(d, e)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / denom
            t = (a[None, :, 0] * e[None, :, 1] - a[None, :, 1] * e[None, :, 0]) * inv
            u = (a[None, :, 0] * d[:, 1:2] - a[None, :, 1] * d[:, 0:1]) * inv
        ok = np.isfinite(inv) & (t > 1e-9) & (u >= -1e-9) & (u <= 1 + 1e-9) & (t <= max_t)
        t = np.where(ok, t, np.inf)
        j = np.argmin(t, axis=1)
        tj = t[np.arange(len(d)), j]
        hit = np.isfinite(tj)
        t_best[s:s + chunk] = np.where(hit, tj, max_t)
        s_best[s:s + chunk] = np.where(hit, idx[j], -1)
    return t_best, s_best


@dataclass
class _Grid:
    x0: float
    y0: float
    res: float
    H: int
    W: int

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World xy -> continuous pixel coordinates (col, row) with cell centres at integers."""
        xy = np.asarray(xy, dtype=float)
        return np.stack([(xy[..., 0] - self.x0) / self.res - 0.5, (xy[..., 1] - self.y0) / self.res - 0.5], axis=-1)

    def cell(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside) integer cells of world xy points."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        c = np.floor((xy[:, 0] - self.x0) / self.res).astype(np.int64)
        r = np.floor((xy[:, 1] - self.y0) / self.res).astype(np.int64)
        inside = (c >= 0) & (c < self.W) & (r >= 0) & (r < self.H)
        return np.clip(r, 0, self.H - 1), np.clip(c, 0, self.W - 1), inside

    def centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return np.column_stack([self.x0 + (cols + 0.5) * self.res, self.y0 + (rows + 0.5) * self.res])


_SHIFT = 4  # cv2 fixed-point bits


def _fixed(px: np.ndarray) -> np.ndarray:
    return np.round(px * (1 << _SHIFT)).astype(np.int32)


def _rasterize_segments(grid: _Grid, seg: np.ndarray) -> np.ndarray:
    import cv2

    mask = np.zeros((grid.H, grid.W), dtype=np.uint8)
    if len(seg):
        pts = _fixed(grid.to_px(seg))  # (S, 2, 2)
        cv2.polylines(mask, list(pts.reshape(-1, 2, 1, 2)), False, 1, thickness=1, lineType=cv2.LINE_8, shift=_SHIFT)
    return mask.astype(bool)


class _Scanner:
    """Virtual 2D range scans in the plane, accumulated in an occupancy grid."""

    def __init__(self, grid: _Grid, seg: np.ndarray, seg_face: np.ndarray, config: DiscretizeConfig):
        self.grid, self.seg, self.seg_face, self.cfg = grid, seg, seg_face, config
        ang = 2 * np.pi * np.arange(config.scan_rays) / config.scan_rays
        self.dirs = np.column_stack([np.cos(ang), np.sin(ang)])
        self.obstacle = _rasterize_segments(grid, seg)
        self.seen = np.zeros((grid.H, grid.W), dtype=bool)
        self.origins: list[np.ndarray] = []
        self.hit_xy: list[np.ndarray] = []
        self.hit_seg: list[np.ndarray] = []
        self.hit_origin: list[np.ndarray] = []

    def scan(self, origin: np.ndarray) -> None:
        import cv2

        t, s = _cast_2d(origin, self.dirs, self.seg, self.cfg.max_scan_range)
        pts = origin + self.dirs * t[:, None]
        poly = np.zeros((self.grid.H, self.grid.W), dtype=np.uint8)
        cv2.fillPoly(poly, [_fixed(self.grid.to_px(pts)).reshape(-1, 1, 2)], 1, lineType=cv2.LINE_8, shift=_SHIFT)
        self.seen |= poly.astype(bool)
        r, c, inside = self.grid.cell(origin[None])
        if inside[0]:
            self.seen[r[0], c[0]] = True
        hit = s >= 0
        self.origins.append(np.asarray(origin, dtype=float))
        self.hit_xy.append(pts[hit])
        self.hit_seg.append(s[hit])
        self.hit_origin.append(np.tile(origin, (int(hit.sum()), 1)))

    def occupancy(self) -> np.ndarray:
        occ = np.full((self.grid.H, self.grid.W), -1, dtype=np.int8)
        occ[self.seen] = 0
        occ[self.obstacle] = 1
        return occ


def _disk(radius_px: float) -> np.ndarray:
    r = int(np.ceil(radius_px))
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    return ((xx * xx + yy * yy) <= radius_px * radius_px).astype(np.float32)


def _explore(scanner: _Scanner, start: np.ndarray, origin_ok, config: DiscretizeConfig) -> None:
    """Scan from ``start``, then from seen free space near unexplored boundary until done.

    ``origin_ok(xy (M, 2)) -> (M,) bool`` says whether a scan may be taken there (floor below).
    """
    import cv2
    from scipy.ndimage import binary_dilation, distance_transform_edt

    g = scanner.grid
    scanner.scan(start)
    clear = distance_transform_edt(~scanner.obstacle) * g.res
    step = max(1, int(round(0.25 / g.res)))  # origins on a 0.25 m lattice
    lattice = np.zeros((g.H, g.W), dtype=bool)
    lattice[step // 2::step, step // 2::step] = True
    lattice &= clear >= max(0.2, min(config.clearance, 0.5))
    rejected = np.zeros_like(lattice)
    exhausted = np.zeros_like(lattice)
    kernel = _disk(config.frontier_radius / g.res)
    min_cells = max(3, int(round(0.15 / g.res)))
    while len(scanner.origins) < config.max_scans:
        free = scanner.seen & ~scanner.obstacle
        unknown = ~scanner.seen & ~scanner.obstacle
        frontier = free & binary_dilation(unknown, structure=np.ones((3, 3), bool)) & ~exhausted
        frontier[[0, -1], :] = False
        frontier[:, [0, -1]] = False
        if frontier.sum() < min_cells:
            break
        score = cv2.filter2D(frontier.astype(np.float32), -1, kernel, borderType=cv2.BORDER_CONSTANT)
        cand = free & lattice & ~rejected
        score = np.where(cand, score, 0.0)
        found = False
        while True:
            k = int(np.argmax(score))
            if score.flat[k] < min_cells:
                break
            r, c = divmod(k, g.W)
            xy = g.centres(np.array([r]), np.array([c]))[0]
            if origin_ok(xy[None])[0]:
                found = True
                break
            rejected[r, c] = True
            score[r, c] = 0.0
        if not found:
            break
        near = np.zeros((g.H, g.W), dtype=np.uint8)
        cv2.circle(near, (int(c), int(r)), int(round(config.frontier_radius / g.res)), 1, -1)
        exhausted |= frontier & near.astype(bool)
        rejected[r, c] = True
        scanner.scan(xy)
    log.debug("explored with %d scans", len(scanner.origins))


# ----------------------------------------------------------------------------------------------
# candidates


def _perimeter(free: np.ndarray, grid: _Grid, min_length: float = 0.5):
    """Boundary loops of the free region: (P, 2) points, (P,) arclength, total length."""
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


def _tag_fits(mesh: _Mesh, centers: np.ndarray, normals: np.ndarray, config: DiscretizeConfig,
              n_side: int = 7, standoff: float = 0.1) -> np.ndarray:
    """(M,) bool: a tag of ``tag_size`` (+ margin) centred at each (M, 3) point fits flat.

    Short rays along -normal from ``standoff`` in front of the wall, over an n_side x n_side
    grid of the tag square plus margin, must all hit within ``flatness_tol`` of the plane
    through the centre (no corner, opening, edge, or object in front of the wall).
    """
    M = len(centers)
    if M == 0:
        return np.zeros(0, dtype=bool)
    h = config.tag_size * (0.5 + config.tag_border)
    a = np.linspace(-h, h, n_side)
    A, B = np.meshgrid(a, a)
    A, B = A.ravel(), B.ravel()
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    x = np.cross(np.tile(geometry.UP, (M, 1)), n)
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    y = np.tile(geometry.UP, (M, 1))
    o = centers[:, None] + A[None, :, None] * x[:, None] + B[None, :, None] * y[:, None] + standoff * n[:, None]
    d = np.repeat(-n[:, None], len(A), axis=1)
    t, _ = mesh.first_hits(o.reshape(-1, 3), d.reshape(-1, 3), standoff + 0.3)
    t = t.reshape(M, -1)
    ok = np.all(np.isfinite(t), axis=1)
    # the sample origins must be reachable from the point in front of the centre (a ray origin
    # inside a perpendicular wall would otherwise hide an inner corner)
    front = centers + standoff * n
    off = o - front[:, None]
    length = np.linalg.norm(off, axis=2)
    lat = length > 1e-9
    rows = np.repeat(np.arange(M)[:, None], len(A), axis=1)[lat]
    dirs_l = off[lat] / length[lat][:, None]
    tl, _ = mesh.first_hits(front[rows], dirs_l, float(length.max()))
    blocked = tl <= length[lat] + 1e-6
    ok &= ~np.bincount(rows[blocked], minlength=M).astype(bool)
    dev = np.abs(t - standoff)
    return ok & np.all(np.where(np.isfinite(t), dev, np.inf) <= config.flatness_tol, axis=1)


def _candidates(mesh: _Mesh, scanner: _Scanner, free: np.ndarray, z: float, config: DiscretizeConfig):
    from scipy.spatial import cKDTree

    g = scanner.grid
    per_xy, per_arc, per_len = _perimeter(free, g)
    empty = (np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
    if not scanner.hit_xy or per_len == 0:
        return empty, per_len
    hxy = np.vstack(scanner.hit_xy)
    hseg = np.concatenate(scanner.hit_seg)
    horg = np.vstack(scanner.hit_origin)
    n3 = mesh.normal[scanner.seg_face[hseg]]
    vertical = (np.abs(n3[:, 2]) < config.max_normal_z) & (np.linalg.norm(n3[:, :2], axis=1) > 1e-6)
    hxy, horg, n2 = hxy[vertical], horg[vertical], n3[vertical, :2]
    n2 = n2 / np.linalg.norm(n2, axis=1, keepdims=True)
    flip = np.einsum("ij,ij->i", n2, horg - hxy) < 0
    n2[flip] *= -1
    # one hit per 5 cm cell and normal direction (first seen wins: deterministic)
    r, c, inside = g.cell(hxy)
    octant = np.floor((np.arctan2(n2[:, 1], n2[:, 0]) + np.pi) / (np.pi / 4)).astype(np.int64) % 8
    key = (r * g.W + c) * 8 + octant
    _, first = np.unique(key, return_index=True)
    first = np.sort(first[inside[first]])
    hxy, n2 = hxy[first], n2[first]
    # position along the perimeter
    dist, j = cKDTree(per_xy).query(hxy)
    near = dist <= 3 * g.res + 1e-9
    hxy, n2, s = hxy[near], n2[near], per_arc[j[near]]
    order = np.lexsort((hxy[:, 1], hxy[:, 0], s))
    hxy, n2, s = hxy[order], n2[order], s[order]
    cos_diff = np.cos(np.radians(config.normal_diff_deg))
    acc_xy: list[np.ndarray] = []
    acc_n: list[np.ndarray] = []
    acc_s: list[float] = []
    batch = 32
    i = 0
    P = len(hxy)
    while i < P:
        # cheap spacing test first, then the tag-fit ray test in small batches
        idx = []
        AX = np.array(acc_xy).reshape(-1, 2)
        AN = np.array(acc_n).reshape(-1, 2)
        while i < P and len(idx) < batch:
            if len(AX):
                close = (np.linalg.norm(AX - hxy[i], axis=1) < config.marker_spacing) & (AN @ n2[i] >= cos_diff)
                if close.any():
                    i += 1
                    continue
            # also keep spacing within this batch
            if idx:
                bx = hxy[idx]
                bn = n2[idx]
                if np.any((np.linalg.norm(bx - hxy[i], axis=1) < config.marker_spacing) & (bn @ n2[i] >= cos_diff)):
                    # decided after the batch's tag test; revisit this point then
                    break
            idx.append(i)
            i += 1
        if not idx:
            continue
        centers = np.column_stack([hxy[idx], np.full(len(idx), z)])
        fits = _tag_fits(mesh, centers, np.column_stack([n2[idx], np.zeros(len(idx))]), config)
        for k, ok in zip(idx, fits):
            if not ok:
                continue
            if acc_xy:
                AX2 = np.array(acc_xy)
                AN2 = np.array(acc_n)
                if np.any((np.linalg.norm(AX2 - hxy[k], axis=1) < config.marker_spacing) & (AN2 @ n2[k] >= cos_diff)):
                    continue
            acc_xy.append(hxy[k])
            acc_n.append(n2[k])
            acc_s.append(float(s[k]))
    return (np.array(acc_xy).reshape(-1, 2), np.array(acc_n).reshape(-1, 2), np.array(acc_s)), per_len


# ----------------------------------------------------------------------------------------------
# main entry


def _back_face_fraction(mesh: _Mesh, origin: np.ndarray, seg: np.ndarray, seg_face: np.ndarray,
                        max_t: float, n_rays: int = 72) -> tuple[float, float]:
    """Fraction of 2D rays from ``origin`` whose first hit is a face's back side, and hit fraction."""
    ang = 2 * np.pi * np.arange(n_rays) / n_rays
    dirs = np.column_stack([np.cos(ang), np.sin(ang)])
    _, s = _cast_2d(origin, dirs, seg, max_t)
    hit = s >= 0
    if not hit.any():
        return 0.0, 0.0
    n = mesh.normal[seg_face[s[hit]], :2]
    back = np.einsum("ij,ij->i", n, dirs[hit]) > 0
    return float(back.mean()), float(hit.mean())


def discretize(scene, config: DiscretizeConfig = DiscretizeConfig()) -> Discretization:
    """Feasible camera poses and candidate marker poses of ``scene`` (see module docstring).

    Args:
        scene: a :class:`~markerplace.scene.types.Scene` (world z up, metres).
        config: settings.

    Returns:
        The :class:`Discretization`.

    Raises:
        UserError: level out of range, no floor, start point in an obstacle or outside the
            model, no walls at the plane height, no feasible camera pose, no candidate marker.
    """
    from scipy.ndimage import distance_transform_edt

    cfg = config
    mesh = _Mesh(scene)
    storeys = find_storeys(mesh, min_separation=cfg.min_storey_separation)
    if not storeys:
        if scene.floor_z is None:
            raise UserError("no floor found (no large upward-facing horizontal surface); check --up")
        storeys = [float(scene.floor_z)]
    if not 0 <= cfg.level < len(storeys):
        heights = ", ".join(f"{z:.2f}" for z in storeys)
        raise UserError(f"--level {cfg.level} is out of range: found {len(storeys)} storey(s) "
                        f"(floor heights {heights} m); use --level 0..{len(storeys) - 1}")
    floor_z = storeys[cfg.level]
    z = floor_z + cfg.height
    ceiling = storeys[cfg.level + 1] if cfg.level + 1 < len(storeys) else np.inf
    if z >= ceiling:
        raise UserError(f"plane z={z:.2f} m is above the next storey's floor ({ceiling:.2f} m); lower --height")

    segs, faces = [], []
    for dz in (0.0,) + tuple(cfg.slab_offsets):
        s, f = mesh.section(z + dz)
        segs.append(s)
        faces.append(f)
    seg = np.concatenate(segs)
    seg_face = np.concatenate(faces)
    if len(segs[0]) == 0:
        raise UserError(f"no walls cut the plane at z={z:.2f} m; check --height/--level/--up")

    margin = 0.5
    lo = seg.reshape(-1, 2).min(axis=0) - margin
    hi = seg.reshape(-1, 2).max(axis=0) + margin
    res = cfg.resolution
    W = int(np.ceil((hi[0] - lo[0]) / res))
    H = int(np.ceil((hi[1] - lo[1]) / res))
    grid = _Grid(float(lo[0]), float(lo[1]), res, H, W)
    scanner = _Scanner(grid, seg, seg_face, cfg)
    clear_occ = distance_transform_edt(~scanner.obstacle) * res

    def has_floor_below(xy: np.ndarray) -> np.ndarray:
        zb = mesh.down_hit_z(xy, z)
        return (zb >= floor_z - 0.1) & (zb < z)

    def clearance_at(xy: np.ndarray) -> np.ndarray:
        r, c, inside = grid.cell(xy)
        return np.where(inside, clear_occ[r, c], 0.0)

    if cfg.start is not None:
        start = np.asarray(cfg.start, dtype=float).reshape(2)
        txt = f"{start[0]:g},{start[1]:g}"
        r, c, inside = grid.cell(start[None])
        if not inside[0] or not has_floor_below(start[None])[0]:
            raise UserError(f"--start {txt} is outside the model (no floor below it on level {cfg.level} at "
                            f"z={floor_z:.2f} m); pick a point in open floor space")
        back, _ = _back_face_fraction(mesh, start, seg, seg_face, cfg.max_scan_range)
        if scanner.obstacle[r[0], c[0]] or back > 0.5:
            raise UserError(f"--start {txt} is inside an obstacle (wall or furniture) at z={z:.2f} m; "
                            "pick a point in open floor space")
    else:
        start = _auto_start(scene, mesh, grid, seg, seg_face, clear_occ, has_floor_below, cfg, z)

    _explore(scanner, start, has_floor_below, cfg)
    occ = scanner.occupancy()
    free = occ == 0

    # camera locations: lattice of cell centres at grid_spacing
    gs = cfg.grid_spacing
    nx = int(np.floor((hi[0] - lo[0]) / gs))
    ny = int(np.floor((hi[1] - lo[1]) / gs))
    gx, gy = np.meshgrid(lo[0] + (np.arange(nx) + 0.5) * gs, lo[1] + (np.arange(ny) + 0.5) * gs)
    pts = np.column_stack([gx.ravel(), gy.ravel()])  # row-major in y, then x
    clear_free = distance_transform_edt(free) * res  # distance to nearest non-free cell
    r, c, inside = grid.cell(pts)
    ok = inside & free[r, c] & (clear_free[r, c] >= cfg.clearance)
    pts = pts[ok]
    if len(pts):
        zb = mesh.down_hit_z(pts, z)
        pts = pts[np.abs(zb - floor_z) <= cfg.floor_tol]
    if len(pts) == 0:
        raise UserError(f"no feasible camera poses: no free cell with clearance >= {cfg.clearance:g} m and floor "
                        f"below at z={z:.2f} m; check --start/--height/--clearance/--grid-spacing")

    L, n = len(pts), cfg.num_yaws
    yaws = 2 * np.pi * np.arange(n) / n
    location_index = np.repeat(np.arange(L), n)
    yaw = np.tile(yaws, L)
    pos = np.column_stack([pts[location_index], np.full(L * n, z)])
    world_from_cam = geometry.world_from_cam_poses(pos, yaw)

    (cxy, cn, cs), per_len = _candidates(mesh, scanner, free, z, cfg)
    if len(cxy) == 0:
        raise UserError(f"no candidate marker poses: no flat near-vertical wall at z={z:.2f} m holds a "
                        f"{cfg.tag_size:g} m tag; check --height/--tag-size")
    cpos = np.column_stack([cxy, np.full(len(cxy), z)])
    cnorm = np.column_stack([cn, np.zeros(len(cn))])
    cT = np.stack([geometry.world_from_marker_pose(p, q) for p, q in zip(cpos, cnorm)])
    log.info("discretize: plane z=%.2f m (level %d of %d), %d scans, %d locations, %d candidates, perimeter %.1f m",
             z, cfg.level, len(storeys), len(scanner.origins), L, len(cpos), per_len)
    return Discretization(
        locations=pts, location_z=float(z), world_from_cam=world_from_cam, location_index=location_index.astype(np.int64),
        yaw=yaw, candidate_world_from_marker=cT, candidate_normal=cnorm, candidate_position=cpos,
        perimeter_arclength=cs, perimeter_length=float(per_len), occupancy=occ,
        grid_origin=np.array([grid.x0, grid.y0]), grid_resolution=float(res), floor_z=float(floor_z),
        storeys=np.asarray(storeys, dtype=float), start=np.asarray(start, dtype=float),
        scan_origins=np.array(scanner.origins).reshape(-1, 2))


def _auto_start(scene, mesh, grid, seg, seg_face, clear_occ, has_floor_below, cfg, z) -> np.ndarray:
    """A start point with floor below, enclosed by walls, not inside a solid, with clearance."""
    need = max(0.2, min(cfg.clearance, 0.5))

    def good(xy: np.ndarray) -> bool:
        r, c, inside = grid.cell(xy[None])
        if not inside[0] or clear_occ[r[0], c[0]] < need or not has_floor_below(xy[None])[0]:
            return False
        back, hit = _back_face_fraction(mesh, xy, seg, seg_face, cfg.max_scan_range)
        return back <= 0.5 and hit >= 0.9

    rooms = sorted(getattr(scene, "rooms", ()) or (), key=lambda rm: (-rm.area, rm.name))
    for room in rooms:
        x0, y0, x1, y1 = room.bounds
        xy = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        if good(xy):
            return xy
    step = max(1, int(round(0.25 / grid.res)))
    rr, cc = np.mgrid[step // 2:grid.H:step, step // 2:grid.W:step]
    rr, cc = rr.ravel(), cc.ravel()
    cl = clear_occ[rr, cc]
    keep = cl >= need
    rr, cc, cl = rr[keep], cc[keep], cl[keep]
    pts = grid.centres(rr, cc)
    if len(pts):
        fl = has_floor_below(pts)
        pts, cl = pts[fl], cl[fl]
    for k in np.argsort(-cl, kind="stable")[:50]:
        if good(pts[k]):
            return pts[k]
    raise UserError(f"could not find an open floor point at z={z:.2f} m to start scanning; give --start x,y")
