"""The camera poses a frames plan serves: the chosen frames' own 6-DoF poses.

* :func:`plan_intrinsics`: the one camera model of the chosen frames (scoring uses one K;
  frames with another model are refused);
* :func:`default_frame_step` / :func:`frame_indices`: the CLI's subsampling (``--frame-step``);
* :func:`pose_fields`: the :class:`~markerplace.plan.discretize.artifact.Discretization`
  fields of the poses (every pose is its own location; yaw = heading of the optical axis).

Frames: ``world_from_cam`` (4, 4), OpenCV camera (x right, y down, z forward), world z up, metres.
"""

from __future__ import annotations

import math

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.scan.frameset import frame_intrinsics

__all__ = ["MAX_POSES", "plan_intrinsics", "default_frame_step", "frame_indices", "pose_fields"]

MAX_POSES = 400
"""Without ``--frame-step``, every n-th frame so that at most this many poses are served."""


def plan_intrinsics(fs, indices: np.ndarray) -> Intrinsics:
    """The one camera model of the frames ``indices`` of ``fs``; :class:`UserError` when they differ."""
    first = frame_intrinsics(fs, fs.frames[int(indices[0])])
    for i in indices[1:]:
        rec = fs.frames[int(i)]
        if frame_intrinsics(fs, rec) != first:
            raise UserError(f"frame {rec.name} has other intrinsics than frame {fs.frames[int(indices[0])].name}; "
                            "plan --frames scores every frame with one camera model: give frames of one camera")
    return first


def default_frame_step(num_frames: int, max_poses: int = MAX_POSES) -> int:
    """Smallest step that keeps at most ``max_poses`` of ``num_frames`` frames."""
    return max(1, math.ceil(num_frames / max_poses))


def frame_indices(num_frames: int, step: int | None) -> np.ndarray:
    """Every ``step``-th frame index (None: :func:`default_frame_step`)."""
    if step is not None and (int(step) != step or step < 1):
        raise UserError(f"--frame-step {step} must be a positive integer")
    step = default_frame_step(num_frames) if step is None else int(step)
    return np.arange(0, num_frames, step, dtype=np.int64)


def pose_fields(world_from_cam: np.ndarray) -> dict:
    """The Discretization's pose fields: ``locations`` (N, 2) and ``location_z`` (N,) camera
    centres, ``location_index`` arange, ``yaw`` (N,) heading of the optical axis (radians CCW
    from +x; 0 for a camera looking straight up or down), ``location_storey`` zeros."""
    T = np.asarray(world_from_cam, float).reshape(-1, 4, 4)
    axis = T[:, :3, 2]
    yaw = np.where(np.linalg.norm(axis[:, :2], axis=1) > 1e-9, np.arctan2(axis[:, 1], axis[:, 0]), 0.0)
    N = len(T)
    return {"locations": T[:, :2, 3].copy(), "location_z": T[:, 2, 3].copy(), "location_index": np.arange(N, dtype=np.int64),
            "yaw": yaw, "location_storey": np.zeros(N, np.int64), "world_from_cam": T.copy()}
