"""Testbed: marker-in-view test, feature re-use across placements, feature sets, experiments,
and a small end-to-end ``evaluate`` run."""

import json

import numpy as np
import pytest

from helpers import undeclared_outputs
from markerplace.geometry import Intrinsics, world_from_cam_pose, world_from_marker_pose
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import FeatureSet, FeatureWriter, ImageFeatures
from markerplace.imaging.visibility import marker_points, markers_in_view
from markerplace.localization.sift import SIFT_DEFAULT
from markerplace.markers import Marker
from markerplace.pipelines.evaluate import EVALUATE_OUTPUTS
from markerplace.runtime.executor import InProcessExecutor
from markerplace.scene.types import MeshPart, Scene
from markerplace.simulation import marker_sets as placements
from markerplace.simulation import pose_sampling as tposes
from markerplace.simulation.rendered_images import TestbedImaging
from markerplace.testbed import config as tbconfig


def _box_scene(size=4.0, height=2.7):
    """A closed textured box room [0, size]^2 x [0, height] with seeded noise walls."""
    rng = np.random.default_rng(0)
    tex = (rng.random((256, 256, 3)) * 255).astype(np.uint8)
    tex = np.kron(tex[::4, ::4], np.ones((4, 4, 1), np.uint8))  # blocky -> plenty of SIFT
    s, h = size, height
    quads = {  # inward-facing walls, floor, ceiling (counter-clockwise seen from inside)
        "south": [(0, 0, 0), (s, 0, 0), (s, 0, h), (0, 0, h)],
        "north": [(s, s, 0), (0, s, 0), (0, s, h), (s, s, h)],
        "west": [(0, s, 0), (0, 0, 0), (0, 0, h), (0, s, h)],
        "east": [(s, 0, 0), (s, s, 0), (s, s, h), (s, 0, h)],
        "floor": [(0, 0, 0), (0, s, 0), (s, s, 0), (s, 0, 0)],
        "ceiling": [(0, 0, h), (s, 0, h), (s, s, h), (0, s, h)],
    }
    parts = []
    for name, q in quads.items():
        v = np.array(q, np.float32)
        uv = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32)
        parts.append(MeshPart(name, v, np.array([[0, 1, 2], [0, 2, 3]], np.int32), uv=uv, texture=tex))
    return Scene("box", tuple(parts), floor_z=0.0)


class _BoxSpec:
    """Picklable stand-in for SceneSpec (workers=1 runs in-process anyway)."""

    def load(self):
        return _box_scene()


def test_markers_in_view_projection_margin_and_occlusion():
    K = Intrinsics().K
    cam = world_from_cam_pose(np.array([2.0, 2.0, 1.5]), 0.0)  # looks along +x
    depth = np.full((450, 600), 2.0, np.float32)  # wall 2 m ahead
    ahead = Marker(0, 0.4, world_from_marker_pose(np.array([4.0, 2.0, 1.5]), np.array([-1.0, 0, 0])))
    behind = Marker(1, 0.4, world_from_marker_pose(np.array([0.0, 2.0, 1.5]), np.array([1.0, 0, 0])))
    side = Marker(2, 0.4, world_from_marker_pose(np.array([2.5, 4.0, 1.5]), np.array([0, -1.0, 0])))
    def samples_of(markers):
        return marker_points(np.array([m.world_from_marker for m in markers]), [m.size for m in markers], grid=7)

    samples = samples_of([ahead, behind, side])
    assert samples.shape == (3, 49, 3)
    vis = markers_in_view(depth, cam, K, samples, margin_px=16, tolerance=0.1)
    # 'ahead' sits at 2 m depth but the wall there is at 2 m -> visible; 'behind' is behind the
    # camera; 'side' projects far outside the 90 deg field of view.
    assert vis.tolist() == [True, False, False]
    occluded = markers_in_view(np.full((450, 600), 1.0, np.float32), cam, K, samples, 16, 0.1)
    assert occluded.tolist() == [False, False, False]
    # a marker just outside the image border still counts inside the margin
    edge = Marker(3, 0.2, world_from_marker_pose(np.array([4.0, 4.3, 1.5]), np.array([-1.0, 0, 0])))
    s = samples_of([edge])
    assert markers_in_view(depth, cam, K, s, margin_px=40, tolerance=0.1).tolist() == [True]
    assert markers_in_view(depth, cam, K, s, margin_px=0, tolerance=0.1).tolist() == [False]


