"""scan/up.py: --up parsing, the minimal rotation to +z, the cameras' and the mesh's up estimates,
and fuse's refinement rule (only an estimate, only within 15 deg)."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.scan.up import angle_deg, estimate_up_from_cameras, estimate_up_from_mesh, parse_up, rotation_to_z_up, world_from_input
from markerplace.scan.walk import world_from_cam_ypr


@pytest.mark.parametrize("text, vec", [("z", (0, 0, 1)), ("-y", (0, -1, 0)), ("+x", (1, 0, 0)), ("X", (1, 0, 0)),
                                       ("0,0.9,0.4", (0, 0.9, 0.4)), ("0 0 -2", (0, 0, -1))])
def test_parse_up(text, vec):
    v = np.asarray(vec, float)
    np.testing.assert_allclose(parse_up(text), v / np.linalg.norm(v))


@pytest.mark.parametrize("text", ["up", "0,0", "0,0,0", "1,nan,0", "w", "--z"])
def test_parse_up_refuses_with_one_line(text):
    with pytest.raises(UserError, match=r"--up .*x, y, z") as err:
        parse_up(text)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("up", [(0, 0, 1), (0, 0, -1), (0, -1, 0), (0.3, 0.2, 0.93), (1, 1, -1)])
def test_rotation_to_z_up_is_minimal(up):
    u = np.asarray(up, float) / np.linalg.norm(up)
    R = rotation_to_z_up(u)
    np.testing.assert_allclose(R @ u, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    # minimal: the rotation angle is the tilt, and a direction horizontal in both worlds (the
    # axis up x z) is unchanged, so headings do not turn
    angle = math.degrees(math.acos(np.clip((np.trace(R) - 1) / 2, -1, 1)))
    assert angle == pytest.approx(angle_deg(u, [0, 0, 1]), abs=1e-6)
    axis = np.cross(u, [0, 0, 1])
    if np.linalg.norm(axis) > 1e-9:
        np.testing.assert_allclose(R @ axis, axis, atol=1e-12)
    np.testing.assert_allclose(world_from_input(u)[:3, :3], R)


def test_camera_estimate_and_spread(caplog):
    rng = np.random.default_rng(3)
    tilt = rotation_to_z_up(np.array([0.1, -0.2, 1.0])).T  # the input world's up is tilt @ z
    poses = []
    for _ in range(24):
        T = world_from_cam_ypr(np.zeros(3), rng.uniform(0, 2 * np.pi), math.radians(rng.uniform(-30, 30)),
                               math.radians(rng.normal(0, 3)))
        T[:3, :3] = tilt @ T[:3, :3]
        poses.append(T)
    up, spread = estimate_up_from_cameras(poses)
    assert angle_deg(up, tilt @ [0, 0, 1]) < 5.0  # pitches do not cancel exactly over 24 random headings
    assert 5.0 < spread < 30.0
    level = [world_from_cam_ypr(np.zeros(3), y, 0.0) for y in np.linspace(0, 6, 7)]
    up, spread = estimate_up_from_cameras(level)
    np.testing.assert_allclose(up, [0, 0, 1], atol=1e-12)
    assert spread < 1e-6
    with pytest.raises(UserError, match="give --up"):
        estimate_up_from_cameras([world_from_cam_ypr(np.zeros(3), 0.0, 0.0, r) for r in (0.0, np.pi)])


def test_cameras_looking_down_one_way_do_not_tilt_the_estimate():
    """A kitchen counter: headings within +-40 deg, all looking down about 25 deg, rolls of 2 deg.
    The mean up axis leans 25 deg towards the counter; the x axes stay horizontal."""
    rng = np.random.default_rng(11)
    poses = [world_from_cam_ypr(np.zeros(3), math.radians(rng.uniform(-40, 40)), math.radians(rng.normal(-25, 8)),
                                math.radians(rng.normal(0, 2))) for _ in range(60)]
    mean_up = np.mean([-T[:3, 1] for T in poses], axis=0)
    assert angle_deg(mean_up, [0, 0, 1]) > 20.0
    up, spread = estimate_up_from_cameras(poses)
    assert angle_deg(up, [0, 0, 1]) < 1.0
    # a camera that barely turned: the x axes do not span a plane, the mean up axis is used
    still = [world_from_cam_ypr(np.zeros(3), math.radians(rng.uniform(-3, 3)), math.radians(-10.0)) for _ in range(10)]
    up, _ = estimate_up_from_cameras(still)
    assert 9.0 < angle_deg(up, [0, 0, 1]) < 11.0


def test_spread_over_30_deg_is_a_warning(tmp_path, caplog, monkeypatch):
    """Cameras rolled every which way: the estimate is logged as a warning."""
    import json

    from PIL import Image

    from helpers.frame_layouts import opengl_pose
    from markerplace.scan.frames import open_frameset

    frames = []
    for i, roll in enumerate((-60.0, 0.0, 60.0, 10.0)):
        T = world_from_cam_ypr(np.array([0.0, 0.0, 1.5]), 0.5 * i, 0.0, math.radians(roll))
        frames.append({"file_path": f"{i}.png", "transform_matrix": opengl_pose(T).tolist()})
    (tmp_path / "transforms.json").write_text(json.dumps({"fl_x": 50, "fl_y": 50, "cx": 16, "cy": 12, "w": 32, "h": 24,
                                                          "frames": frames}))
    Image.fromarray(np.zeros((24, 32, 3), np.uint8)).save(tmp_path / "0.png")
    monkeypatch.setattr(logging.getLogger("markerplace"), "propagate", True)
    with caplog.at_level(logging.INFO, logger="markerplace"):
        fs = open_frameset(tmp_path)
    warned = [r for r in caplog.records if r.levelno == logging.WARNING and "spread" in r.getMessage()]
    assert warned and all("spread widely" in r.getMessage() for r in warned)
    assert fs.up_source == "estimated from the cameras' down axes"


def _room_points(tilt_deg: float, rng):
    """Vertices and outward normals of a 4 x 4 x 2.5 m room's floor, a table top and walls,
    the floor normal tilted by ``tilt_deg`` about x, with 3 deg normal noise."""
    pts, nrm = [], []
    for _ in range(4000):  # floor
        pts.append([rng.uniform(0, 4), rng.uniform(0, 4), 0.0])
        nrm.append([0, 0, 1])
    for _ in range(800):  # table top
        pts.append([rng.uniform(1, 2), rng.uniform(1, 2), 0.75])
        nrm.append([0, 0, 1])
    for _ in range(1000):  # ceiling, normals down
        pts.append([rng.uniform(0, 4), rng.uniform(0, 4), 2.5])
        nrm.append([0, 0, -1])
    for k in range(4):  # walls
        for _ in range(2000):
            a = k * np.pi / 2
            pts.append([rng.uniform(0, 4), rng.uniform(0, 4), rng.uniform(0, 2.5)])
            nrm.append([np.cos(a), np.sin(a), 0])
    for _ in range(600):  # a ramp at 20 deg: not a floor
        pts.append([rng.uniform(0, 1), rng.uniform(0, 1), 0.2])
        nrm.append([0, np.sin(0.35), np.cos(0.35)])
    N = np.asarray(nrm, float) + rng.normal(0, math.radians(3), (len(nrm), 3))
    R = np.array([[1, 0, 0], [0, math.cos(math.radians(tilt_deg)), -math.sin(math.radians(tilt_deg))],
                  [0, math.sin(math.radians(tilt_deg)), math.cos(math.radians(tilt_deg))]])
    return np.asarray(pts, float) @ R.T, N @ R.T, R @ [0, 0, 1]


@pytest.mark.parametrize("tilt", [0.0, 4.0, 12.0])
def test_mesh_estimate_finds_the_floor_normal(tilt):
    V, N, truth = _room_points(tilt, np.random.default_rng(5))
    up = estimate_up_from_mesh(V, N)
    assert up is not None and angle_deg(up, truth) < 0.3, (angle_deg(up, truth), tilt)


def test_mesh_estimate_needs_upward_surfaces():
    rng = np.random.default_rng(1)
    V = rng.uniform(0, 4, (5000, 3))
    N = np.tile([1.0, 0.0, 0.0], (5000, 1))  # walls only
    assert estimate_up_from_mesh(V, N) is None
    assert estimate_up_from_mesh(np.zeros((0, 3)), np.zeros((0, 3))) is None


def test_refine_up_only_refines_an_estimate_within_15_deg():
    from pathlib import Path

    import open3d as o3d

    from markerplace.geometry import Intrinsics
    from markerplace.scan.frameset import FrameRecord, FrameSet
    from markerplace.scan.fuse import refine_up

    def mesh_of(tilt):
        V, N, _ = _room_points(tilt, np.random.default_rng(2))
        m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V), o3d.utility.Vector3iVector(np.array([[0, 1, 2]])))
        m.vertex_normals = o3d.utility.Vector3dVector(N)
        return m

    rec = FrameRecord("a", Path("a.png"), Path("a.d.png"), np.eye(4))
    est = FrameSet(Path("."), "tum", Intrinsics(), 1000.0, (rec,), "estimated from the cameras' down axes", np.eye(4))
    fs2, m2 = refine_up(est, mesh_of(6.0))
    assert fs2.up_source.endswith("refined by the mesh's horizontal surfaces")
    assert angle_deg(fs2.world_from_input[:3, :3].T @ [0, 0, 1], [0, -math.sin(math.radians(6)), math.cos(math.radians(6))]) < 0.3
    assert angle_deg(estimate_up_from_mesh(np.asarray(m2.vertices), np.asarray(m2.vertex_normals)), [0, 0, 1]) < 0.3
    fs3, m3 = refine_up(est, mesh_of(20.0))  # too far from the cameras' estimate: kept
    assert fs3 is est
    known = FrameSet(Path("."), "7scenes", Intrinsics(), 1000.0, (rec,), "gravity-direction.txt", np.eye(4))
    assert refine_up(known, mesh_of(6.0))[0] is known  # a stated up axis is never second-guessed
