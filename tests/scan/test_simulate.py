"""Simulated scans: the walk, the depth noise model, glass, and `scene export NAME OUT.ply --as-scan`."""

from __future__ import annotations

import dataclasses
import logging
import math

import numpy as np
import pytest

from markerplace.cli.main import main
from markerplace.geometry import world_from_cam_pose
from markerplace.scan.depth_noise import DepthNoiseConfig, noisy_depth
from markerplace.scan.frame_images import load_frame
from markerplace.scan.frames import open_frameset
from markerplace.scan.simulate import FrameSimulator, ScanConfig, distance_to_scene
from markerplace.scan.walk import WalkConfig, find_doorways, plan_walk, world_from_cam_ypr
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster
from markerplace.scene.types import MeshPart, Room, Scene


def _one_line_error(capsys, fragment: str) -> None:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:") and fragment in err[0], err


# ------------------------------------------------------------------------------------- poses
def test_pitched_pose_convention():
    T = world_from_cam_ypr(np.array([1.0, 2.0, 1.5]), math.radians(90.0), math.radians(30.0))
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R[:, 2], [0.0, math.cos(math.radians(30)), math.sin(math.radians(30))], atol=1e-12)
    assert abs(R[2, 0]) < 1e-12  # no roll: the image x axis stays horizontal
    level = world_from_cam_ypr(np.array([1.0, 2.0, 1.5]), 0.7, 0.0)
    np.testing.assert_allclose(level, world_from_cam_pose(np.array([1.0, 2.0, 1.5]), 0.7), atol=1e-12)


# -------------------------------------------------------------------------------------- walk
def _pitches_deg(poses: np.ndarray) -> np.ndarray:
    return np.degrees(np.arcsin(np.clip(poses[:, 2, 2], -1, 1)))


def test_walk_visits_the_room_over_its_floor_at_hand_height():
    scene = load_scene("tiny")
    poses, positions, doorways = plan_walk(scene, WalkConfig(), seed=0)
    (room,) = scene.rooms
    x0, y0, x1, y1 = room.bounds
    assert len(positions) >= 10 and len(doorways) == 0
    assert np.all((positions[:, 0] > x0 + 0.3) & (positions[:, 0] < x1 - 0.3))
    assert np.all((positions[:, 1] > y0 + 0.3) & (positions[:, 1] < y1 - 0.3))
    assert np.all((positions[:, 2] >= 1.2) & (positions[:, 2] <= 1.6))
    # over the floor, not over furniture, and clear of everything
    caster = RayCaster(*scene.geometry())
    t, _ = caster.first_hits(positions, np.tile([0.0, 0.0, -1.0], (len(positions), 1)))
    np.testing.assert_allclose(t, positions[:, 2], atol=0.05)
    # 8 yaws x 3 pitches per position; pitches around -45, 0, +30 deg
    assert len(poses) == 24 * len(positions)
    p = _pitches_deg(poses)
    for target in (-45.0, 0.0, 30.0):
        assert np.sum(np.abs(p - target) < 8.0) == 8 * len(positions)
    # deterministic in the seed
    again, _, _ = plan_walk(scene, WalkConfig(), seed=0)
    other, _, _ = plan_walk(scene, WalkConfig(), seed=1)
    np.testing.assert_array_equal(poses, again)
    assert not np.allclose(poses[: len(other)], other[: len(poses)])


def test_walk_uses_the_room_floor_height():
    tiny = load_scene("tiny")
    up = np.array([0.0, 0.0, 3.0], dtype=np.float32)
    parts = tuple(dataclasses.replace(p, vertices=np.asarray(p.vertices) + up) for p in tiny.parts)
    rooms = tuple(Room(r.name, r.bounds, floor_z=3.0) for r in tiny.rooms)
    upper = Scene("upper", parts, rooms, floor_z=3.0)
    _, positions, _ = plan_walk(upper, WalkConfig(), seed=0)
    assert len(positions) >= 10
    assert np.all((positions[:, 2] >= 4.2) & (positions[:, 2] <= 4.6))


def test_doorways_of_the_office_are_found_and_crossed():
    office = load_scene("office")
    doorways = find_doorways(office, RayCaster(*office.geometry()))
    pairs = sorted((d["a"], d["b"]) for d in doorways)
    names = [r.name for r in office.rooms]
    assert [(names[a], names[b]) for a, b in pairs] == [("open_office", "meeting"), ("open_office", "kitchen"),
                                                        ("meeting", "kitchen")]
    for d in doorways:  # on the shared wall line, the normal pointing from room a into room b
        a, b = office.rooms[d["a"]], office.rooms[d["b"]]
        c = d["centre"] + 0.5 * d["normal"]
        assert b.bounds[0] <= c[0] <= b.bounds[2] and b.bounds[1] <= c[1] <= b.bounds[3]
        c = d["centre"] - 0.5 * d["normal"]
        assert a.bounds[0] <= c[0] <= a.bounds[2] and a.bounds[1] <= c[1] <= a.bounds[3]