def test_feature_set_round_trip_and_replace(tmp_path):
    rng = np.random.default_rng(0)

    def img(n, t):
        return ImageFeatures(rng.random((n, 2), np.float32), rng.integers(0, 255, (n, 128)).astype(np.uint8),
                                 rng.random((n, 3)).astype(np.float32), np.arange(t, dtype=np.int32),
                                 rng.random((t, 4, 2)).astype(np.float32))

    fs = FeatureSet.from_images([img(5, 0), img(0, 1), img(3, 2)])
    assert len(fs) == 3 and fs.offsets.tolist() == [0, 5, 5, 8] and fs.tag_offsets.tolist() == [0, 0, 1, 3]
    fs.save(tmp_path / "f")
    back = FeatureSet.load(tmp_path / "f", mmap=True)
    assert np.array_equal(back.descriptors, fs.descriptors) and np.array_equal(back.image(2).tag_corners, fs.image(2).tag_corners)
    new = img(7, 1)
    rep = back.with_images({1: new})
    assert rep.offsets.tolist() == [0, 5, 12, 15] and np.array_equal(rep.image(1).keypoints, new.keypoints)
    assert np.array_equal(rep.image(2).descriptors, fs.image(2).descriptors)


def test_render_reuse_identical_without_marker_in_view():
    """The efficiency premise: a render whose view holds no marker equals the marker-free one,
    and the in-view test flags the markers that do change the image."""
    seen = Marker(5, 0.4, world_from_marker_pose(np.array([4.0, 2.0, 1.5]), np.array([-1.0, 0, 0])))
    unseen = Marker(6, 0.4, world_from_marker_pose(np.array([0.0, 2.0, 1.5]), np.array([1.0, 0, 0])))
    poses = np.stack([world_from_cam_pose(np.array([2.0, 2.0, 1.5]), 0.0),
                      world_from_cam_pose(np.array([2.0, 2.0, 1.5]), np.pi)])
    tb = TestbedImaging(_BoxSpec(), ImagingConfig(sift=SIFT_DEFAULT), [seen, unseen], InProcessExecutor(), progress=False)
    with tb.executor:
        base = tb.render(poses, [0, 1], [], False, "base")
        marked = tb.render(poses, [0, 1], [seen], False, "with marker")
    vis = np.stack([base[0].extras["in_view"], base[1].extras["in_view"]])
    assert vis.tolist() == [[True, False], [False, True]]
    assert tb.view_keys(vis, [seen]) == [((0, 5),), ()]  # (union column, tag id) of the markers in view
    assert tb.view_keys(vis, []) == [(), ()]
    # another id at the same pose: the same visibility column, another appearance
    renamed = Marker(9, 0.4, seen.world_from_marker)
    assert tb.view_keys(vis, [renamed]) == [((0, 9),), ()] and len(tb.union) == 2
    base = {i: (f, None) for i, f in base.items()}
    marked = {i: (f, None) for i, f in marked.items()}
    # pose 1 looks away from 'seen': features identical with and without it
    assert np.array_equal(base[1][0].descriptors, marked[1][0].descriptors)
    assert np.array_equal(base[1][0].keypoints, marked[1][0].keypoints)
    # pose 0 sees it: different features, and the tag is detected with its id
    assert not np.array_equal(base[0][0].keypoints, marked[0][0].keypoints)
    assert marked[0][0].tag_ids.tolist() == [5] and base[0][0].tag_ids.tolist() == []


