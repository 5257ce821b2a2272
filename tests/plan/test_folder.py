"""A plan folder read back by ``export``, ``check`` and ``evaluate --plan`` (:mod:`markerplace.plan.folder`,
issue 50 item 6): its files checked against each other and for numbers that are not finite, the
folder locked (shared) while it is read, and ``check --out PLAN_DIR`` refused. Each refusal is one
line, exit code 2, before anything is written."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from helpers import FAST, SRC
from markerplace.cli.main import main
from markerplace.runtime import run_folder
from markerplace.runtime.run_lock import RunLock

ENV = {**os.environ, "PYTHONPATH": str(SRC) + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH")
                                               else "")}


@pytest.fixture(scope="module")
def plan(run_plan):
    return run_plan(2, folder="readers")


@pytest.fixture
def copy(plan, tmp_path):
    dst = tmp_path / "plan"
    shutil.copytree(plan, dst)
    return dst


def _reader(command: str, plan, tmp_path) -> list[str]:
    return ["--quiet", *{"export": ["export", str(plan), "--gltf", str(tmp_path / "m.glb")],
                         "check": ["check", str(plan), "--installed", str(plan / "placement.json"), "--out",
                                   str(tmp_path / "c")],
                         "evaluate --plan": ["evaluate", "--plan", str(plan), "--out", str(tmp_path / "e")]}[command]]


def _one_line(capsys, needle: str) -> str:
    err = capsys.readouterr().err
    assert err.startswith("markerplace: error: ") and err.count("\n") == 1, err
    assert needle in err, err
    return err


def _edit(path, change) -> None:
    doc = json.loads(path.read_text())
    change(doc)
    path.write_text(json.dumps(doc))  # Python writes NaN as the bare token NaN


READERS = ["export", "check", "evaluate --plan"]


@pytest.mark.parametrize("command", READERS)
def test_a_nan_position_in_placement_json_is_refused_by_every_reader(command, copy, tmp_path, capsys):
    _edit(copy / "placement.json", lambda d: d["markers"][0]["position"].__setitem__(0, float("nan")))
    assert main(_reader(command, copy, tmp_path)) == 2
    _one_line(capsys, "holds NaN, a NaN or infinite number")
    assert not (tmp_path / "m.glb").exists() and not (tmp_path / "c").exists() and not (tmp_path / "e").exists()


@pytest.mark.parametrize("command", READERS)
def test_a_scene_edited_in_config_json_is_refused_by_every_reader(command, copy, tmp_path, capsys):
    _edit(copy / "config.json", lambda d: d.__setitem__("scene", "room"))
    assert main(_reader(command, copy, tmp_path)) == 2
    _one_line(capsys, "placement.json does not match the scene of its config.json (placement.json: tag 0 at")
    assert not (tmp_path / "m.glb").exists()


def test_a_tag_moved_along_its_wall_in_placement_json_is_refused_by_export(copy, tmp_path, capsys):
    def move(doc):  # still on the wall, 10 cm along it: on no candidate spot of the plan's (cached) discretization
        m = doc["markers"][0]
        along = [-m["normal"][1], m["normal"][0], 0.0]
        m["position"] = [p + 0.1 * a for p, a in zip(m["position"], along)]
        for i in range(3):
            m["world_from_marker"][i][3] += 0.1 * along[i]

    _edit(copy / "placement.json", move)
    assert main(_reader("export", copy, tmp_path)) == 2
    _one_line(capsys, "is on none of their candidate spots")


@pytest.mark.parametrize("command", READERS)
def test_a_plan_folder_being_written_is_not_read(command, copy, tmp_path, capsys):
    writer = RunLock(copy / run_folder.LOCK, "--out")  # a `plan` running into it (another process's lock)
    writer.acquire("plan tiny --out plan")
    try:
        assert main(_reader(command, copy, tmp_path)) == 2
    finally:
        writer.release()
    _one_line(capsys, "is being written by another markerplace run (pid")


def test_a_plan_cannot_start_writing_a_folder_being_read(copy, tmp_path, capsys):
    from markerplace.plan.folder import read_plan_folder

    before = sorted(p.name for p in copy.iterdir())
    read_plan_folder(copy)  # export, evaluate --plan: a shared lock until the command ends
    try:
        res = subprocess.run([sys.executable, "-m", "markerplace.cli", "plan", "tiny", "-k", "2", "--out", str(copy),
                              *FAST], capture_output=True, text=True, env=ENV, timeout=120)
    finally:
        run_folder.close_all()
    assert res.returncode == 2 and res.stderr.count("\n") == 1, res.stderr
    assert "in use by another markerplace run (one reading it" in res.stderr
    assert sorted(p.name for p in copy.iterdir()) == before  # the reader's empty lock file is gone again


def test_export_leaves_the_plan_folder_as_it_was(copy, tmp_path):
    before = {p.name: p.stat().st_mtime_ns for p in copy.iterdir()}
    assert main(_reader("export", copy, tmp_path)) == 0
    assert {p.name: p.stat().st_mtime_ns for p in copy.iterdir()} == before


def test_check_out_the_plan_folder_itself_is_refused(copy, capsys):
    tagmaps = {p.name: p.read_bytes() for p in (copy / "tagmaps").iterdir()}
    assert main(["check", str(copy), "--installed", str(copy / "placement.json"), "--out", str(copy), "--quiet"]) == 2
    _one_line(capsys, "is the plan folder itself: check writes its own tagmaps/")
    assert {p.name: p.read_bytes() for p in (copy / "tagmaps").iterdir()} == tagmaps


def test_check_through_a_link_to_the_plan_reads_then_writes_it_without_locking_itself_out(copy, tmp_path):
    link = tmp_path / "link"
    link.symlink_to(copy)  # read_plan_folder's shared lock and the run folder's exclusive one: the same file
    assert main(_reader("check", link, tmp_path)) == 0
    assert not (copy / run_folder.LOCK).exists()
