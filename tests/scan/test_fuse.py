"""`markerplace fuse`: RGB-D frames (markerplace and TUM layouts) -> TSDF -> vertex-coloured PLY."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from markerplace.cli.main import main
from markerplace.geometry import Intrinsics, project
from markerplace.scan.frame_images import load_frame
from markerplace.scan.frames import FrameWriter, open_frameset
from markerplace.scan.frameset import rotation_from_quaternion
from markerplace.scan.fuse import read_ahead
from markerplace.scan.simulate import distance_to_scene
from markerplace.scan.tum import associate, nearest, read_tum
from markerplace.scan.walk import world_from_cam_ypr
from markerplace.scene import load_scene

INTR = Intrinsics(160, 120, 100.0, 100.0, 79.5, 59.5)
VOXEL = 0.03


def _one_line_error(capsys, fragment: str) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("markerplace: error:"), err
    assert fragment in err[0], err
    return err[0]


@pytest.fixture(scope="module")
def tiny_frames(tmp_path_factory):
    """Clean RGB-D frames of the built-in `tiny` room (3.6 x 3.6 m) in the markerplace layout."""
    from markerplace.render.renderer import Renderer

    root = tmp_path_factory.mktemp("tiny_frames")
    scene = load_scene("tiny")
    poses = []
    for x, y in ((1.2, 1.5), (2.4, 2.4), (2.3, 1.2)):
        for pitch in (-40.0, 0.0, 30.0):
            for k in range(8):
                poses.append(world_from_cam_ypr(np.array([x, y, 1.4]), np.radians(45.0 * k + 10.0), np.radians(pitch)))
    frames = []
    with Renderer(scene, INTR) as r, FrameWriter(root, INTR) as w:
        for i, T in enumerate(poses):
            res = r.render(T, normal=False)
            d16 = np.rint(res.depth * 1000.0).astype(np.uint16)
            w.write(f"f{i:03d}", res.rgb, d16, T)
            frames.append((res.rgb, d16, T))
    return root, scene, frames


def test_fused_surface_lies_on_the_true_surface_with_its_colours(tiny_frames, tmp_path, capsys):
    root, scene, frames = tiny_frames
    out = tmp_path / "tiny.ply"
    assert main(["--quiet", "fuse", str(root), "--out", str(out), "--voxel", str(VOXEL)]) == 0
    assert str(out) in capsys.readouterr().out
    assert out.read_bytes()[:200].find(b"binary_little_endian") > 0
    fused = load_scene(str(out))
    (part,) = fused.parts
    assert part.colors is not None and part.texture is None
    V = np.asarray(part.vertices, dtype=float)
    assert 5_000 < len(part.faces) < 1_000_000
    d = distance_to_scene(V, scene)
    # clean depth: the surface is exact up to marching cubes on thin things (plant leaves, shelf edges)
    assert np.median(d) < 0.1 * VOXEL, np.median(d)
    assert np.percentile(d, 95) < 0.5 * VOXEL, np.percentile(d, 95)
    assert np.percentile(d, 99) < 2.0 * VOXEL, np.percentile(d, 99)
    # the fused mesh spans the room: floor to ceiling, wall to wall
    lo, hi = V.min(axis=0), V.max(axis=0)
    assert lo[2] < 0.05 and hi[2] > 2.6 and hi[0] - lo[0] > 3.4 and hi[1] - lo[1] > 3.4
    # colours: each vertex seen head-on in frame 0 has the colour of its pixel (RGB order kept)
    rgb, d16, T = frames[8]  # level view
    uv, z = project(INTR.K, T, V)
    u, v = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
    inside = (z > 0.3) & (u >= 0) & (u < INTR.width) & (v >= 0) & (v < INTR.height)
    u, v, z, idx = u[inside], v[inside], z[inside], np.flatnonzero(inside)
    seen = np.abs(d16[v, u] / 1000.0 - z) < 0.01
    assert seen.sum() > 500
    col = part.colors[idx[seen], :3].astype(float)
    diff = np.abs(col - rgb[v[seen], u[seen]].astype(float))
    assert np.median(diff) < 12, np.median(diff)
    assert np.std(col) > 10  # not one flat colour


@pytest.mark.parametrize("a, b", [(1.0, 0.0), (0.0, -1.0)])
def test_slanted_plane_is_not_shifted_by_half_a_pixel(a, b):
    """Open3D reads pixel int(u); ours are centred on integers. A 45 deg plane must stay put."""
    from markerplace.scan.fuse import FuseConfig, TSDFFusion

    v, u = np.mgrid[0 : INTR.height, 0 : INTR.width].astype(float)
    z = 2.0 / (1.0 - a * (u - INTR.cx) / INTR.fx - b * (v - INTR.cy) / INTR.fy)  # plane z = 2 + a x + b y
    fusion = TSDFFusion(INTR, FuseConfig(voxel=0.02))
    assert fusion.integrate(np.full((INTR.height, INTR.width, 3), 90, np.uint8), np.rint(z * 1000).astype(np.uint16), 1000.0, np.eye(4))
    V = np.asarray(fusion.extract_mesh().vertices)
    signed = (V[:, 2] - 2.0 - a * V[:, 0] - b * V[:, 1]) / np.sqrt(1 + a * a + b * b)
    assert len(V) > 1000
    assert abs(np.median(signed)) < 0.001, np.median(signed)  # half a pixel would be about 9 mm


def test_every_and_trunc_in_metres(tiny_frames, tmp_path, capsys):
    root, scene, _ = tiny_frames
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    assert main(["--quiet", "fuse", str(root), "--out", str(a), "--voxel", "0.05", "--trunc", "0.15"]) == 0
    assert main(["--quiet", "fuse", str(root), "--out", str(b), "--voxel", "0.05", "--trunc", "3x", "--every", "8"]) == 0
    fa, fb = load_scene(str(a)), load_scene(str(b))
    # every 8th frame is one heading per position and pitch: most of the room is unseen
    assert fb.num_faces < 0.6 * fa.num_faces
    assert np.median(distance_to_scene(np.asarray(fb.parts[0].vertices, float), scene)) < 0.02


# -------------------------------------------------------------------------------------- TUM
def _write_tum(root: Path, with_intrinsics: bool = True) -> dict:
    """A 64x48 TUM sequence looking at the world plane z = 2 m; returns what it should parse to."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "rgb").mkdir()
    (root / "depth").mkdir()
    rgb_t = ["1.000000", "1.033000", "1.066000", "1.100000"]
    dep_t = ["1.005000", "1.040000", "1.090000"]
    # colour 1.066 has no depth within 0.02 s once 1.090 is taken by 1.100 (0.010 < 0.024)
    q = (0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))  # 90 deg about the optical axis
    gt = [(0.99, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)), (1.03, (0.2, -0.1, 0.5), q), (1.3, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))]
    (root / "rgb.txt").write_text("# color images\n# file: 'test'\n# timestamp filename\n"
                                  + "".join(f"{t} rgb/{t}.png\n" for t in rgb_t))
    (root / "depth.txt").write_text("# depth maps\n# timestamp filename\n" + "".join(f"{t} depth/{t}.png\n" for t in dep_t))
    (root / "groundtruth.txt").write_text("# ground truth trajectory\n# timestamp tx ty tz qx qy qz qw\n"
                                          + "".join(f"{s} {' '.join(map(str, p))} {' '.join(map(str, qq))}\n" for s, p, qq in gt))
    depth_m = {"1.005000": 2.0, "1.040000": 1.5, "1.090000": 2.0}  # camera 2 is 0.5 m nearer the plane
    for t in rgb_t:
        Image.fromarray(np.full((48, 64, 3), (200, 60, 30), np.uint8)).save(root / "rgb" / f"{t}.png")
    for t, z in depth_m.items():
        cv2.imwrite(str(root / "depth" / f"{t}.png"), np.full((48, 64), int(z * 5000), np.uint16))
    if with_intrinsics:
        (root / "cam.json").write_text(json.dumps({"width": 64, "height": 48, "fx": 50, "fy": 50, "cx": 31.5, "cy": 23.5}))
    return {"names": ["1.000000", "1.033000"], "pose1_t": np.array([0.2, -0.1, 0.5])}