def test_shift_and_scale_markers():
    ms = [Marker(i, 0.4, world_from_marker_pose(np.array([1.0 + i, 0.0, 1.5]), np.array([0, 1.0, 0]))) for i in range(4)]
    shifted = placements.shift_markers(ms, 0.25, seed=3)
    d = np.array([s.position - m.position for s, m in zip(shifted, ms)])
    assert np.allclose(np.abs(d[:, 0]), 0.25) and np.allclose(d[:, 1:], 0)
    assert np.all(np.sign(d[1:, 0]) == -np.sign(d[:-1, 0]))  # alternating
    assert np.allclose([s.world_from_marker[:3, :3] for s in shifted], [m.world_from_marker[:3, :3] for m in ms])
    again = placements.shift_markers(ms, 0.25, seed=3)
    assert np.allclose([a.position for a in again], [s.position for s in shifted])
    scaled = placements.scale_markers(ms, 1.5)
    assert all(s.size == pytest.approx(0.6) and np.allclose(s.position, m.position) for s, m in zip(scaled, ms))


@pytest.mark.parametrize("part, field, value, message", [
    ("study", "tag_scale", 0.0, "--tag-scale"), ("study", "shift", -1.0, "--shift"),
    ("study", "methods", ("omp", "best"), "--methods"), ("test", "sets", ("hard",), "--test-sets"),
    ("study", "ks", (0,), "--k"), ("study", "runs", 0, "--runs"), ("test", "tests", 0, "--tests"),
    ("localization", "localizer", "orb", "--localizer"),
])
def test_bad_evaluate_settings_are_user_errors(part, field, value, message):
    from dataclasses import replace

    from markerplace.errors import UserError

    base = tbconfig.EvaluateConfig()
    config = replace(base, **{part: replace(getattr(base, part), **{field: value})})
    with pytest.raises(UserError, match=message):
        tbconfig.validate_evaluate_config(config)


def test_find_placement_files(tmp_path):
    (tmp_path / "expert").mkdir()
    (tmp_path / "expert" / "placement.json").write_text(json.dumps({"markers": []}))
    (tmp_path / "manual.json").write_text("[]")
    (tmp_path / "human.json").write_text("[]")  # a built-in method's name: renamed
    (tmp_path / "expert" / "config.json").write_text("{}")
    found = placements.find_placement_files(tmp_path)
    assert sorted(found) == ["expert", "human-file", "manual"]
    # a plan folder's own artifacts are not placements; the diagnostics' names are reserved
    (tmp_path / "expert" / "success_model_expected-recall.json").write_text("{}")
    (tmp_path / "expert" / "tagmaps").mkdir()
    (tmp_path / "expert" / "tagmaps" / "wpilib_field_layout.json").write_text("{}")
    (tmp_path / "expert" / "calibration").mkdir()
    (tmp_path / "expert" / "calibration" / "x.json").write_text("{}")
    (tmp_path / "ceiling.json").write_text("[]")
    assert sorted(placements.find_placement_files(tmp_path)) == ["ceiling-file", "expert", "human-file", "manual"]


# --- end to end --------------------------------------------------------------------------------

FAST = ["--grid-spacing", "1.0", "--yaws", "4", "--workers", "2", "--quiet"]


