"""``plan --frames``: planning at a rendered handheld sequence's own poses from its own images
(:mod:`markerplace.pipelines.plan_frames`), checked against the ``tiny`` scene it came from."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest

from markerplace.cli.main import main
from markerplace.imaging.visibility import marker_points, markers_unoccluded
from markerplace.pipelines.plan_frames import prepare_frames
from markerplace.plan.config import PlanConfig
from markerplace.plan.place.stage import place
from markerplace.render.renderer import Renderer
from markerplace.scan.frames import open_frameset
from markerplace.scan.simulate import distance_to_scene
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster


@pytest.fixture(scope="module")
def tiny():
    return load_scene("tiny")


@pytest.fixture(scope="module")
def prepared(tiny_frames, tmp_path_factory):
    fs = open_frameset(tiny_frames)
    run = tmp_path_factory.mktemp("prepared")
    return fs, run, prepare_frames(fs, np.arange(len(fs.frames)), PlanConfig(), run, progress=False)


def test_poses_are_the_frames_own(prepared):
    fs, _, data = prepared
    d = data.disc
    assert np.allclose(d.world_from_cam, [r.world_from_cam for r in fs.frames])
    assert d.location_index.tolist() == list(range(len(fs.frames)))
    assert np.allclose(d.location_z, d.world_from_cam[:, 2, 3])
    assert d.summary["frames"]["count"] == 40 and d.summary["frames"]["layout"] == "markerplace"
    assert d.summary["frames"]["floor_found"] and abs(d.storeys[0]) < 0.03  # tiny's floor is z = 0


def test_candidates_lie_on_the_true_walls(prepared, tiny):
    _, _, data = prepared
    p, n = data.disc.candidate_position, data.disc.candidate_normal
    assert data.num_candidates >= 6
    assert np.all(distance_to_scene(p, tiny) < 0.03)
    _, f = RayCaster(*tiny.geometry()).first_hits(p + 0.1 * n, -n, 0.2)
    assert np.all(f >= 0)
    true_n = RayCaster(*tiny.geometry()).face_normal[f]
    assert np.all(np.abs(np.einsum("ij,ij->i", true_n, n)) > np.cos(np.radians(10)))


def test_observed_points_lie_on_the_true_surface(prepared, tiny):
    _, _, data = prepared
    d = distance_to_scene(data.points_world, tiny)
    assert len(d) > 300
    assert np.median(d) < 0.02 and np.quantile(d, 0.9) < 0.05


def test_unoccluded_agrees_with_a_render_of_the_same_tags(prepared, tiny):
    fs, run, data = prepared
    from markerplace.imaging.features import FeatureSet
    from markerplace.plan.discretize.artifact import load

    obs = FeatureSet.load(run / "observations").extras["candidate_unoccluded"]
    disc = load(run / "discretization.npz")  # every candidate (the scores drop those nobody sees)
    samples = marker_points(disc.candidate_world_from_marker, PlanConfig().placement.tag_size)
    rendered = np.zeros_like(obs)
    with Renderer(tiny, fs.intrinsics) as r:
        for i, T in enumerate(disc.world_from_cam):
            res = r.render(T, rgb=False, depth=True, normal=False)
            rendered[i] = markers_unoccluded(res.depth, T, fs.intrinsics.K, samples, 0.10)
    assert rendered.sum() > 20
    assert (obs == rendered).mean() > 0.95


def test_second_prepare_reuses_every_stage(prepared):
    fs, run, data = prepared
    again = prepare_frames(fs, np.arange(len(fs.frames)), PlanConfig(), run, progress=False)
    assert set(again.timings) >= {"fuse", "discretize", "observe"}
    assert np.array_equal(again.disc.candidate_position, data.disc.candidate_position)
    assert np.allclose(again.base_score, data.base_score)


def test_frames_looked_at_in_this_process_give_the_pools_observations(prepared, tiny_frames, tmp_path):
    """The fixture looked at the frames on a pool (PlanConfig's automatic workers: the CPU count,
    2 in CI); one process must give the same bytes."""
    fs, run, data = prepared
    one = replace(PlanConfig(), runtime=replace(PlanConfig().runtime, workers=1))
    shutil.copy(run / "fused.ply", tmp_path / "fused.ply")
    again = prepare_frames(fs, np.arange(len(fs.frames)), one, tmp_path, progress=False)
    assert "observe" in again.timings
    assert np.array_equal(again.points_world, data.points_world, equal_nan=True)
    assert np.array_equal(again.pose_index, data.pose_index)
    assert np.array_equal(again.base_score, data.base_score)


@pytest.mark.parametrize("method", ["omp", "random", "uniform", "human"])
def test_every_method_but_the_calibrated_one_places_tags(prepared, method):
    _, _, data = prepared
    config = replace(PlanConfig().placement, method=method, k=3)
    placement = place(data, config, progress=False)
    assert len(set(placement.candidates.tolist())) == 3


def test_a_given_mesh_replaces_the_fused_surface(prepared, tmp_path):
    fs, run, data = prepared
    shutil.copy(run / "fused.ply", tmp_path / "mesh.ply")
    other = prepare_frames(fs, np.arange(len(fs.frames)), PlanConfig(), tmp_path / "run", mesh=tmp_path / "mesh.ply",
                           progress=False)
    assert not (tmp_path / "run" / "fused.ply").exists()
    assert np.allclose(other.disc.candidate_position, data.disc.candidate_position)
    assert other.disc.summary["frames"]["surface"] == str(tmp_path / "mesh.ply")


def test_plan_from_frames_end_to_end(tiny_frames, tiny, tmp_path):
    out = tmp_path / "o"
    assert main(["plan", "--frames", str(tiny_frames), "-k", "3", "--out", str(out), "--paper", "none",
                 "--quiet"]) == 0
    doc = json.loads((out / "placement.json").read_text())
    pos = np.array([m["position"] for m in doc["markers"]])
    assert len(pos) == 3 and np.all(distance_to_scene(pos, tiny) < 0.03)
    assert all(0.4 < m["install"]["height_m"] < 2.0 for m in doc["markers"])
    report = (out / "report.html").read_text()
    assert "planned from frames" in report and "40 of 40 frames" in report and "camera_path.png" in report
    assert (out / "camera_path.png").is_file() and (out / "fused.ply").is_file()
    config = json.loads((out / "config.json").read_text())
    assert config["scene"].startswith("frames:") and config["imaging"]["camera"]["width"] == 320
    # config.json reproduces the plan (in the same folder: every cached stage is reused)
    (tmp_path / "config.json").write_text((out / "config.json").read_text())
    assert main(["plan", "--frames", str(tiny_frames), "--config", str(tmp_path / "config.json"), "--out", str(out),
                 "--paper", "none", "--quiet"]) == 0
    assert json.loads((out / "placement.json").read_text())["markers"] == doc["markers"]
    # the commands that rebuild a run from a scene say they cannot (one line)
    assert main(["export", str(out), "--gltf", str(tmp_path / "x.glb")]) == 2


@pytest.mark.parametrize("args, message", [
    (["tiny", "--frames", "{frames}"], "not both"),
    ([], "a scene (a built-in name or a mesh file) or --frames DIR"),
    (["--frames", "{frames}", "--method", "expected-recall"], "calibrated by rendering"),
    (["--frames", "{empty}"], "not an RGB-D frame folder"),
])
def test_bad_input_is_one_line(args, message, tiny_frames, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    args = [a.format(frames=tiny_frames, empty=tmp_path / "empty") for a in args]
    assert main(["plan", *args, "-k", "3", "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err


def test_a_7scenes_copy_of_the_frames_plans_the_same_spots(prepared, tiny, tmp_path):
    """The same frames written in the 7-Scenes layout (the format's own conventions, in a world
    tilted by 100 degrees with its gravity file; tests/helpers/frame_layouts.py) give candidate
    spots on the same true walls: the layout's reader, up axis and depth registration feed the
    plan as the project's own layout does."""
    from helpers.frame_layouts import write_7scenes
    from markerplace.geometry import invert
    from markerplace.scan.frame_images import load_frame

    fs, _, data = prepared
    c, s_ = np.cos(np.radians(100.0)), np.sin(np.radians(100.0))
    A = np.eye(4)
    A[1:3, 1:3] = [[c, -s_], [s_, c]]
    frames = []
    for rec in fs.frames:
        rgb, d16 = load_frame(fs, rec)
        frames.append((rgb, d16 / fs.depth_scale, A @ rec.world_from_cam))
    write_7scenes(tmp_path / "seq", frames, fs.intrinsics, gravity_down=A[:3, :3] @ np.array([0.0, 0.0, -1.0]))
    fs7 = open_frameset(tmp_path / "seq")
    assert fs7.format == "7scenes" and fs7.up_source == "gravity-direction.txt"
    data7 = prepare_frames(fs7, np.arange(len(fs7.frames)), PlanConfig(), tmp_path / "run", progress=False)
    scene_from_world7 = fs.frames[0].world_from_cam @ invert(fs7.frames[0].world_from_cam)
    np.testing.assert_allclose(scene_from_world7[2, :3], [0, 0, 1], atol=1e-6)  # z up in both worlds
    pos = (scene_from_world7[:3, :3] @ data7.disc.candidate_position.T).T + scene_from_world7[:3, 3]
    assert abs(len(pos) - data.num_candidates) <= max(2, data.num_candidates // 4)
    assert np.max(distance_to_scene(pos, tiny)) < 0.03
