"""Output folders checked up front, NaN and absurd numbers, the run-size guard, render poses
(issue 13, items 2 and 3). Every case ends in one line ``markerplace: error: ...`` and exit 2."""

import argparse
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from helpers import FAST
from markerplace.cli.main import build_parser, main

try:
    from markerplace import validation
except ImportError:  # a version without it: its tests must fail, the CLI tests still run
    validation = None
from markerplace.cli import bounds
from markerplace.errors import UserError
from markerplace.pipelines import size_guard


def _one_line_error(capsys, *needles):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:"), err
    for needle in needles:
        assert needle in err[0], (needle, err[0])
    return err[0]


# --- item 2: output folders -----------------------------------------------------------------------

def _commands(out):
    return {
        "plan": ["plan", "tiny", "-k", "1", "--out", str(out), *FAST],
        "render": ["render", "tiny", "--out", str(out)],
        "scene export": ["scene", "export", "tiny", str(out)],
    }


@pytest.mark.parametrize("command", ["plan", "render", "scene export"])
def test_out_under_a_file_is_one_line_error(command, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(_commands(blocker / "sub" / "out")[command]) == 2
    _one_line_error(capsys, str(blocker), "is a file")


def test_plan_out_naming_a_file_is_one_line_error(tmp_path, capsys):
    target = tmp_path / "placement_dir"
    target.write_text("not a folder")
    assert main(_commands(target)["plan"]) == 2
    _one_line_error(capsys, "--out", "is an existing file")


def test_a_map_too_small_for_the_vlad_codebook_is_one_line(tmp_path, capsys):
    """expected-recall's fit on a map of a few images without 64 SIFT features: one line naming
    the fix, not k-means' ValueError."""
    args = ["plan", "tiny", "--method", "expected-recall", "--grid-spacing", "2", "--yaws", "1", "-k", "1",
            "--workers", "1", "--quiet", "--out", str(tmp_path / "o")]
    assert main(args) == 2
    _one_line_error(capsys, "VLAD codebook", "--grid-spacing")


@pytest.mark.parametrize("command", ["render", "scene export"])
def test_file_output_naming_a_folder_is_one_line_error(command, tmp_path, capsys):
    target = tmp_path / "tiny.glb"
    (target / "").mkdir()
    (tmp_path / "view_rgb.png").mkdir()
    out = target if command == "scene export" else tmp_path / "view"
    assert main(_commands(out)[command]) == 2
    _one_line_error(capsys, "is an existing folder")


def _run_without_root_powers(args, cwd):
    """Run the CLI in a subprocess that cannot bypass file permissions (root loses
    CAP_DAC_OVERRIDE through setpriv, as a normal user would be)."""
    cmd = [sys.executable, "-m", "markerplace.cli", *args]
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        if setpriv is None:
            pytest.fail("running as root without setpriv: cannot make a folder read-only for this test")
        cmd = [setpriv, "--inh-caps=-dac_override,-dac_read_search",
               "--bounding-set=-dac_override,-dac_read_search", "--", *cmd]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, timeout=120)


@pytest.mark.parametrize("command", ["plan", "render", "scene export"])
def test_read_only_folder_is_one_line_error(command, tmp_path):
    ro = tmp_path / "read_only"
    ro.mkdir()
    target = {"plan": ro / "plan", "render": ro / "view", "scene export": ro / "tiny.glb"}[command]
    if command == "plan":
        target.mkdir()  # an existing folder that cannot be written
    ro.chmod(0o555)
    target.chmod(0o555) if target.exists() else None
    try:
        t0 = time.perf_counter()
        res = _run_without_root_powers(_commands(target)[command], tmp_path)
        seconds = time.perf_counter() - t0
    finally:
        ro.chmod(0o755)
        if target.exists():
            target.chmod(0o755)
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert len(err) == 1 and "cannot" in err[0] and str(ro) in err[0], err
    assert seconds < 60  # refused before any rendering
    assert not any(p.name != "plan" for p in ro.iterdir())


# --- item 3: NaN and absurd numbers --------------------------------------------------------------