# ------------------------------------------------------------------------------------- noise
def _plane_frame(z: float, tilt_deg: float = 0.0, size=(120, 160)):
    """Planar depth of a plane through (0, 0, z) tilted about the camera y axis; camera = world."""
    cfg = ScanConfig(width=size[1], height=size[0], fx=130.0, fy=130.0)
    intr = cfg.intrinsics
    v, u = np.mgrid[0 : intr.height, 0 : intr.width].astype(float)
    a = math.tan(math.radians(tilt_deg))
    depth = z / (1.0 - a * (u - intr.cx) / intr.fx)  # plane z = z0 + a x
    n = np.array([-a, 0.0, 1.0]) / math.hypot(a, 1.0)
    normal = np.broadcast_to(n, depth.shape + (3,)).copy()
    return depth.astype(np.float32), normal.astype(np.float32), intr


def test_axial_noise_follows_nguyen_2012():
    depth, normal, intr = _plane_frame(2.0)
    cfg = DepthNoiseConfig(lateral_px=0.0, disparity_step=0.0, speckle_rate=0.0)
    out = noisy_depth(depth, normal, intr, np.eye(4), np.random.default_rng(0), cfg)
    ok = out > 0
    assert ok.mean() > 0.99
    expected = 0.0012 + 0.0019 * (2.0 - 0.4) ** 2  # 6.1 mm at 2 m, head-on
    assert np.std(out[ok] - depth[ok]) == pytest.approx(expected, rel=0.05)
    assert abs(np.mean(out[ok] - depth[ok])) < 0.0005
    # same generator state, same frame
    again = noisy_depth(depth, normal, intr, np.eye(4), np.random.default_rng(0), cfg)
    np.testing.assert_array_equal(out, again)


def test_disparity_quantization_and_range():
    depth, normal, intr = _plane_frame(3.0)
    out = noisy_depth(depth, normal, intr, np.eye(4), np.random.default_rng(1), DepthNoiseConfig(speckle_rate=0.0))
    vals = out[out > 0]
    inv = 1.0 / (vals * 2.85e-3)
    np.testing.assert_allclose(inv, np.rint(inv), atol=1e-3)  # on the inverse-depth lattice
    levels = np.unique(vals)
    assert 3 <= len(levels) < 30
    steps = np.diff(levels) / levels[1:] ** 2  # the step grows as z^2: 2.85e-3 z^2 (2.6 cm at 3 m)
    np.testing.assert_allclose(steps, 2.85e-3, rtol=0.05)
    far, normal, _ = _plane_frame(5.5)
    assert not np.any(noisy_depth(far, normal, intr, np.eye(4), np.random.default_rng(2)))  # beyond 5 m


def test_grazing_angles_speckle_and_edges_drop_readings():
    rng = np.random.default_rng(3)
    steep, normal, intr = _plane_frame(2.0, tilt_deg=80.0)
    steep[steep <= 0] = 0
    cfg = DepthNoiseConfig(speckle_rate=0.0)
    centre = noisy_depth(steep, normal, intr, np.eye(4), rng, cfg)[50:70, 70:90]
    assert np.mean(centre > 0) < 0.02  # 80 deg incidence near the image centre: no reading
    flat, normal, _ = _plane_frame(2.0, tilt_deg=30.0)
    assert np.mean(noisy_depth(flat, normal, intr, np.eye(4), rng, cfg) > 0) > 0.99
    speckled = noisy_depth(flat, normal, intr, np.eye(4), rng, DepthNoiseConfig())
    assert 0.005 < np.mean(speckled == 0) < 0.05
    # a step from 1.5 m to 3 m: a band along the discontinuity has no reading
    step = np.where(np.arange(160)[None, :] < 80, 1.5, 3.0) * np.ones((120, 1))
    head_on = np.broadcast_to([0.0, 0.0, 1.0], (120, 160, 3))
    out = noisy_depth(step.astype(np.float32), head_on, intr, np.eye(4), rng, cfg)
    assert np.all(out[:, 79:81] == 0)
    assert np.mean(out[:, 70:76] > 0) > 0.95 and np.mean(out[:, 84:90] > 0) > 0.95


