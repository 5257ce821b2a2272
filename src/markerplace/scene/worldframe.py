"""The user's world frame and markerplace's internal one, which may be shifted by an offset.

Mesh vertices are stored as float32 (:class:`~markerplace.scene.types.MeshPart`, for the GL
renderer); at survey coordinates near 1e6 m a float32 snaps to 1/16 m. So the loader
(:func:`markerplace.scene.loader.load_mesh_file`) recentres a model that lies far from the
origin: in float64, before the float32 conversion, it subtracts a whole-metre ``offset`` and
stores it in ``scene.meta["world_offset"]``::

    p_internal = p_user - offset          (offset: (3,) float64 metres; zero when not shifted)

Everything inside markerplace (discretization, rendering, caches) works in the internal frame.
The user only ever sees the user frame (the file's coordinates, z up, metres): positions the
user gives are moved in with the ``*_to_internal`` functions (``render --pose``, ``render
--markers``, ``plan --start``, ``--existing``, ``evaluate --start`` and ``--placements``) and
every position written for the user is moved out with the ``*_to_user`` functions
(``placement.json``/``.csv``, tag sheets, ``scores.npz``, the floor-map figures). Rotations are
the same in both frames.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Sequence

import numpy as np

OFFSET_KEY = "world_offset"


def world_offset(scene) -> np.ndarray:
    """(3,) float64 offset of ``scene``'s internal frame (``p_internal = p_user - offset``), metres."""
    meta = getattr(scene, "meta", None) or {}
    return np.asarray(meta.get(OFFSET_KEY, (0.0, 0.0, 0.0)), dtype=np.float64).reshape(3)


def points_to_internal(points: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(..., 3) or (..., 2) user-frame points (metres) -> internal frame (xy uses the offset's xy)."""
    p = np.asarray(points, dtype=np.float64)
    return p - np.asarray(offset, dtype=np.float64)[: p.shape[-1]]


def points_to_user(points: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(..., 3) or (..., 2) internal-frame points (metres) -> user frame."""
    p = np.asarray(points, dtype=np.float64)
    return p + np.asarray(offset, dtype=np.float64)[: p.shape[-1]]


def poses_to_internal(T: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(..., 4, 4) ``world_from_*`` poses in the user frame -> internal frame (copy)."""
    out = np.array(T, dtype=np.float64, copy=True)
    out[..., :3, 3] -= np.asarray(offset, dtype=np.float64)
    return out


def poses_to_user(T: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """(..., 4, 4) ``world_from_*`` poses in the internal frame -> user frame (copy)."""
    out = np.array(T, dtype=np.float64, copy=True)
    out[..., :3, 3] += np.asarray(offset, dtype=np.float64)
    return out


def markers_to_internal(markers: Sequence, offset: np.ndarray) -> list:
    """:class:`~markerplace.markers.Marker` list from the user frame to the internal frame."""
    if not np.any(offset):
        return list(markers)
    return [replace(m, world_from_marker=poses_to_internal(m.world_from_marker, offset)) for m in markers]


def markers_to_user(markers: Sequence, offset: np.ndarray) -> list:
    """:class:`~markerplace.markers.Marker` list from the internal frame to the user frame."""
    if not np.any(offset):
        return list(markers)
    return [replace(m, world_from_marker=poses_to_user(m.world_from_marker, offset)) for m in markers]


# Positional fields of a Discretization and how each moves: "xy"/"xyz" points, "z" heights,
# "pose" (..., 4, 4) transforms. Fields a version of the class lacks are skipped.
_DISC_FIELDS = {"locations": "xy", "location_z": "z", "world_from_cam": "pose",
                "candidate_world_from_marker": "pose", "candidate_position": "xyz", "grid_origin": "xy",
                "floor_z": "z", "storeys": "z", "start": "xy", "scan_origins": "xy"}


def discretization_to_user(disc, offset: np.ndarray):
    """A :class:`~markerplace.plan.discretize.artifact.Discretization` with every position in the user frame
    (locations, heights, poses, candidates, grid origin, storey floors, scan points)."""
    off = np.asarray(offset, dtype=np.float64)
    if not np.any(off):
        return disc
    names = {f.name for f in fields(disc)}
    changes = {}
    for name, kind in _DISC_FIELDS.items():
        if name not in names or getattr(disc, name) is None:
            continue
        value = getattr(disc, name)
        if kind == "pose":
            changes[name] = poses_to_user(value, off)
        elif kind == "z":
            moved = np.asarray(value, dtype=np.float64) + off[2]
            changes[name] = float(moved) if np.ndim(value) == 0 else moved
        else:
            changes[name] = points_to_user(value, off)
    return replace(disc, **changes)