@pytest.mark.parametrize("count", [0, 2, 7])
def test_read_ahead_gives_every_frame_in_order(tiny_frames, count):
    """Frames read on a thread ahead of the fusion are the frames a plain loop reads, in order
    (fewer frames than the read-ahead, and more)."""
    fs = open_frameset(tiny_frames[0])
    records = fs.frames[:count]
    got = list(read_ahead(fs, records, ahead=4))
    assert len(got) == count
    for (rgb, depth), rec in zip(got, records):
        want_rgb, want_depth = load_frame(fs, rec)
        assert np.array_equal(rgb, want_rgb) and np.array_equal(depth, want_depth)


def test_tum_association_matches_associate_py():
    # one-to-one, closest pair first, strictly below max_dt
    assert associate([0.0, 0.03, 0.06], [0.001, 0.035, 0.1], 0.02) == [(0, 0), (1, 1)]
    assert associate([1.00, 1.01], [1.009], 0.02) == [(1, 0)]
    assert associate([1.0], [1.02], 0.02) == []
    assert list(nearest(np.array([1.0, 1.5, 2.0]), np.array([0.99, 1.6, 2.015, 3.0]), 0.02)) == [0, -1, 2]


def test_tum_layout_parsing_and_fusion(tmp_path, capsys):
    expect = _write_tum(tmp_path / "seq")
    # TUM's world has no stated up axis (it would be estimated): this one is z up, looking at a ceiling
    fs = open_frameset(tmp_path / "seq", "auto", tmp_path / "seq" / "cam.json", up="z")
    assert fs.format == "tum" and fs.depth_scale == 5000.0 and fs.up_source == "--up"
    assert [f.name for f in fs.frames] == expect["names"]
    assert fs.frames[0].depth_path.name == "1.005000.png" and fs.frames[1].depth_path.name == "1.040000.png"
    T1 = fs.frames[1].world_from_cam
    np.testing.assert_allclose(T1[:3, 3], expect["pose1_t"])
    np.testing.assert_allclose(T1[:3, :3], [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    np.testing.assert_allclose(rotation_from_quaternion(0, 0, 0, 1), np.eye(3))
    out = tmp_path / "tum.ply"
    assert main(["--quiet", "fuse", str(tmp_path / "seq"), "--out", str(out), "--intrinsics",
                 str(tmp_path / "seq" / "cam.json"), "--voxel", "0.02", "--up", "z"]) == 0
    mesh = load_scene(str(out))
    V = np.asarray(mesh.parts[0].vertices, float)
    # both frames fuse onto the one world plane z = 2 (depth scale 5000 and the poses applied)
    assert np.all(np.abs(V[:, 2] - 2.0) < 0.02), (V[:, 2].min(), V[:, 2].max())
    assert np.all(mesh.parts[0].colors[:, 0] > mesh.parts[0].colors[:, 2])  # red stays red


def test_tum_without_intrinsics_uses_freiburg1(tmp_path, caplog, monkeypatch):
    _write_tum(tmp_path / "seq")
    monkeypatch.setattr(logging.getLogger("markerplace"), "propagate", True)
    with caplog.at_level(logging.INFO, logger="markerplace"):
        fs = read_tum(tmp_path / "seq")
    assert (fs.intrinsics.fx, fs.intrinsics.fy, fs.intrinsics.cx, fs.intrinsics.cy) == (517.3, 516.5, 318.6, 255.3)
    assert any("freiburg1" in r.getMessage() for r in caplog.records)


# -------------------------------------------------------------------------------- bad input
def _valid_set(root: Path) -> Path:
    intr = Intrinsics(32, 24, 20.0, 20.0, 15.5, 11.5)
    with FrameWriter(root, intr) as w:
        for i in range(2):
            T = world_from_cam_ypr(np.array([0.0, 0.0, 1.0]), 0.3 * i, 0.0)
            w.write(f"f{i}", np.full((24, 32, 3), 120, np.uint8), np.full((24, 32), 2000, np.uint16), T)
    return root


def _rewrite_pose_line(root: Path, fn) -> None:
    lines = (root / "poses.txt").read_text().splitlines()
    data = [i for i, line in enumerate(lines) if line and not line.startswith("#")]
    lines[data[0]] = fn(lines[data[0]])
    (root / "poses.txt").write_text("\n".join(lines) + "\n")


def _scale_pose(line: str) -> str:
    f = line.split()
    v = np.array([float(x) for x in f[1:]]).reshape(4, 4)
    v[:3, :3] *= 1.5
    return f[0] + " " + " ".join(str(float(x)) for x in v.reshape(-1))


BAD_CASES = {
    "missing folder": (lambda r: shutil.rmtree(r), "not found"),
    "not a frame folder": (lambda r: [(r / n).unlink() for n in ("poses.txt", "intrinsics.json")], "not an RGB-D frame folder"),
    "missing intrinsics": (lambda r: (r / "intrinsics.json").unlink(), "intrinsics.json not found"),
    "bad intrinsics": (lambda r: (r / "intrinsics.json").write_text('{"width": 32, "height": 24, "fx": 20}'), "missing fy, cx, cy"),
    "missing poses": (lambda r: (r / "poses.txt").unlink(), "poses.txt not found"),
    "missing colour": (lambda r: (r / "color" / "f1.png").unlink(), "colour image"),
    "missing depth": (lambda r: (r / "depth" / "f0.png").unlink(), "depth image"),
    "pose with 15 values": (lambda r: _rewrite_pose_line(r, lambda s: " ".join(s.split()[:-1])), "got 15 values"),
    "pose not numbers": (lambda r: _rewrite_pose_line(r, lambda s: s.replace(" 0 0 0 1", " 0 0 0 one")), "expected numbers"),
    "non-rigid pose": (lambda r: _rewrite_pose_line(r, _scale_pose), "not rigid"),
    "depth wrong size": (lambda r: cv2.imwrite(str(r / "depth" / "f1.png"), np.full((12, 16), 2000, np.uint16)), "16x12, the intrinsics say 32x24"),
    "depth 8-bit": (lambda r: cv2.imwrite(str(r / "depth" / "f0.png"), np.full((24, 32), 200, np.uint8)), "16-bit single-channel"),
    "depth not an image": (lambda r: (r / "depth" / "f0.png").write_bytes(b"not a png"), "cannot read depth image"),
    "colour 16-bit": (lambda r: cv2.imwrite(str(r / "color" / "f0.png"), np.full((24, 32), 2000, np.uint16)), "must be 8-bit RGB"),
    "zero frames": (lambda r: (r / "poses.txt").write_text("# nothing here\n"), "no frames"),
    "no depth in range": (lambda r: [cv2.imwrite(str(r / "depth" / f"f{i}.png"), np.zeros((24, 32), np.uint16)) for i in range(2)], "no frame has a depth reading"),
}


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_frame_sets_give_one_line_errors(case, tmp_path, capsys):
    root = _valid_set(tmp_path / "frames")
    mutate, fragment = BAD_CASES[case]
    mutate(root)
    out = tmp_path / "out.ply"
    assert main(["--quiet", "fuse", str(root), "--out", str(out), "--voxel", "0.05"]) == 2
    _one_line_error(capsys, fragment)
    assert not out.exists() and not list(tmp_path.glob(".out.ply*"))  # nothing half-written


def test_valid_set_fuses(tmp_path, capsys):
    root = _valid_set(tmp_path / "frames")
    assert main(["--quiet", "fuse", str(root), "--out", str(tmp_path / "ok.ply"), "--voxel", "0.05"]) == 0
    assert load_scene(str(tmp_path / "ok.ply")).num_faces > 0


@pytest.mark.parametrize("args, fragment", [
    (["--voxel", "0"], "--voxel 0"),
    (["--trunc", "wide"], "--trunc 'wide'"),
    (["--trunc", "0.5x"], "1 to 100 voxels"),
    (["--every", "0"], "--every 0"),
    (["--depth-max", "-1"], "--depth-max -1"),
    (["--format", "tum"], "rgb.txt not found"),
])
def test_bad_options_give_one_line_errors(args, fragment, tmp_path, capsys):
    root = _valid_set(tmp_path / "frames")
    assert main(["--quiet", "fuse", str(root), "--out", str(tmp_path / "o.ply"), *args]) == 2
    _one_line_error(capsys, fragment)


def test_output_must_be_ply(tmp_path, capsys):
    root = _valid_set(tmp_path / "frames")
    assert main(["--quiet", "fuse", str(root), "--out", str(tmp_path / "o.glb")]) == 2
    _one_line_error(capsys, "must end in .ply")


@pytest.mark.parametrize("case, fragment", [
    ("gt 7 values", "(8 values), got 7"),
    ("gt bad quaternion", "quaternion norm"),
    ("no association", "no frames"),
    ("default intrinsics", "the intrinsics say 640x480"),
])
def test_bad_tum_sequences_give_one_line_errors(case, fragment, tmp_path, capsys):
    root = tmp_path / "seq"
    _write_tum(root)
    gt = root / "groundtruth.txt"
    if case == "gt 7 values":
        gt.write_text(gt.read_text().replace("0.99 0.0 0.0 0.0 0.0 0.0 0.0 1.0", "0.99 0.0 0.0 0.0 0.0 0.0 1.0"))
    elif case == "gt bad quaternion":
        gt.write_text(gt.read_text().replace("0.99 0.0 0.0 0.0 0.0 0.0 0.0 1.0", "0.99 0.0 0.0 0.0 0.0 0.0 0.0 2.0"))
    elif case == "no association":
        gt.write_text("5.0 0 0 0 0 0 0 1\n")
    extra = [] if case == "default intrinsics" else ["--intrinsics", str(root / "cam.json")]
    assert main(["--quiet", "fuse", str(root), "--out", str(tmp_path / "o.ply"), *extra]) == 2
    _one_line_error(capsys, fragment)


def test_output_folder_checked_before_fusing(tmp_path, capsys):
    root = _valid_set(tmp_path / "frames")
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["--quiet", "fuse", str(root), "--out", str(blocker / "o.ply")]) == 2
    _one_line_error(capsys, "is a file")


def test_frame_whose_few_readings_touch_no_block_is_skipped():
    """Open3D looks at a subsample of the depth pixels to find the blocks a frame touches and
    aborts when none is found: a frame with a lone reading between the sampled pixels (a scan
    frame looking down a long corridor) is skipped, not an error, and fuses nothing."""
    from markerplace.scan.fuse import TSDFFusion

    fusion = TSDFFusion(Intrinsics())
    rgb = np.zeros((450, 600, 3), np.uint8)
    outcomes = []
    for dy, dx in [(0, 1), (1, 1), (3, 2)]:
        depth = np.zeros((450, 600), np.uint16)
        depth[200 + dy, 300 + dx] = 1500
        outcomes.append(fusion.integrate(rgb, depth, 1000.0, np.eye(4)))
    assert outcomes == [False, False, False] and fusion.frames == 0
    depth = np.full((450, 600), 1500, np.uint16)
    assert fusion.integrate(rgb, depth, 1000.0, np.eye(4)) and fusion.frames == 1