def test_glass_gives_no_depth():
    tiny = load_scene("tiny")
    # a 0.4 x 0.4 m pane 0.7 m in front of a camera at the room centre looking along +x
    x = 2.5
    V = np.array([[x, 1.6, 1.2], [x, 2.0, 1.2], [x, 2.0, 1.6], [x, 1.6, 1.6]], dtype=np.float32)
    Fc = np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int32)
    T = world_from_cam_pose(np.array([1.8, 1.8, 1.4]), 0.0)
    out = {}
    for transparent, drop in ((False, True), (True, True), (True, False)):
        pane = MeshPart("pane", V, Fc, base_color=(0.8, 0.9, 1.0, 0.3), transparent=transparent)
        scene = Scene("glass", tiny.parts + (pane,), tiny.rooms)
        cfg = ScanConfig(noise=DepthNoiseConfig(speckle_rate=0.0, glass_dropout=drop))
        with FrameSimulator(scene, cfg) as sim:
            out[transparent, drop] = sim.frame(T, np.random.default_rng(0))[1] / 1000.0
    centre = (slice(105, 135), slice(145, 175))
    assert np.mean(np.abs(out[False, True][centre] - 0.7) < 0.03) > 0.9  # an opaque pane reads 0.7 m
    assert np.all(out[True, True][centre] == 0)  # glass: no reading where it is the first surface
    assert np.mean(out[True, True][:, :20] > 0) > 0.8  # the rest of the view still reads
    # glass_dropout=False keeps the renderer's reading of the wall behind the glass (1.75 m)
    assert np.mean(np.abs(out[True, False][centre] - 1.75) < 0.05) > 0.8


# ------------------------------------------------------------------------------- scan export
@pytest.fixture(scope="module")
def tiny_scan(tmp_path_factory):
    root = tmp_path_factory.mktemp("scan")
    out, frames = root / "tiny_scan.ply", root / "frames"
    logger = logging.getLogger("markerplace")
    saved = logger.handlers[:]
    logger.handlers.clear()
    try:
        assert main(["--quiet", "scene", "export", "tiny", str(out), "--as-scan", "--keep-frames", str(frames)]) == 0
    finally:
        logger.handlers[:] = saved
    return out, frames


def test_scan_export_is_a_noisy_vertex_coloured_mesh_covering_the_floor(tiny_scan):
    import open3d as o3d

    out, _ = tiny_scan
    original = load_scene("tiny")
    scan = load_scene(str(out))
    (part,) = scan.parts
    assert part.colors is not None and part.texture is None and part.uv is None
    assert np.std(part.colors[:, :3].astype(float)) > 10
    assert 20_000 < scan.num_faces < 1_000_000
    V = np.asarray(part.vertices, dtype=float)
    d = distance_to_scene(V, original)
    rms = float(np.sqrt(np.mean(d**2)))
    assert 0.001 < rms < 0.02, rms  # noisy, but on the surface
    assert np.median(d) < 0.005
    # holes: the mesh is open (boundary edges where the walk saw nothing or readings dropped out)
    F = np.sort(np.asarray(part.faces, dtype=np.int64), axis=1)
    edges = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [0, 2]]])
    _, counts = np.unique(edges[:, 0] * len(V) + edges[:, 1], return_counts=True)
    assert np.sum(counts == 1) > 100
    # most of the floor that furniture does not cover is in the scan
    caster = RayCaster(*original.geometry())
    g = np.arange(0.1, 3.55, 0.1)
    X, Y = np.meshgrid(g, g)
    P = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 2.0)], axis=1)
    t, _ = caster.first_hits(P, np.tile([0.0, 0.0, -1.0], (len(P), 1)))
    floor = P[np.abs(t - 2.0) < 0.01] * [1.0, 1.0, 0.0]
    assert len(floor) > 800
    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(part.faces.astype(np.uint32)))
    near = rs.compute_distance(o3d.core.Tensor(floor.astype(np.float32))).numpy()
    assert np.mean(near < 0.05) > 0.9


def test_kept_frames_are_noisy_and_fuse_back_to_the_same_mesh(tiny_scan, tmp_path):
    from markerplace.render.renderer import Renderer

    out, frames = tiny_scan
    fs = open_frameset(frames)
    assert fs.format == "markerplace" and len(fs.frames) >= 240 and fs.depth_scale == 1000.0
    assert (fs.intrinsics.width, fs.intrinsics.height) == (320, 240)
    # against a clean render at the same pose: dropouts and depth noise of the model's size
    original = load_scene("tiny")
    dropped, errors = [], []
    with Renderer(original, fs.intrinsics) as r:
        for rec in fs.frames[8:16]:  # the level headings of the first position
            _, d16 = load_frame(fs, rec)
            clean = r.render(rec.world_from_cam, rgb=False, normal=False).depth
            seen = clean > 0
            dropped.append(np.mean(d16[seen] == 0))
            both = seen & (d16 > 0)
            errors.append(np.median(np.abs(d16[both] / 1000.0 - clean[both])))
    assert 0.01 < np.mean(dropped) < 0.4, dropped
    assert 0.001 < np.median(errors) < 0.03, errors
    # the kept frames are a valid `fuse` input and rebuild the very same mesh
    again = tmp_path / "again.ply"
    assert main(["--quiet", "fuse", str(frames), "--out", str(again), "--voxel", "0.04", "--trunc", "2.5x"]) == 0
    assert again.read_bytes() == out.read_bytes()


