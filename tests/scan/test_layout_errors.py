"""Malformed 7-Scenes, nerfstudio and Stray Scanner folders: `fuse` stops with one line that names
the file (and line or frame), exit code 2, nothing written; the valid folders fuse."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from helpers.frame_layouts import write_7scenes, write_nerfstudio, write_stray
from markerplace.cli.main import main
from markerplace.geometry import Intrinsics
from markerplace.scan.walk import world_from_cam_ypr
from markerplace.scene import load_scene

INTR = Intrinsics(32, 24, 20.0, 20.0, 15.5, 11.5)


def _frames(n: int = 3):
    return [(np.full((24, 32, 3), (150, 90, 40), np.uint8), np.full((24, 32), 2.0),
             world_from_cam_ypr(np.array([0.0, 0.0, 1.0]), 0.3 * i, 0.0)) for i in range(n)]


def _seven(root: Path) -> Path:
    write_7scenes(root, _frames(), INTR, gravity_down=(0.0, 0.0, -1.0))
    return root


def _nerf(root: Path) -> Path:
    write_nerfstudio(root, _frames(), INTR)
    return root


def _stray(root: Path, video: bool = False) -> Path:
    write_stray(root, _frames(), INTR, [np.full((12, 16), 2.0)] * 3, video=video,
                confidence=[np.full((12, 16), 2, np.uint8)] * 3)
    return root


def _edit_json(root: Path, fn) -> None:
    meta = json.loads((root / "transforms.json").read_text())
    fn(meta)
    (root / "transforms.json").write_text(json.dumps(meta))


def _replace(path: Path, old: str, new: str) -> None:
    text = path.read_text()
    assert old in text, (old, text[:300])
    path.write_text(text.replace(old, new, 1))


def _pose_lines(root: Path, lines: list[str]) -> None:
    (root / "frame-000001.pose.txt").write_text("".join(line + "\n" for line in lines))


def _video_shorter(root: Path) -> None:
    shutil.copy(root / "depth" / "000002.png", root / "depth" / "000003.png")
    shutil.copy(root / "confidence" / "000002.png", root / "confidence" / "000003.png")
    with open(root / "odometry.csv", "a") as f:
        f.write("1000.1, 000003, 0, 0, 1, 1, 0, 0, 0\n")


CASES = {
    # 7-Scenes
    "7s pose of 3 lines": (_seven, lambda r: _pose_lines(r, ["1 0 0 0", "0 1 0 0", "0 0 1 0"]),
                           "frame-000001.pose.txt: expected 4 lines of 4 numbers"),
    "7s pose not numbers": (_seven, lambda r: _pose_lines(r, ["1 0 0 0", "0 1 x 0", "0 0 1 0", "0 0 0 1"]),
                            "frame-000001.pose.txt:2: expected numbers"),
    "7s pose line of 5": (_seven, lambda r: _pose_lines(r, ["1 0 0 0", "0 1 0 0", "0 0 1 0 7", "0 0 0 1"]),
                          "frame-000001.pose.txt:3: expected 4 numbers"),
    "7s non-rigid pose": (_seven, lambda r: _pose_lines(r, ["2 0 0 0", "0 1 0 0", "0 0 1 0", "0 0 0 1"]), "not rigid"),
    "7s bad intrinsics": (_seven, lambda r: (r / "camera-intrinsics.txt").write_text("20 0 15.5\n0 20 11.5\n"),
                          "camera-intrinsics.txt: expected 3 lines"),
    "7s gravity of 2": (_seven, lambda r: (r / "gravity-direction.txt").write_text("0\n1\n"),
                        "gravity-direction.txt: expected 3 numbers"),
    "7s gravity zero": (_seven, lambda r: (r / "gravity-direction.txt").write_text("0 0 0\n"), "non-zero"),
    "7s gravity word": (_seven, lambda r: (r / "gravity-direction.txt").write_text("0\ndown\n0\n"),
                        "gravity-direction.txt:2: expected numbers"),
    "7s depth wrong size": (_seven, lambda r: cv2.imwrite(str(r / "frame-000002.depth.png"), np.full((12, 16), 9, np.uint16)),
                            "frame-000002.depth.png is 16x12, the intrinsics say 32x24"),
    "7s missing colour": (_seven, lambda r: (r / "frame-000000.color.png").unlink(), "colour image"),
    # nerfstudio
    "ns not json": (_nerf, lambda r: (r / "transforms.json").write_text("{frames: oops"), "transforms.json"),
    "ns no frames list": (_nerf, lambda r: (r / "transforms.json").write_text("{}"), 'a "frames" list'),
    "ns missing fl_x": (_nerf, lambda r: _edit_json(r, lambda m: m.pop("fl_x")), "frame 0 (images/frame_00003.png): missing fl_x"),
    "ns k4 without fisheye": (_nerf, lambda r: _edit_json(r, lambda m: m.update(k4=0.1)), "k4 is only read"),
    "ns unsupported model": (_nerf, lambda r: _edit_json(r, lambda m: m.update(camera_model="EQUIRECTANGULAR")),
                             "'EQUIRECTANGULAR' is not supported"),
    "ns 3x3 transform": (_nerf, lambda r: _edit_json(r, lambda m: m["frames"][1].update(transform_matrix=np.eye(3).tolist())),
                         "frame 1 (images/frame_00002.png): transform_matrix must be a 4x4"),
    "ns scaled transform": (_nerf, lambda r: _edit_json(r, lambda m: m["frames"][0].update(
        transform_matrix=(2 * np.eye(4) - np.diag([0, 0, 0, 1])).tolist())), "not rigid"),
    "ns no depth files": (_nerf, lambda r: _edit_json(r, lambda m: [f.pop("depth_file_path") for f in m["frames"]]),
                          "no depth images (nerfstudio layout: no frame has a depth_file_path); fusion needs depth"),
    "ns missing image": (_nerf, lambda r: (r / "images" / "frame_00002.png").unlink(), "colour image"),
    "ns depth other aspect": (_nerf, lambda r: cv2.imwrite(str(r / "depth" / "frame_00001.png"), np.full((16, 16), 9, np.uint16)),
                              "is 16x16, the intrinsics say 32x24"),
    # Stray Scanner
    "stray row of 8": (_stray, lambda r: _replace(r / "odometry.csv", ", 0.0, ", ", "), "odometry.csv:2: expected 9 values"),
    "stray bad quaternion": (_stray, lambda r: _replace(r / "odometry.csv", "000001, ", "000001, 0, 0, 0, 0, 0, 0, 0 #"),
                             "odometry.csv:3: the pose is not rigid (quaternion norm 0"),
    "stray bad header": (_stray, lambda r: _replace(r / "odometry.csv", "qx, qy", "qa, qb"), "odometry.csv:1: unexpected header"),
    "stray frame twice": (_stray, lambda r: _replace(r / "odometry.csv", "000002", "000001"), "odometry.csv:4: frame 1 is listed twice"),
    "stray camera matrix": (_stray, lambda r: (r / "camera_matrix.csv").write_text("20, 0, 15.5\n0, 20, 11.5\n"),
                            "camera_matrix.csv: expected 3 lines"),
    "stray no colour": (_stray, lambda r: shutil.rmtree(r / "rgb"), "neither rgb.mp4 nor an rgb/ folder"),
    "stray confidence size": (_stray, lambda r: cv2.imwrite(str(r / "confidence" / "000001.png"), np.full((24, 32), 2, np.uint8)),
                              "confidence image"),
    "stray video shorter": (lambda r: _stray(r, video=True), _video_shorter, "rgb.mp4 ends after 3 frames"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_layouts_give_one_line_errors(case, tmp_path, capsys):
    make, mutate, fragment = CASES[case]
    root = make(tmp_path / "frames")
    mutate(root)
    out = tmp_path / "out.ply"
    assert main(["--quiet", "fuse", str(root), "--out", str(out), "--voxel", "0.05"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:") and fragment in err[0], err
    assert not out.exists()


@pytest.mark.parametrize("make", [_seven, _nerf, _stray, lambda r: _stray(r, video=True)], ids=["7scenes", "nerfstudio", "stray", "stray-video"])
def test_valid_small_layouts_fuse(make, tmp_path, capsys):
    root = make(tmp_path / "frames")
    out = tmp_path / "ok.ply"
    assert main(["--quiet", "fuse", str(root), "--out", str(out), "--voxel", "0.05"]) == 0
    V = np.asarray(load_scene(str(out)).parts[0].vertices, float)
    assert len(V) > 50


@pytest.mark.parametrize("args, fragment", [(["--up", "sideways"], "--up 'sideways'"), (["--up", "0,0,0"], "--up '0,0,0'"),
                                            (["--format", "stray"], "camera_matrix.csv not found"),
                                            (["--format", "nerfstudio"], "transforms.json not found")])
def test_bad_up_and_format_give_one_line_errors(args, fragment, tmp_path, capsys):
    root = _seven(tmp_path / "frames")
    assert main(["--quiet", "fuse", str(root), "--out", str(tmp_path / "o.ply"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0], err
