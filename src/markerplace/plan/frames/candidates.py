"""Candidate tag spots on the surface the frames saw, with the mesh plan's spot rules as far as
they apply (:mod:`markerplace.plan.discretize.wall_candidates`).

1. **Spots**: the surface is ray cast from every chosen camera on a pixel grid
   (:data:`GRID_COLS` x :data:`GRID_ROWS` rays, up to ``max_scan_range``): what the camera saw,
   on the surface itself (no eye-level plane, floor or ceiling needed).
2. **Walls facing the cameras**: a hit's face normal (turned towards the camera) must be
   near-vertical (|n_z| < ``max_normal_z``) and the camera must see the face within
   :data:`MAX_VIEW_ANGLE_DEG` of its normal (grazing hits on a fused surface are noisy).
3. **Height band**: tag centres between the lowest camera height - :data:`BELOW` and the highest
   + :data:`ABOVE` (where the cameras that will look for the tags are; a person hangs a tag
   within reach of where the camera was held).
4. One spot per 5 cm cell and normal octant (first seen wins); each spot's plane is then fitted
   to a 5 x 5 ray grid over the tag square (marching-cubes faces are too noisy for a normal),
   its centre moved onto that plane; spots whose fitted normal fails 2., or whose samples
   stray more than half of ``flatness_tol`` from the plane, are dropped.
5. **Spacing and flatness**: ordered by angle around the camera path's centroid (a closed loop,
   so the ``uniform`` baseline has an arclength), spots are spaced out ``marker_spacing`` apart
   in 3D unless their normals differ by more than ``normal_diff_deg``
   (:func:`~markerplace.plan.discretize.spacing.space_out`), each kept only when a tag and its
   border lie flat with open space in front (:func:`~markerplace.plan.discretize.candidate_rules.tag_fits`)
   and the mesh plan's geometric rules pass
   (:func:`~markerplace.plan.discretize.candidate_rules.surface_shape`: ``off-wall``, a surface
   standing off the wall such as a cupboard front or a picture, and ``in-opening``; unless
   ``allow`` names them), with the floor of :func:`~markerplace.plan.frames.top_view.floor_height`.

The name rules (doors, windows, pictures, glass...) need part names; a fused surface has none,
so they do not apply.

Marker pose: z = the wall normal towards the cameras, y = world up projected on the wall,
x = y x z (:mod:`markerplace.geometry`). Frames: world z up, metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplace.geometry import Intrinsics
from markerplace.plan.discretize.candidate_rules import GEOMETRIC, CandidateConfig, surface_shape, tag_fits
from markerplace.plan.discretize.spacing import space_out
from markerplace.scene.raycast import RayCaster

__all__ = ["FrameCandidates", "frame_candidates", "marker_poses", "BELOW", "ABOVE"]

GRID_COLS, GRID_ROWS = 32, 24
MAX_VIEW_ANGLE_DEG = 70.0
BELOW, ABOVE = 0.8, 0.3
CELL = 0.05
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, eq=False)
class FrameCandidates:
    """Candidate spots: ``position`` (C, 3) tag centres and ``normal`` (C, 3) unit wall normals
    towards the cameras, ordered by ``arclength`` (C,) along the loop around the camera path
    (``loop_length`` metres); ``counts``: ``found`` (one per cell and octant), ``spots``
    (spaced out with no rule), ``kept``, and ``removed``: the spots tested while spacing out
    that each rule removed (a spot counts under the first)."""

    position: np.ndarray
    normal: np.ndarray
    arclength: np.ndarray
    loop_length: float
    counts: dict


def _pixel_rays(world_from_cam: np.ndarray, intr: Intrinsics) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Origins (R, 3), unit directions (R, 3) and camera index (R,) of a pixel grid per camera."""
    u = (np.arange(GRID_COLS) + 0.5) * intr.width / GRID_COLS - 0.5
    v = (np.arange(GRID_ROWS) + 0.5) * intr.height / GRID_ROWS - 0.5
    U, V = (a.ravel() for a in np.meshgrid(u, v))
    cam = np.column_stack([(U - intr.cx) / intr.fx, (V - intr.cy) / intr.fy, np.ones_like(U)])
    cam /= np.linalg.norm(cam, axis=1, keepdims=True)
    d = np.einsum("nij,rj->nri", world_from_cam[:, :3, :3], cam).reshape(-1, 3)
    o = np.repeat(world_from_cam[:, :3, 3], len(cam), axis=0)
    return o, d, np.repeat(np.arange(len(world_from_cam)), len(cam))


def _facing(n: np.ndarray, p: np.ndarray, cam: np.ndarray, config: CandidateConfig) -> np.ndarray:
    """(M,) near-vertical and seen within MAX_VIEW_ANGLE_DEG of the normal from ``cam`` (M, 3)."""
    to_cam = cam - p
    to_cam /= np.maximum(np.linalg.norm(to_cam, axis=1, keepdims=True), 1e-9)
    return (np.abs(n[:, 2]) < config.max_normal_z) & (np.einsum("ij,ij->i", n, to_cam) > np.cos(np.radians(MAX_VIEW_ANGLE_DEG)))