@pytest.mark.parametrize("option, value, needle", [
    ("--grid-spacing", "nan", "not a finite number"),
    ("--grid-spacing", "inf", "not a finite number"),
    ("--grid-spacing", "1e-4", "is outside [0.05, 50] m"),
    ("--grid-spacing", "0.01", "is outside [0.05, 50] m"),
    ("--marker-spacing", "nan", "not a finite number"),
    ("--clearance", "-1", "is outside [0, 5] m"),
    ("--height", "nan", "not a finite number"),
    ("--tag-size", "inf", "not a finite number"),
    ("-v", "nan", "not a finite number"),
    ("--unit-scale", "nan", "not a finite number"),
    ("--unit-scale", "-1", "--unit-scale"),
    ("--workers", "100000", "must be at most 256"),
    ("--placement-seed", "-1", "must be at least 0"),
    ("--seed", "-3", "must be at least 0"),
    ("--yaws", "100000000000000000000", "must be at most 360"),
    ("-k", "-2", "must be at least 1"),
    ("--level", "99999", "must be at most 1000"),
    ("--start", "nan,1", "X = nan is not a finite number"),
    ("--start", "1,2,3", "X,Y"),
])
def test_plan_numbers_are_checked_before_any_work(option, value, needle, tmp_path, capsys, monkeypatch):
    import markerplace.pipelines.plan

    monkeypatch.setattr(markerplace.pipelines.plan, "prepare", lambda *a, **k: pytest.fail("prepare ran"))
    t0 = time.perf_counter()
    assert main(["plan", "tiny", "--out", str(tmp_path / "o"), *FAST, option, value]) == 2
    assert time.perf_counter() - t0 < 5
    _one_line_error(capsys, option if option != "--start" else "--start", needle)
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("args, needle", [
    (["--pose", "nan,1,1.5,0"], "X = nan is not a finite number"),
    (["--pose", "1,1,inf,0"], "Z = inf"),
    (["--pose", "1,1,1.5,nan"], "YAW_DEG = nan"),
    (["--pose", "50,50,1.5,0"], "outside the model"),
    (["--pose", "1.5,1.5,-3,0"], "outside the model"),
    (["--width", "0"], "--width 0 must be at least 16"),
    (["--height", "99999"], "--height 99999 must be at most 4096 px"),
    (["--hfov", "180"], "--hfov 180 deg is outside [1, 170] deg"),
    (["--hfov", "nan"], "not a finite number"),
])
def test_render_bad_pose_or_camera_writes_nothing(args, needle, tmp_path, capsys):
    prefix = tmp_path / "view"
    assert main(["render", "tiny", "--out", str(prefix), *args]) == 2
    _one_line_error(capsys, needle)
    assert not list(tmp_path.iterdir())


def test_render_that_sees_nothing_is_refused():
    class Result:
        depth = np.zeros((4, 4), np.float32)

    with pytest.raises(UserError, match="sees nothing"):
        validation.check_render_sees_something(Result(), "1,1,1,0")
    Result.depth[1, 1] = 2.0
    validation.check_render_sees_something(Result(), "1,1,1,0")


@pytest.mark.parametrize("args, needle", [
    (["--tests", "nan"], "invalid int"),  # argparse: exit 2 with usage
    (["--tests", "1000000000"], "--tests 1000000000 must be at most 100000"),
    (["--k", "5,-1"], "--k -1 must be at least 1"),
    (["--k", "99999999999999999999999"], "--k 9999...(23 digits) must be at most 10000"),
    (["--tag-scale", "nan"], "not a finite number"),
    (["--shift", "inf"], "not a finite number"),
    (["--test-seed", "-1"], "must be at least 0"),
    (["--runs", "0"], "--runs 0 must be at least 1"),
])
def test_evaluate_numbers_are_checked(args, needle, tmp_path, capsys):
    try:
        code = main(["evaluate", "tiny", "--out", str(tmp_path / "e"), "--quiet", *args])
    except SystemExit as exc:  # argparse rejects a non-integer for an int option itself
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err, err