@pytest.mark.parametrize("args, fragment", [
    (["office", "o.glb", "--as-scan"], "must end in .ply"),
    (["scene.glb", "o.ply", "--as-scan"], "built-in scenes only"),
    (["tiny", "o.ply", "--as-scan", "--voxel", "0"], "--voxel 0"),
    (["tiny", "o.glb", "--voxel", "0.05"], "apply to --as-scan only"),
    (["tiny", "o.glb", "--keep-frames", "f"], "apply to --as-scan only"),
])
def test_scan_export_bad_options(args, fragment, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["--quiet", "scene", "export", *args]) == 2
    _one_line_error(capsys, fragment)


def test_keep_frames_must_be_a_new_folder(tmp_path, capsys):
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "x.txt").write_text("x")
    assert main(["--quiet", "scene", "export", "tiny", str(tmp_path / "o.ply"), "--as-scan", "--keep-frames",
                 str(tmp_path / "frames")]) == 2
    _one_line_error(capsys, "is not empty")


@pytest.mark.slow
def test_office_scan_size_accuracy_and_time(tmp_path):
    """`scene export office OUT.ply --as-scan` (about 1 min on 2 cores): 1e5-1e6 faces, on the surface, floors covered."""
    import time

    import open3d as o3d

    out = tmp_path / "office_scan.ply"
    t0 = time.perf_counter()
    assert main(["--quiet", "scene", "export", "office", str(out), "--as-scan"]) == 0
    seconds = time.perf_counter() - t0
    assert seconds < 300
    office = load_scene("office")
    scan = load_scene(str(out))
    assert 100_000 < scan.num_faces < 1_000_000
    V = np.asarray(scan.parts[0].vertices, dtype=float)
    d = distance_to_scene(V, office)
    assert np.sqrt(np.mean(d**2)) < 0.02 and np.median(d) < 0.005
    caster = RayCaster(*office.geometry())
    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(o3d.core.Tensor(V.astype(np.float32)), o3d.core.Tensor(scan.parts[0].faces.astype(np.uint32)))
    for room in office.rooms:
        x0, y0, x1, y1 = room.bounds
        X, Y = np.meshgrid(np.arange(x0 + 0.1, x1 - 0.05, 0.1), np.arange(y0 + 0.1, y1 - 0.05, 0.1))
        P = np.stack([X.ravel(), Y.ravel(), np.full(X.size, room.floor_z + 1.0)], axis=1)
        t, _ = caster.first_hits(P, np.tile([0.0, 0.0, -1.0], (len(P), 1)))
        floor = P[np.abs(t - 1.0) < 0.01] - [0.0, 0.0, 1.0]
        near = rs.compute_distance(o3d.core.Tensor(floor.astype(np.float32))).numpy()
        assert np.mean(near < 0.05) > 0.9, room.name


def test_discretization_of_the_scan_matches_the_original(tiny_scan):
    """The planner on the fused scan finds (nearly) the camera locations of the procedural
    original on the same grid, its storey and wall candidates, despite holes and noise."""
    from markerplace.plan.discretize.stage import DiscretizeConfig, discretize

    out, _ = tiny_scan
    original = discretize(load_scene("tiny"), DiscretizeConfig())
    scan = discretize(load_scene(str(out)), DiscretizeConfig())
    assert len(scan.storeys) == 1 and abs(scan.storeys[0] - original.storeys[0]) < 0.02
    ours = {tuple(np.round(p, 3)) for p in scan.locations}
    found = np.mean([tuple(np.round(p, 3)) in ours for p in original.locations])
    # tiny is 3.5 m across: its outer ring of lattice points sits exactly at the 0.3 m
    # clearance from the true walls and a fused wall 1-2 cm inwards drops them (the office and
    # house scans find 97 % and 92 %, benchmarks/scan_plan.py)
    assert found >= 0.75, found
    assert all(tuple(np.round(p, 3)) in {tuple(np.round(q, 3)) for q in original.locations} or
               np.all((p > 0.3) & (p < 3.3)) for p in scan.locations)
    assert len(scan.locations) <= 1.1 * len(original.locations)  # no leak outside the room
    assert len(scan.candidate_position) >= 0.6 * len(original.candidate_position)


def test_scan_export_checks_its_output_before_scanning(tmp_path, capsys):
    """An unwritable OUT fails in a second, not after minutes of scanning (then a traceback)."""
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["--quiet", "scene", "export", "tiny", str(blocker / "tiny_scan.ply"), "--as-scan"]) == 2
    _one_line_error(capsys, "is a file")