def _fit_planes(rc: RayCaster, p: np.ndarray, n: np.ndarray, half: float, max_residual: float,
                standoff: float = 0.3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Plane through a 5 x 5 ray grid of +-``half`` around each spot: centres (M, 3), unit
    normals (M, 3) on the side of ``n``, and (M,) bool where all 25 rays hit within
    ``max_residual`` of the plane (a spot across a step, e.g. a picture's edge, would tilt it)."""
    M = len(p)
    y = UP - n[:, 2:3] * n
    y /= np.maximum(np.linalg.norm(y, axis=1, keepdims=True), 1e-9)
    x = np.cross(y, n)
    a = np.linspace(-half, half, 5)
    A, B = (g.ravel() for g in np.meshgrid(a, a))
    o = p[:, None] + A[None, :, None] * x[:, None] + B[None, :, None] * y[:, None] + standoff * n[:, None]
    t, _ = rc.first_hits(o.reshape(-1, 3), np.repeat(-n, len(A), axis=0), standoff + 0.3)
    t = t.reshape(M, -1)
    ok = np.isfinite(t).all(axis=1)
    hits = o - np.where(np.isfinite(t), t, standoff)[..., None] * n[:, None]
    mean = hits.mean(axis=1)
    _, _, vt = np.linalg.svd(hits - mean[:, None])
    normal = vt[:, 2]
    normal *= np.where(np.einsum("ij,ij->i", normal, n) < 0, -1.0, 1.0)[:, None]
    centre = p - np.einsum("ij,ij->i", p - mean, normal)[:, None] * normal
    residual = np.abs(np.einsum("mkj,mj->mk", hits - mean[:, None], normal)).max(axis=1)
    return centre, normal, ok & (residual <= max_residual)


def frame_candidates(rc: RayCaster, world_from_cam: np.ndarray, intr: Intrinsics, config: CandidateConfig,
                     tag_size: float, floor_z: float) -> FrameCandidates:
    """Candidate spots seen from the cameras ``world_from_cam`` (N, 4, 4) on the surface of
    ``rc`` whose floor is at ``floor_z`` (module docstring)."""
    T = np.asarray(world_from_cam, float).reshape(-1, 4, 4)
    o, d, ci = _pixel_rays(T, intr)
    t, f = rc.first_hits(o, d, config.max_scan_range)
    hit = f >= 0
    p, f, ci = o[hit] + d[hit] * t[hit, None], f[hit], ci[hit]
    cams = T[:, :3, 3]
    n = np.asarray(rc.face_normal, float)[f]
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    n *= np.where(np.einsum("ij,ij->i", n, cams[ci] - p) < 0, -1.0, 1.0)[:, None]
    zlo, zhi = cams[:, 2].min() - BELOW, cams[:, 2].max() + ABOVE
    keep = _facing(n, p, cams[ci], config) & (p[:, 2] >= zlo) & (p[:, 2] <= zhi)
    p, n, ci = p[keep], n[keep], ci[keep]
    # one spot per cell and horizontal normal octant (first seen wins: deterministic)
    cell = np.floor(p / CELL).astype(np.int64)
    octant = np.floor((np.arctan2(n[:, 1], n[:, 0]) + np.pi) / (np.pi / 4)).astype(np.int64) % 8
    _, first = np.unique(np.column_stack([cell, octant]), axis=0, return_index=True)
    first = np.sort(first)
    p, n, ci = p[first], n[first], ci[first]
    found = len(p)
    p, n, ok = _fit_planes(rc, p, n, 0.5 * tag_size, 0.5 * config.flatness_tol)
    ok &= _facing(n, p, cams[ci], config) & (p[:, 2] >= zlo) & (p[:, 2] <= zhi)
    p, n = p[ok], n[ok]
    centroid = cams[:, :2].mean(axis=0)
    ang = np.arctan2(p[:, 1] - centroid[1], p[:, 0] - centroid[0])
    order = np.lexsort((p[:, 2], ang))
    p, n = p[order], n[order]
    cos_diff = np.cos(np.radians(config.normal_diff_deg))
    removed = {"does not fit": 0, **{g: 0 for g in GEOMETRIC}}
    rules = [g for g in GEOMETRIC if g not in config.allow]

    def accept(idx: np.ndarray) -> np.ndarray:
        ok = tag_fits(rc, p[idx], n[idx], config, tag_size=tag_size)
        removed["does not fit"] += int((~ok).sum())
        go = idx[ok]
        if len(go) and rules:
            shape = surface_shape(rc, p[go], n[go], np.full(len(go), floor_z), config)
            bad = np.zeros(len(go), bool)
            for g in rules:
                removed[g] += int((shape[g] & ~bad).sum())
                bad |= shape[g]
            ok[np.flatnonzero(ok)[bad]] = False
        return ok

    kept = np.asarray(space_out(p, n, config.marker_spacing, cos_diff, accept), np.int64)
    nominal = len(space_out(p, n, config.marker_spacing, cos_diff, lambda idx: np.ones(len(idx), bool)))
    p, n = p[kept], n[kept]
    arc, length = _loop(p[:, :2])
    return FrameCandidates(p, n, arc, length, {"spots": int(nominal), "found": int(found), "kept": int(len(p)),
                                               "removed": removed})


def _loop(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Arclength (C,) of points taken in order along a closed polyline, and its length."""
    if len(xy) == 0:
        return np.zeros(0), 0.0
    d = np.linalg.norm(np.diff(np.vstack([xy, xy[:1]]), axis=0), axis=1)
    return np.r_[0.0, np.cumsum(d[:-1])], float(max(d.sum(), 1e-6))


def marker_poses(position: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(C, 4, 4) world_from_marker: z = normal, y = world up projected on the wall, x = y x z."""
    n = np.asarray(normal, float).reshape(-1, 3)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    y = UP - n[:, 2:3] * n
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    x = np.cross(y, n)
    T = np.tile(np.eye(4), (len(n), 1, 1))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3] = x, y, n, position
    return T