def _numeric_options(parser: argparse.ArgumentParser, prefix: str = ""):
    """(subcommand, dest) of every option parsed as int or float."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _numeric_options(sub, f"{prefix} {name}".strip())
        elif action.type in (int, float):
            yield prefix, action.dest


def test_every_numeric_option_has_a_bound():
    missing = [(cmd, dest) for cmd, dest in _numeric_options(build_parser())
               if dest not in bounds.option_bounds().get(cmd, {})]
    assert not missing, f"numeric options without a bound in markerplace.cli.bounds.option_bounds(): {missing}"


def test_bound_messages_name_option_value_range_and_unit():
    b = bounds.field_bound("plan", "discretize.grid_spacing")
    for value, needle in [(float("nan"), "not a finite number"), (-1.0, "-1 m is outside [0.05, 50] m"),
                          (1e300, "1e+300 m is outside"), ("x", "is not a number")]:
        with pytest.raises(UserError, match="--grid-spacing") as info:
            b.check(value)
        assert needle in str(info.value) and "metres" in str(info.value)
    assert b.check(0.5) == 0.5


# --- item 3: the size guard --------------------------------------------------------------------------

def test_size_guard_refuses_a_run_that_would_not_fit(tmp_path, capsys, monkeypatch):
    import markerplace.pipelines.plan

    monkeypatch.setattr(markerplace.pipelines.plan, "prepare", lambda *a, **k: pytest.fail("prepare ran"))
    t0 = time.perf_counter()
    assert main(["plan", "office", "--grid-spacing", "0.05", "--out", str(tmp_path / "o"), "--quiet"]) == 2
    assert time.perf_counter() - t0 < 20
    line = _one_line_error(capsys, "camera poses", "GiB of memory", "--force", "--grid-spacing")
    assert "more than 200,000 poses" in line
    assert not (tmp_path / "o").exists()  # a refused run leaves nothing behind


def test_size_guard_counts_the_poses_when_the_bounding_box_overstates_them(tmp_path, caplog, monkeypatch):
    """A small room beside a tall, far mast (a multi-level game level, an antenna, a stray
    vertex): the bounding-box bound is over the limits (by less than ten times), the
    discretized count is not, so the run goes on; the log gives both."""
    import logging

    import trimesh

    from markerplace.scene import load_scene

    V, F = (np.asarray(a) for a in load_scene("tiny").geometry())
    mast = trimesh.creation.box(extents=(0.2, 0.2, 12.0))
    mast.apply_translation((40.0, 40.0, 6.0))
    path = tmp_path / "tiny_and_mast.obj"
    trimesh.Trimesh(np.vstack([V, mast.vertices]), np.vstack([F, len(V) + mast.faces]), process=False).export(str(path))
    monkeypatch.setattr(size_guard, "machine_memory_bytes", lambda: 24 * 2**30)  # the bound: 164 GB, 9 x over
    with caplog.at_level(logging.INFO):
        assert main(["plan", str(path), "-k", "1", "--out", str(tmp_path / "o"), "--grid-spacing", "0.5",
                     "--yaws", "8", "--workers", "1"]) == 0
    text = caplog.text
    assert "by the bounding box; counting the camera poses" in text and "(discretized)" in text


def test_size_guard_estimate_bounds_the_real_pose_count(tmp_path):
    import json
    from dataclasses import replace

    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import DiscretizeConfig
    from markerplace.scene import load_scene

    out = tmp_path / "p"
    assert main(["plan", "tiny", "-k", "1", "--out", str(out), *FAST]) == 0
    poses = json.loads((out / "placement.json").read_text())["summary"]["num_poses"]
    config = PlanConfig(discretize=replace(DiscretizeConfig(), grid_spacing=1.0, num_yaws=4))
    est = size_guard.estimate_run(load_scene("tiny"), config)
    assert poses <= est.poses <= 4 * poses
    assert est.seconds == pytest.approx(est.poses * size_guard.SECONDS_PER_POSE_CORE / est.workers)


def test_size_guard_limits_and_force(caplog):
    est = size_guard.RunEstimate(footprint_m2=100.0, poses=50_000, memory_bytes=50e9, seconds=3600.0, workers=2)
    with pytest.raises(UserError, match=r"50,000 camera poses.*more memory than this machine has \(16.0 GiB\).*--force"):
        size_guard.check_run_size(est, memory_bytes=16 * 2**30)
    size_guard.check_run_size(est, memory_bytes=128 * 2**30)  # fits a bigger machine
    with pytest.raises(UserError, match="longer than 0.5 h"):
        size_guard.check_run_size(est, limits=size_guard.SizeLimits(max_hours=0.5), memory_bytes=128 * 2**30)
    import logging

    with caplog.at_level(logging.WARNING):
        size_guard.check_run_size(est, force=True, memory_bytes=16 * 2**30)
    assert "--force" in caplog.text


def test_force_flag_is_accepted_by_plan_and_evaluate():
    parser = build_parser()
    assert parser.parse_args(["plan", "tiny", "--out", "x", "--force"]).force
    assert not parser.parse_args(["evaluate", "tiny", "--out", "x"]).force


def test_size_guard_counts_storeys_of_level_all():
    from dataclasses import replace

    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import DiscretizeConfig
    from markerplace.scene import load_scene

    house = load_scene("house")  # two storeys
    every = size_guard.estimate_run(house, PlanConfig(discretize=replace(DiscretizeConfig(), level=None)))
    one = size_guard.estimate_run(house, PlanConfig(discretize=replace(DiscretizeConfig(), level=0)))
    assert every.storeys == 2 and one.storeys == 1 and every.poses == 2 * one.poses
    assert size_guard.estimate_run(load_scene("tiny"), PlanConfig()).storeys == 1
    assert "x 2 storeys" in every.describe()


def test_measured_estimate_times_the_scene_and_refuses_a_run_too_long(monkeypatch, caplog):
    """After discretizing, the estimate comes from a timed sample of the scene's own poses; a
    scene whose poses are slow enough to need more than the limit is refused before rendering."""
    import logging

    from markerplace.pipelines import size_guard
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import discretize
    from markerplace.scene.spec import SceneSpec

    spec = SceneSpec("tiny", None, None, 0)
    scene = spec.load()
    config = PlanConfig()
    disc = discretize(scene, config.discretize)
    sample = size_guard.time_sample(spec, disc.world_from_cam, config.imaging, n=4)
    assert sample.poses == 3 and sample.render_seconds > 0 and sample.feature_seconds > 0
    assert sample.features_per_pose > 0 and sample.setup_seconds > 0
    stages = size_guard.estimate_plan(sample, 1000, 2, config.similarity, 5)
    assert stages["total"] == pytest.approx(stages["observe"] + stages["similarity"] + stages["outputs"])
    assert stages["observe"] > 1000 * sample.render_seconds  # renders do not get faster with workers
    caplog.set_level(logging.INFO, logger="markerplace")
    size_guard.measured_size_check(scene, spec, config, 5)(disc)
    assert any("run size:" in r.getMessage() and "in all" in r.getMessage() for r in caplog.records)
    slow = size_guard.PoseSample(1000.0, 1000.0, 1.0, 50.0, 4)  # 2000 s per pose
    monkeypatch.setattr(size_guard, "time_sample", lambda *a, **k: slow)
    with pytest.raises(UserError, match="longer than 12 h"):
        size_guard.measured_size_check(scene, spec, config, 5)(disc)
    size_guard.measured_size_check(scene, spec, config, 5, force=True)(disc)  # --force: a warning only


def test_measured_estimate_with_location_views_charges_half_a_face(monkeypatch):
    """With --observe-views location-*, the sample renders faces and charges each pose half of
    one; the features per pose stay those of a pose (the look-alike search's input)."""
    from dataclasses import replace

    from markerplace.pipelines import size_guard
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import discretize
    from markerplace.scene.spec import SceneSpec

    spec = SceneSpec("tiny", None, None, 0)
    config = PlanConfig()
    disc = discretize(spec.load(), config.discretize)
    shapes = []
    real = size_guard.ImagingEngine.render
    monkeypatch.setattr(size_guard.ImagingEngine, "render",
                        lambda self, *a, **k: shapes.append(real(self, *a, **k).rgb.shape[:2]) or real(self, *a, **k))
    pose = size_guard.time_sample(spec, disc.world_from_cam, replace(config.imaging, observe_views="pose"), n=6)
    assert set(shapes) == {(450, 600)}
    for views in ("location-renders", "location-features"):
        shapes.clear()
        s = size_guard.time_sample(spec, disc.world_from_cam, replace(config.imaging, observe_views=views), n=6)
        assert len(set(shapes)) == 1 and shapes[0][0] > 450 and shapes[0][1] > 600  # faces
        assert s.render_seconds > 0 and s.feature_seconds > 0
        assert 0.5 * pose.features_per_pose < s.features_per_pose < 1.5 * pose.features_per_pose


def test_size_guard_counts_query_conditions_and_the_ceiling():
    """Every query condition renders and localizes the test images again, and the ceiling runs
    every candidate alone on the clean ones: the estimate grows with both (a corridor run with
    six conditions and the ceiling took 6 h where a guess that left them out said 2 h 15 min)."""
    from dataclasses import replace

    from markerplace.plan.config import PlanConfig
    from markerplace.scene import load_scene
    from markerplace.testbed import config as tb

    scene, plan = load_scene("tiny"), PlanConfig()
    clean = tb.EvaluateConfig(test=tb.TestSetConfig(tests=100, sets=("weighted",)),
                              study=tb.StudyConfig(methods=("none", "omp", "random"), runs=2, ks=(5, 10)))
    base = size_guard.estimate_run(scene, plan, clean, poses=400)
    assert base.queries == 100 * (1 + 2 + 2 * 2)  # none, omp at two k, random at two k x 2 runs
    three = replace(clean, test=replace(clean.test, conditions=("clean", "blur", "noise")))
    est = size_guard.estimate_run(scene, plan, three, poses=400)
    assert est.queries == 3 * base.queries
    renders = 2 * 100 * size_guard.SECONDS_PER_POSE_CORE / est.workers  # the two conditions' test images
    assert est.seconds == pytest.approx(base.seconds + renders + 2 * base.queries * size_guard.SECONDS_PER_QUERY_CORE / est.workers)
    ceiling = replace(clean, diagnostics=tb.DiagnosticsConfig(ceiling=True))
    first_guess = size_guard.estimate_run(scene, plan, ceiling, poses=400)
    assert first_guess.queries == base.queries + 2 * 100  # its picks at each k, candidates not known yet
    measured = size_guard.estimate_run(scene, plan, ceiling, poses=400, candidates=30)
    assert measured.queries == first_guess.queries + 30 * 100 and measured.seconds > first_guess.seconds
