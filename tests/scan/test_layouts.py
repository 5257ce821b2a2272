"""The five RGB-D layouts `fuse` reads, round trip: the built-in `tiny` room rendered from known
poses, written in each layout's own conventions (tests/helpers/frame_layouts.py) in a world
tilted by a known rotation, read back (poses, up axis) and fused onto the room's surface; and,
per layout, a hand-made sample from the format's documentation with a known answer."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from PIL import Image

from helpers.frame_layouts import write_7scenes, write_nerfstudio, write_stray, write_tum
from markerplace.cli.main import main
from markerplace.geometry import Intrinsics, invert
from markerplace.scan.frame_images import load_frame
from markerplace.scan.frames import FrameWriter, detect_format, open_frameset
from markerplace.scan.frameset import frame_intrinsics
from markerplace.scan.fuse import FuseConfig, fuse_frameset, refine_up
from markerplace.scan.simulate import distance_to_scene
from markerplace.scan.up import angle_deg, rotation_to_z_up
from markerplace.scan.walk import world_from_cam_ypr
from markerplace.scene import load_scene

INTR = Intrinsics(160, 120, 100.0, 100.0, 79.5, 59.5)
LOW = Intrinsics(64, 48, 40.0, 40.0, 31.5, 23.5)  # INTR scaled by 0.4, pixel centres aligned
COLOUR7 = Intrinsics(160, 120, 131.25, 131.25, 79.625, 59.625)
"""7-Scenes' colour camera (fx 525, principal point (320, 240) at 640x480) scaled to 160x120."""
VOXEL = 0.04
Z = np.array([0.0, 0.0, 1.0])


