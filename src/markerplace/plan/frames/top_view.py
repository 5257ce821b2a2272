"""The top-down view of a frames plan and its :class:`~markerplace.plan.discretize.artifact.Discretization`.

* **Floor** (:func:`floor_height`): the lowest level of horizontal surface below the cameras
  that covers at least :data:`MIN_FLOOR_AREA` (5 cm bins, area-weighted); a sequence that never
  looked at the floor gets the lowest camera height minus the plan's ``height`` (the eye level
  above the floor), logged. It only says how high each tag hangs above the floor; nothing else
  needs a floor.
* **Grid** (:func:`occupancy_grid`, one storey): free = cells within :data:`FOOTPRINT` of a
  camera centre (where the cameras went), obstacle = cells holding surface between the floor +
  0.1 m and the highest camera, -1 elsewhere; the report's maps and the ``human`` baseline read it.
* :func:`frames_discretization`: the poses (:func:`~markerplace.plan.frames.poses.pose_fields`),
  the candidates (:mod:`markerplace.plan.frames.candidates`) and the grid in one artifact, with
  a ``summary`` the report reads (``frames``: how many, which layout).

Frames: world z up, metres; grid row 0 at ``grid_origin[1]``, column 0 at ``grid_origin[0]``.
"""

from __future__ import annotations

import logging

import numpy as np

from markerplace.plan.discretize.artifact import Discretization
from markerplace.plan.frames.candidates import FrameCandidates, marker_poses
from markerplace.plan.frames.poses import pose_fields
from markerplace.scene.raycast import RayCaster

log = logging.getLogger(__name__)

__all__ = ["FOOTPRINT", "MIN_FLOOR_AREA", "floor_height", "occupancy_grid", "frames_discretization"]

FOOTPRINT = 0.35
MIN_FLOOR_AREA = 0.25
OBSTACLE_ABOVE_FLOOR = 0.1


def _faces(rc: RayCaster) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Face centres (F, 3), unit normals (F, 3) and areas (F,) of the ray engine's mesh."""
    tri = rc.vertices[rc.faces]
    return tri.mean(axis=1), rc.face_normal, rc.face_area


def floor_height(rc: RayCaster, camera_z: np.ndarray, height: float) -> tuple[float, bool]:
    """(floor z, found on the surface) (module docstring)."""
    centre, normal, area = _faces(rc)
    below = camera_z.min() - 0.3
    up = (np.abs(normal[:, 2]) > 0.9) & (centre[:, 2] < below)
    if up.any():
        z0 = centre[up, 2].min()
        bins = np.floor((centre[up, 2] - z0) / 0.05).astype(np.int64)
        per = np.bincount(bins, weights=area[up])
        big = np.flatnonzero(per >= MIN_FLOOR_AREA)
        if len(big):
            sel = up.copy()
            sel[up] = bins == big[0]
            return float(np.average(centre[sel, 2], weights=area[sel])), True
    z = float(camera_z.min() - height)
    log.info("frames: no floor in the surface below the cameras; taking it %.2f m below the lowest camera (z=%.2f)",
             height, z)
    return z, False


def occupancy_grid(rc: RayCaster, cam_xy: np.ndarray, cand_xy: np.ndarray, floor_z: float, top_z: float,
                   resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) int8 occupancy (-1 unknown, 0 free, 1 obstacle) and its (2,) origin (module docstring)."""
    from scipy.ndimage import distance_transform_edt

    centre, _, _ = _faces(rc)
    pts = np.vstack([cam_xy, cand_xy.reshape(-1, 2)])
    lo, hi = pts.min(axis=0) - 1.0, pts.max(axis=0) + 1.0
    W, H = (np.ceil((hi - lo) / resolution).astype(int) + 1)
    occ = np.full((H, W), -1, np.int8)
    cam_cell = np.zeros((H, W), bool)
    c, r = np.floor((cam_xy - lo) / resolution).astype(int).T
    cam_cell[r, c] = True
    occ[distance_transform_edt(~cam_cell) * resolution <= FOOTPRINT] = 0
    sel = (centre[:, 2] > floor_z + OBSTACLE_ABOVE_FLOOR) & (centre[:, 2] < top_z)
    c, r = np.floor((centre[sel, :2] - lo) / resolution).astype(int).T
    inside = (r >= 0) & (r < H) & (c >= 0) & (c < W)
    occ[r[inside], c[inside]] = 1
    return occ, lo


def frames_discretization(rc: RayCaster, world_from_cam: np.ndarray, cand: FrameCandidates, floor: tuple[float, bool],
                          resolution: float, frames_info: dict) -> Discretization:
    """The frames plan's Discretization (module docstring); ``floor`` is :func:`floor_height`'s
    answer; ``frames_info`` goes into its summary as ``frames`` (count, layout, folder, step,
    surface)."""
    f = pose_fields(world_from_cam)
    floor_z, found = floor
    occ, origin = occupancy_grid(rc, f["locations"], cand.position[:, :2], floor_z, float(f["location_z"].max()),
                                 resolution)
    C = len(cand.position)
    free_m2 = float((occ == 0).sum()) * resolution ** 2
    summary = {
        "storeys": [floor_z], "normals": "frames",
        "per_storey": [{"storey": 0, "floor_z": floor_z, "open_floor_m2": free_m2, "free_m2": free_m2,
                        "covered_m2": free_m2, "locations": int(len(f["locations"])), "candidates": C,
                        "unreached": []}],
        "candidates_removed": dict(cand.counts["removed"]),
        "wall_spots": cand.counts["spots"], "wall_spots_pass": C, "candidates_crowded": 0, "candidates_added": 0,
        "allow": [],
        "frames": {**frames_info, "floor_found": found,
                   "camera_height_m": [float(f["location_z"].min() - floor_z), float(f["location_z"].max() - floor_z)]},
    }
    return Discretization(
        **f, candidate_world_from_marker=marker_poses(cand.position, cand.normal), candidate_normal=cand.normal,
        candidate_position=cand.position, candidate_storey=np.zeros(C, np.int64), perimeter_arclength=cand.arclength,
        perimeter_length=float(cand.loop_length), occupancy=occ[None], planned_storeys=np.zeros(1, np.int64),
        grid_origin=np.asarray(origin, float), grid_resolution=float(resolution), storeys=np.array([floor_z]),
        start=f["locations"].mean(axis=0), summary=summary, candidate_surface=np.full(C, "wall"),
        candidate_part=np.full(C, "fused surface" if frames_info.get("surface") == "fused" else "mesh"))