def test_evaluate_tiny_end_to_end_and_resume(tmp_path, capsys):
    import csv

    from markerplace.cli.main import main

    out = tmp_path / "eval"
    args = ["evaluate", "tiny", "--out", str(out), "--tests", "20", "--k", "2", "--runs", "1", *FAST]
    assert main(args) == 0
    assert undeclared_outputs(out, EVALUATE_OUTPUTS) == []  # what --adopt checks before any work
    printed = capsys.readouterr().out  # the printed summary carries the paired intervals
    assert "Paired differences, `weighted` test set, 5cm/5deg" in printed and "| Ours | Rand. (1 run) |" in printed
    for name in ("recall.csv", "tables.md", "recall_vs_k.png", "query_errors.npz", "timings.json", "config.json",
                 "test_poses_weighted.npz", "test_poses_uniform.npz"):
        assert (out / name).stat().st_size > 0, name
    rows = list(csv.DictReader((out / "recall.csv").open()))
    got = {(r["method"], r["run"], r["k"], r["test_set"], r["threshold"]) for r in rows}
    expected = {(m, "0", k, ts, th) for m, k in [("none", "0"), ("omp", "2"), ("random", "2"), ("uniform", "2"), ("human", "2"),
                                                 ("expected-recall", "2")]
                for ts in ("weighted", "uniform") for th in ("1cm/1deg", "5cm/5deg", "10cm/10deg", "1m/30deg")}
    assert got == expected and len(rows) == len(expected)
    assert all(r["scene"] == "tiny" and r["n_tests"] == "20" and 0.0 <= float(r["recall"]) <= 1.0 for r in rows)
    env = json.loads((out / "config.json").read_text())["environment"]  # what the numbers were computed with
    assert env["packages"]["numpy"] == np.__version__ and "GL_RENDERER" in env["gl"]
    for r in rows:  # recall is monotone in the threshold
        if r["threshold"] == "1cm/1deg":
            loose = next(x for x in rows if x["threshold"] == "1m/30deg" and
                         (x["method"], x["k"], x["test_set"]) == (r["method"], r["k"], r["test_set"]))
            assert float(loose["recall"]) >= float(r["recall"])
    tables = (out / "tables.md").read_text()
    assert "| tiny (" in tables
    assert "## Paired differences at 5cm/5deg" in tables and "| Ours | Rand. (1 run) |" in tables
    errs = np.load(out / "query_errors.npz")
    assert errs["weighted_t_err"].shape == (6, 20)
    assert errs["weighted_method"].tolist() == ["none", "omp", "random", "uniform", "human", "expected-recall"]
    # same test poses for every method: one file per test set, identical on a re-run
    poses = tposes.TestPoses.load(out / "test_poses_weighted.npz").world_from_cam
    results = sorted((out / "cache" / "predictions").glob("*.npz"))
    sets = [json.loads(p.with_name(p.name + ".meta.json").read_text())["test_set"] for p in results]
    # 6 marker sets x 2 test sets, and expected-recall's calibration on the map images: none and one
    # tag set (tiny has 11 candidates, so its 3 draws of min(20, 11) are one set)
    assert sorted(sets) == ["map"] * 2 + ["uniform"] * 6 + ["weighted"] * 6
    stamps = [p.stat().st_mtime_ns for p in results]
    assert main(args) == 0  # resume: every placement's predictions are reused
    assert [p.stat().st_mtime_ns for p in results] == stamps
    assert np.array_equal(tposes.TestPoses.load(out / "test_poses_weighted.npz").world_from_cam, poses)
    assert list(csv.DictReader((out / "recall.csv").open())) == rows
    # determinism: a fresh folder evaluating other placements alongside (k = 1 first, no OMP)
    # gives the shared placements bit-identical per-image errors (renders and results cached
    # between placements must not leak into each other)
    other = tmp_path / "other"
    assert main(["evaluate", "tiny", "--out", str(other), "--tests", "20", "--k", "1,2", "--runs", "1",
                 "--methods", "none,random", "--test-sets", "weighted", *FAST]) == 0
    again = np.load(other / "query_errors.npz")
    for method in ("none", "random"):
        i = errs["weighted_method"].tolist().index(method)
        j = [(m, int(k)) for m, k in zip(again["weighted_method"].tolist(), again["weighted_k"])].index(
            (method, 0 if method == "none" else 2))
        for name in ("weighted_t_err", "weighted_r_err"):
            assert np.array_equal(errs[name][i], again[name][j], equal_nan=True), (method, name)