def _rot(axis, deg: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = math.radians(deg)
    return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K


def _T(R=np.eye(3), t=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


# input_from_scene of each layout: the world the files are written in
TILTS = {
    "markerplace": _T(_rot(Z, 30.0), (0.4, -0.2, 0.0)),  # the layout is z up: yaw and shift only
    "tum": _T(_rot([1.0, 0.3, 0.0], 25.0) @ _rot(Z, 40.0), (0.3, 0.1, -0.5)),
    "7scenes": _T(_rot([1.0, 0.0, 0.2], 100.0), (-1.0, 0.5, 0.2)),  # z up -> about -y, as 7-Scenes' y-down worlds
    "nerfstudio": _T(_rot([0.2, 1.0, 0.0], 18.0) @ _rot(Z, -70.0), (0.0, 0.0, 0.3)),
    "stray": _T(_rot([0.0, 1.0, 0.0], 55.0) @ _rot([1.0, 0.0, 0.0], -90.0), (-1.2, 0.0, 0.7)),  # ARKit: y up
}
KNOWN_UP = {"markerplace": True, "tum": False, "7scenes": True, "nerfstudio": False, "stray": True}


@pytest.fixture(scope="module")
def rendered():
    """48 views of `tiny` (z-up scene world): colour + depth at 160x120, depth at 64x48 too."""
    from markerplace.render.renderer import Renderer

    scene = load_scene("tiny")
    rng = np.random.default_rng(7)
    poses = []
    for x, y, h in ((1.2, 1.5, 1.4), (2.4, 2.3, 1.55)):
        for pitch in (-25.0, 0.0, 20.0):
            for k in range(8):
                poses.append(world_from_cam_ypr(np.array([x, y, h]), math.radians(45.0 * k + 10.0 + rng.uniform(-5, 5)),
                                                math.radians(pitch), math.radians(rng.uniform(-2.0, 2.0))))
    frames, low = [], []
    with Renderer(scene, INTR) as r:
        for T in poses:
            res = r.render(T, normal=False)
            frames.append((res.rgb, np.where(np.isfinite(res.depth), res.depth, 0.0), T))
    with Renderer(scene, LOW) as r:
        for T in poses:
            d = r.render(T, rgb=False, normal=False).depth
            low.append(np.where(np.isfinite(d), d, 0.0))
    colour7 = []  # 7-Scenes: the colour camera is not the depth camera (INTR); both images of it
    with Renderer(scene, COLOUR7) as r:
        for T in poses:
            res = r.render(T, normal=False)
            colour7.append((res.rgb, np.where(np.isfinite(res.depth), res.depth, 0.0), T))
    return scene, frames, low, colour7


def _write(fmt: str, root, rendered):
    _, frames, low, colour7 = rendered
    A = TILTS[fmt]
    tilted = [(rgb, d, A @ T) for rgb, d, T in frames]
    if fmt == "markerplace":
        with FrameWriter(root, INTR) as w:
            for i, (rgb, d, T) in enumerate(tilted):
                w.write(f"f{i:03d}", rgb, np.rint(d * 1000).astype(np.uint16), T)
    elif fmt == "tum":
        write_tum(root, tilted)
        (root / "cam.json").write_text(json.dumps({"width": 160, "height": 120, "fx": 100, "fy": 100, "cx": 79.5, "cy": 59.5}))
    elif fmt == "7scenes":
        # colour from the colour camera, depth from the depth camera (camera-intrinsics.txt)
        tilted7 = [(c[0], d, A @ T) for c, (_, d, T) in zip(colour7, frames)]
        write_7scenes(root, tilted7, INTR, gravity_down=A[:3, :3] @ -Z)
    elif fmt == "nerfstudio":
        write_nerfstudio(root, tilted, INTR, depth_size=(80, 60), opencv_coeffs=(-0.08, 0.02, 0.001, -0.0005, 0.0))
    else:
        conf = [np.full(d.shape, 2, np.uint8) for d in low]
        for c in conf[::5]:
            c[:8] = 0  # low confidence: dropped
        write_stray(root, tilted, INTR, low, confidence=conf)
    return A


@pytest.mark.parametrize("fmt", sorted(TILTS))
def test_layout_round_trip_poses_up_axis_and_fused_surface(fmt, rendered, tmp_path):
    scene, frames, _, colour7 = rendered
    root = tmp_path / fmt
    A = _write(fmt, root, rendered)
    assert detect_format(root) == fmt
    fs = open_frameset(root, intrinsics_path=root / "cam.json" if fmt == "tum" else None)
    assert fs.format == fmt and len(fs.frames) == len(frames)
    up_true = A[:3, :3] @ Z  # the up direction in the written world
    W = fs.world_from_input
    assert angle_deg(W[:3, :3].T @ Z, up_true) < (1e-6 if KNOWN_UP[fmt] else 2.0), fs.up_source
    assert fs.up_source == {"markerplace": "layout (z up)", "7scenes": "gravity-direction.txt", "stray":
                            "layout (ARKit world, y up)"}.get(fmt, "estimated from the cameras' down axes")
    for rec, (_, _, T) in zip(fs.frames, frames):
        truth = A @ T
        got = invert(W) @ rec.world_from_cam  # the pose as written
        if KNOWN_UP[fmt]:
            np.testing.assert_allclose(W[:3, :3], rotation_to_z_up(up_true), atol=1e-9)
        dR = got[:3, :3].T @ truth[:3, :3]
        assert math.degrees(math.acos(min(1.0, (np.trace(dR) - 1) / 2))) < 0.1, rec.name
        assert np.linalg.norm(got[:3, 3] - truth[:3, 3]) < 1e-3, rec.name
        assert abs(rec.world_from_cam[2, 3] - (W @ truth)[2, 3]) < 1e-3
    # images: pinhole, colour size, depth in metres where the scene is
    rgb, d16 = load_frame(fs, fs.frames[8])
    assert rgb.shape == (120, 160, 3) and d16.shape == (120, 160) and frame_intrinsics(fs, fs.frames[8]).width == 160
    truth = colour7[8] if fmt == "7scenes" else frames[8]  # 7-Scenes: depth registered to the colour camera
    assert frame_intrinsics(fs, fs.frames[8]) == (COLOUR7 if fmt == "7scenes" else INTR)
    ok = (d16 > 0) & (truth[1] > 0)
    assert ok.mean() > (0.7 if fmt == "7scenes" else 0.8)  # 7-Scenes: the colour camera sees wider than the depth
    assert np.median(np.abs(d16[ok] / fs.depth_scale - truth[1][ok])) < 0.01
    assert np.median(np.abs(rgb.astype(float) - truth[0].astype(float))) < 12  # undistorted back (nerfstudio), video (stray)
    # fused surface on the room's surface, floor level after the up rotation (and refinement)
    mesh = fuse_frameset(fs, FuseConfig(voxel=VOXEL), progress=False)
    fs2, mesh2 = refine_up(fs, mesh)
    assert angle_deg(fs2.world_from_input[:3, :3].T @ Z, up_true) < (1e-6 if KNOWN_UP[fmt] else 1.0), fs2.up_source
    V = np.asarray(mesh2.vertices)
    V_scene = (invert(A) @ invert(fs2.world_from_input) @ np.c_[V, np.ones(len(V))].T).T[:, :3]
    d = distance_to_scene(V_scene, scene)
    assert len(V) > 2000
    assert np.median(d) < 0.25 * VOXEL, np.median(d)
    assert np.percentile(d, 90) < 2 * VOXEL, np.percentile(d, 90)


def test_fuse_command_detects_each_layout_and_takes_up(rendered, tmp_path, capsys):
    root = tmp_path / "seq"
    _write("7scenes", root, rendered)
    out = tmp_path / "o.ply"
    assert main(["--quiet", "fuse", str(root), "--out", str(out), "--voxel", "0.08", "--every", "6"]) == 0
    V = np.asarray(load_scene(str(out)).parts[0].vertices, float)
    assert V[:, 2].max() - V[:, 2].min() > 2.4  # floor to ceiling along +z
    # --up overrides the gravity file: the written world's own z (100 deg off) is then "up"
    assert main(["--quiet", "fuse", str(root), "--out", str(out), "--voxel", "0.08", "--every", "6", "--format",
                 "7scenes", "--up", "z"]) == 0
    V2 = np.asarray(load_scene(str(out)).parts[0].vertices, float)
    assert V[:, 2].max() - V[:, 2].min() < 2.9 < V2[:, 2].max() - V2[:, 2].min()  # the room lies on its side


# ------------------------------------------------------------------ samples from the documentation
def test_7scenes_pose_file_as_given(tmp_path):
    """A 7-Scenes pose (camera-to-world, OpenCV camera) in a y-down world, gravity (0, 1, 0)."""
    (tmp_path / "frame-000000.pose.txt").write_text(
        "1.0 0.0 0.0 0.1\n0.0 1.0 0.0 -1.2\n0.0 0.0 1.0 0.3\n0.0 0.0 0.0 1.0\n")
    (tmp_path / "gravity-direction.txt").write_text("0.0\n1.0\n0.0\n")
    fs = open_frameset(tmp_path)
    T = fs.frames[0].world_from_cam
    assert fs.format == "7scenes" and (fs.intrinsics.fx, fs.intrinsics.cx, fs.intrinsics.width) == (525.0, 320.0, 640)
    assert (fs.depth_intrinsics.fx, fs.depth_intrinsics.cx) == (585.0, 320.0)  # the dataset's depth camera
    np.testing.assert_allclose(T[:3, 3], [0.1, 0.3, 1.2], atol=1e-12)  # 1.2 m above the origin
    np.testing.assert_allclose(T[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)  # looks level, along the old +z
    np.testing.assert_allclose(T[:3, 1], [0.0, 0.0, -1.0], atol=1e-12)  # image down = world down


def test_nerfstudio_camera_looking_along_minus_x(tmp_path):
    """nerfstudio docs: OpenGL camera (x right, y up, looks along -z), z-up world. A camera at
    (1, 2, 1.5) looking along world -x, level: its -z column is (-1, 0, 0), its y column (0, 0, 1)."""
    meta = {"fl_x": 500, "fl_y": 500, "cx": 320, "cy": 240, "w": 640, "h": 480,
            "frames": [{"file_path": "images/a.png",
                        "transform_matrix": [[0, 0, 1, 1], [1, 0, 0, 2], [0, 1, 0, 1.5], [0, 0, 0, 1]]}]}
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    fs = open_frameset(tmp_path)
    rec = fs.frames[0]
    assert fs.format == "nerfstudio" and fs.up_source == "estimated from the cameras' down axes"
    np.testing.assert_allclose(rec.world_from_cam[:3, 2], [-1.0, 0.0, 0.0], atol=1e-12)  # optical axis
    np.testing.assert_allclose(rec.world_from_cam[:3, 1], [0.0, 0.0, -1.0], atol=1e-12)  # image down
    np.testing.assert_allclose(rec.world_from_cam[:3, 3], [1.0, 2.0, 1.5], atol=1e-12)
    K = frame_intrinsics(fs, rec)
    assert (K.cx, K.cy) == (319.5, 239.5)  # nerfstudio's pixel centres at +0.5
    # no depth: colour-only reading works, fusion says why it cannot
    (tmp_path / "images").mkdir()
    Image.fromarray(np.zeros((480, 640, 3), np.uint8)).save(tmp_path / "images" / "a.png")
    rgb, depth = load_frame(fs, rec)
    assert rgb.shape == (480, 640, 3) and not depth.any()


def test_stray_odometry_rows(tmp_path):
    """Stray Scanner rows: ARKit's identity camera (looking along ARKit -z, upright) is written
    as q = q_identity * q_AC = (1, 0, 0, 0); a camera turned to look along ARKit +x as
    (0.7071, 0, 0.7071, 0). ARKit's world is y up."""
    (tmp_path / "camera_matrix.csv").write_text("1400.0, 0.0, 960.0\n0.0, 1400.0, 720.0\n0.0, 0.0, 1.0\n")
    (tmp_path / "odometry.csv").write_text("timestamp, frame, x, y, z, qx, qy, qz, qw\n"
                                           "12.5, 000000, 0.5, 1.4, -2.0, 1.0, 0.0, 0.0, 0.0\n"
                                           "12.6, 000001, 0.5, 1.4, -2.0, 0.70710678, 0.0, 0.70710678, 0.0\n")
    (tmp_path / "rgb").mkdir()
    Image.fromarray(np.zeros((1440, 1920, 3), np.uint8)).save(tmp_path / "rgb" / "000000.png")
    fs = open_frameset(tmp_path)
    a, b = (r.world_from_cam for r in fs.frames)
    assert fs.format == "stray" and (fs.intrinsics.width, fs.intrinsics.height, fs.intrinsics.cx) == (1920, 1440, 960.0)
    np.testing.assert_allclose(a[:3, 3], [0.5, 2.0, 1.4], atol=1e-12)  # ARKit y (height) -> z
    np.testing.assert_allclose(a[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)  # ARKit -z -> +y, level
    np.testing.assert_allclose(a[:3, 1], [0.0, 0.0, -1.0], atol=1e-12)  # image down = world down
    np.testing.assert_allclose(b[:3, 2], [1.0, 0.0, 0.0], atol=1e-7)  # ARKit +x stays +x
    np.testing.assert_allclose(b[:3, 1], [0.0, 0.0, -1.0], atol=1e-7)


def test_nerfstudio_fisheye_and_per_frame_cameras(tmp_path):
    """Per-frame cameras (two sizes) and an OPENCV_FISHEYE lens: each frame loads at its own size,
    undistorted back to the pinhole image it was made from; fusion takes each frame's camera."""
    import cv2

    from markerplace.scan.fuse import TSDFFusion

    v, u = np.mgrid[0:96, 0:128]
    pinhole = np.stack([(u * 2) % 256, (v * 2) % 256, ((u // 16 + v // 16) % 2) * 255], axis=-1).astype(np.uint8)
    K = np.array([[70.0, 0, 63.5], [0, 70.0, 47.5], [0, 0, 1]])
    D = np.array([0.05, -0.01, 0.002, 0.0])
    pts = np.stack([u.ravel(), v.ravel()], axis=1).astype(np.float64).reshape(-1, 1, 2)
    und = cv2.fisheye.undistortPoints(pts, K, D, P=K).reshape(96, 128, 2).astype(np.float32)
    stored = cv2.remap(pinhole, und[..., 0], und[..., 1], cv2.INTER_LINEAR)
    (tmp_path / "images").mkdir()
    Image.fromarray(stored).save(tmp_path / "images" / "a.png")
    Image.fromarray(np.zeros((48, 64, 3), np.uint8)).save(tmp_path / "images" / "b.png")
    cv2.imwrite(str(tmp_path / "b_depth.png"), np.full((24, 32), 2000, np.uint16))
    eye = np.eye(4).tolist()
    meta = {"frames": [
        {"file_path": "images/a.png", "transform_matrix": eye, "camera_model": "OPENCV_FISHEYE", "fl_x": 70.0, "fl_y": 70.0,
         "cx": 64.0, "cy": 48.0, "w": 128, "h": 96, "k1": 0.05, "k2": -0.01, "k3": 0.002, "k4": 0.0},
        {"file_path": "images/b.png", "depth_file_path": "b_depth.png", "transform_matrix": eye, "fl_x": 40.0,
         "fl_y": 40.0, "cx": 32.0, "cy": 24.0}]}
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    fs = open_frameset(tmp_path, up="y")
    a, b = fs.frames
    assert a.distortion.model == "fisheye" and b.distortion is None
    assert (frame_intrinsics(fs, a).width, frame_intrinsics(fs, b).width, frame_intrinsics(fs, b).cx) == (128, 64, 31.5)
    rgb, depth = load_frame(fs, a)
    inner = (slice(15, 81), slice(20, 108))
    err_back = np.mean(np.abs(rgb[inner].astype(float) - pinhole[inner].astype(float)))
    err_lens = np.mean(np.abs(stored[inner].astype(float) - pinhole[inner].astype(float)))
    assert err_back < 0.25 * err_lens, (err_back, err_lens)  # undistorted back, where the lens moved things
    rgb_b, depth_b = load_frame(fs, b)  # depth 32x24 -> 64x48, nearest
    assert depth_b.shape == (48, 64) and np.all(depth_b == 2000)
    fusion = TSDFFusion(frame_intrinsics(fs, a), FuseConfig(voxel=0.05))
    assert fusion.integrate(rgb_b, depth_b, fs.depth_scale, np.eye(4), frame_intrinsics(fs, b))
    V = np.asarray(fusion.extract_mesh().vertices)
    assert len(V) > 50 and np.all(np.abs(V[:, 2] - 2.0) < 0.03)
