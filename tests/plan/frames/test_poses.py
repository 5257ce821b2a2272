"""Which frames a frames plan serves, their camera model and pose fields (plan/frames/poses.py)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from helpers.frames import tiny_poses
from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.plan.frames.poses import MAX_POSES, default_frame_step, frame_indices, plan_intrinsics, pose_fields
from markerplace.scan.frameset import FrameRecord, FrameSet, frame_intrinsics


def _frameset(n: int = 5) -> FrameSet:
    recs = tuple(FrameRecord(f"f{i}", Path(f"c{i}.png"), Path(f"d{i}.png"), np.eye(4)) for i in range(n))
    return FrameSet(Path("."), "markerplace", Intrinsics(320, 240, 262.5, 262.5, 159.5, 119.5), 1000.0, recs)


def test_default_step_keeps_at_most_max_poses():
    assert default_frame_step(10) == 1
    assert default_frame_step(MAX_POSES) == 1
    assert default_frame_step(MAX_POSES + 1) == 2
    assert len(frame_indices(1001, None)) <= MAX_POSES
    assert frame_indices(10, 3).tolist() == [0, 3, 6, 9]
    with pytest.raises(UserError, match="--frame-step"):
        frame_indices(10, 0)


def test_intrinsics_come_from_the_set_unless_a_frame_has_its_own():
    fs = _frameset()
    assert frame_intrinsics(fs, fs.frames[0]) == fs.intrinsics
    assert plan_intrinsics(fs, np.arange(5)) == fs.intrinsics

    class Own:  # a future FrameRecord with its own intrinsics
        intrinsics = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)
        name = "own"

    fs2 = replace(fs, frames=fs.frames + (Own(),))
    assert frame_intrinsics(fs2, fs2.frames[-1]).width == 640
    with pytest.raises(UserError, match="other intrinsics"):
        plan_intrinsics(fs2, np.arange(6))


def test_pose_fields_are_the_frames_own_poses():
    T = tiny_poses(12)
    f = pose_fields(T)
    assert np.array_equal(f["world_from_cam"], T)
    assert np.allclose(f["locations"], T[:, :2, 3]) and np.allclose(f["location_z"], T[:, 2, 3])
    assert f["location_index"].tolist() == list(range(12))
    axis = T[:, :3, 2]
    assert np.allclose(np.cos(f["yaw"]) * axis[:, 1], np.sin(f["yaw"]) * axis[:, 0], atol=1e-9)
    assert np.all(np.cos(f["yaw"]) * axis[:, 0] + np.sin(f["yaw"]) * axis[:, 1] > 0)