def test_evaluate_bad_option_is_one_line_error(tmp_path, capsys):
    from markerplace.cli.main import main

    assert main(["evaluate", "tiny", "--out", str(tmp_path / "x"), "--tag-scale", "0", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--tag-scale" in err[0]
    assert main(["evaluate", "tiny", "--out", str(tmp_path / "x"), "--k", "5,a", "--quiet"]) == 2


def test_feature_writer_streams_parts_and_resumes(tmp_path):
    """Parts written by an interrupted run with the same key are reused; other keys' parts are
    dropped; the assembled folder holds the images in order with their extras."""
    rng = np.random.default_rng(1)
    imgs = [ImageFeatures(rng.random((n, 2), np.float32), rng.integers(0, 255, (n, 128)).astype(np.uint8),
                          rng.random((n, 3)).astype(np.float32), extras={"flag": np.array([n % 2 == 0, True])})
            for n in (3, 0, 5, 2, 4)]
    w = FeatureWriter(tmp_path / "f", 5, "key-a", part_size=2)
    for i in (4, 1, 3):  # arrives in any order; the run stops before images 0 and 2
        w.add(i, imgs[i])
    w.flush()
    assert FeatureWriter(tmp_path / "f", 5, "key-b").done() == set()  # other settings: dropped
    for i in (4, 1, 3):
        w.add(i, imgs[i])
    w.flush()
    again = FeatureWriter(tmp_path / "f", 5, "key-a", part_size=2)
    assert again.done() == {1, 3, 4}
    for i in (0, 2):
        again.add(i, imgs[i])
    fs = again.finish()
    assert fs.offsets.tolist() == [0, 3, 3, 8, 10, 14] and not (tmp_path / "f" / "parts").exists()
    for i, f in enumerate(imgs):
        assert np.array_equal(fs.image(i).descriptors, f.descriptors)
        assert np.array_equal(fs.extras["flag"][i], f.extras["flag"])


def test_reusing_unchanged_queries_changes_no_result(tmp_path):
    """Queries that a placement's markers cannot change take the no-marker result: identical
    predictions to localizing every query. Both paths are exercised: OMP's tags change the
    retrieval of tiny's queries (they are localized again), a tag on the outside of the house
    changes nothing (nearly every query takes the no-marker result)."""
    from dataclasses import replace

    from markerplace.geometry import world_from_marker_pose
    from markerplace.pipelines.evaluate import run_evaluation
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import DiscretizeConfig
    from markerplace.runtime.executor import RuntimeConfig
    from markerplace.scene.spec import SceneSpec

    outside = Marker(30, 0.4, world_from_marker_pose(np.array([-0.15, 1.7, 1.5]), np.array([-1.0, 0.0, 0.0])))
    (tmp_path / "extra" / "outside").mkdir(parents=True)
    (tmp_path / "extra" / "outside" / "placement.json").write_text(json.dumps({"markers": [outside.to_json()]}))
    plan = PlanConfig(discretize=replace(DiscretizeConfig(), grid_spacing=1.0, num_yaws=4),
                      runtime=RuntimeConfig(workers=1))
    config = tbconfig.EvaluateConfig(test=tbconfig.TestSetConfig(tests=12, sets=("weighted",)),
                                     study=tbconfig.StudyConfig(methods=("none", "omp"), runs=1, ks=(3,)),
                                     diagnostics=tbconfig.DiagnosticsConfig(calibration=True))
    import shutil

    errors, outcomes = {}, {}
    for reuse in (False, True):
        out = tmp_path / f"reuse_{reuse}"
        if reuse:  # the same plan, map and query features; only the predictions are made again
            shutil.copytree(tmp_path / "reuse_False", out, ignore=shutil.ignore_patterns("predictions"))
        run_evaluation(SceneSpec("tiny"), plan, config, out, placements_dir=tmp_path / "extra", progress=False,
                       reuse_unchanged=reuse)
        errors[reuse] = np.load(out / "query_errors.npz")
        outcomes[reuse] = np.load(out / "map_outcomes.npz")
        metas = [json.loads(p.read_text()) for p in (out / "cache" / "predictions").glob("*.meta.json")]
        localized = {(m["method"], m["k"], m["test_set"]): m["localized"] for m in metas}
        assert localized[("omp", 3, "weighted")] > 0 and localized[("omp", 3, "map")] > 0
        # (a query whose image edge the tag is near counts as seeing it: the in-view test is conservative)
        assert localized[("outside", 1, "weighted")] < 4 if reuse else localized[("outside", 1, "weighted")] == 12
        # map images, each localized without its own location: the same reuse rule, with that exclusion
        assert localized[("outside", 1, "map")] < 8 if reuse else localized[("outside", 1, "map")] == 32
    assert errors[True]["weighted_method"].tolist() == ["none", "omp", "outside"]
    for key in errors[False].files:
        a, b = errors[False][key], errors[True][key]
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), key
    assert outcomes[True].files == outcomes[False].files and "corners_score" in outcomes[True].files
    for key in outcomes[False].files:
        assert np.array_equal(outcomes[False][key], outcomes[True][key]), key
