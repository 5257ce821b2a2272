"""Run folders markerplace owns (issue 35, items 1-3): foreign files survive, links are never
followed, one run per folder, caches keyed on the content they were computed from, and a full
disk or an unwritable path is one line and resumes. Every refusal is one line, exit 2."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers import FAST
from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.runtime import run_folder

FOREIGN = {"tags/company_logo.svg": "<svg>logo</svg>", "tagmaps/robot_config.yaml": "robot: 1\n",
           "observations/parts/important.txt": "keep me", "notes.txt": "my notes"}


def _plan(out, *extra) -> list[str]:
    return ["plan", "tiny", "-k", "3", "--out", str(out), *FAST, *extra]


def _one_line_error(capsys, *needles) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:"), err
    for needle in needles:
        assert needle in err[0], (needle, err[0])
    return err[0]


def _snapshot(folder: Path) -> dict:
    """Every entry below ``folder`` (links not followed): file bytes, link targets, folders."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder).as_posix()
        out[rel] = ("link", os.readlink(p)) if p.is_symlink() else ("dir",) if p.is_dir() else p.read_bytes()
    return out


def _picks(folder: Path) -> list[int]:
    return [m["candidate_index"] for m in json.loads((folder / "placement.json").read_text())["markers"]]


def _write_foreign(folder: Path) -> None:
    for rel, text in FOREIGN.items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_text(text)


@pytest.fixture(scope="module")
def adopted(tmp_path_factory):
    """`plan tiny -k 3 --adopt` into someone else's non-empty folder."""
    out = tmp_path_factory.mktemp("own") / "theirs"
    _write_foreign(out)
    assert main(_plan(out, "--adopt")) == 0
    return out


@pytest.fixture
def copy_of(adopted, tmp_path):
    """A copy of the adopted plan folder (marker and manifest included) to change."""
    def make(name="run"):
        dst = tmp_path / name
        shutil.copytree(adopted, dst, symlinks=True)
        return dst
    return make


# --- item 1: a folder the tool owns -------------------------------------------------------------

def test_foreign_files_survive_an_adopted_run(adopted, copy_of):
    for rel, text in FOREIGN.items():
        assert (adopted / rel).read_text() == text, rel
    assert (adopted / run_folder.MARKER).is_file() and json.loads((adopted / run_folder.MARKER).read_text())["adopted"]
    assert not list((adopted / "observations" / "parts").glob("part_*"))  # its own parts are gone, not the folder
    assert len(list((adopted / "tags").glob("0*_tag*.svg"))) == 3
    run = copy_of()
    assert main(["plan", "tiny", "-k", "2", "--out", str(run), *FAST]) == 0  # a smaller plan into it
    assert sorted(p.name for p in (run / "tags").iterdir()) == ["01_tag0.svg", "02_tag1.svg", "company_logo.svg"]
    for rel, text in FOREIGN.items():
        assert (run / rel).read_text() == text, rel


@pytest.mark.parametrize("command", ["plan", "evaluate", "study", "check"])
def test_non_empty_foreign_folder_is_refused_without_adopt(command, adopted, tmp_path, capsys):
    theirs = tmp_path / "theirs"
    _write_foreign(theirs)
    before = _snapshot(theirs)
    argv = {"plan": _plan(theirs),
            "evaluate": ["evaluate", "tiny", "--out", str(theirs), "--k", "1", *FAST],
            "study": ["study", "tiny", "--out", str(theirs), "--k", "1", *FAST],
            "check": ["check", str(adopted), "--installed", str(adopted / "placement.json"), "--out", str(theirs)]}
    assert main(argv[command]) == 2
    _one_line_error(capsys, str(theirs), "not empty", "--adopt")
    assert _snapshot(theirs) == before


def test_check_keeps_foreign_tag_maps_and_runs_from_inside_the_plan(copy_of, tmp_path, monkeypatch, capsys):
    theirs = tmp_path / "theirs"
    (theirs / "tagmaps").mkdir(parents=True)
    (theirs / "tagmaps" / "robot.yaml").write_text("robot: 1\n")
    run = copy_of()
    assert main(["check", str(run), "--installed", str(run / "placement.json"), "--out", str(theirs), "--adopt",
                 "--quiet"]) == 0
    assert (theirs / "tagmaps" / "robot.yaml").read_text() == "robot: 1\n"
    assert (theirs / "check.json").is_file() and (theirs / "tagmaps" / "wpilib_field_layout.json").is_file()
    monkeypatch.chdir(run)  # the working directory is used when it is already a run folder
    assert main(["check", ".", "--installed", "placement.json", "--quiet"]) == 0
    assert (run / "check" / "check.json").is_file()


def test_no_write_onto_or_deletion_of_a_file_markerplace_did_not_write(tmp_path):
    from markerplace.runtime.atomic_io import write_json

    folder = tmp_path / "adopted"
    folder.mkdir()
    (folder / "report.html").write_text("their report")
    try:
        run_folder.open_run_folder(folder, "test", adopt=True)
        with pytest.raises(UserError, match="report.html was not written by markerplace"):
            write_json(folder / "report.html", {"x": 1})
        assert run_folder.remove(folder / "report.html") is False
        write_json(folder / "mine.json", {"x": 1})
        assert run_folder.remove(folder / "mine.json") is True
    finally:
        run_folder.close_all()
    assert (folder / "report.html").read_text() == "their report"
    assert sorted(p.name for p in folder.iterdir()) == sorted([run_folder.MANIFEST, run_folder.MARKER, "report.html"])


@pytest.mark.parametrize("where", ["root", "home", "cwd", "above cwd"])
def test_root_home_and_working_directory_are_never_used(where, tmp_path, capsys, monkeypatch):
    home = tmp_path / "home"
    work = home / "project"
    work.mkdir(parents=True)
    (work / "src.py").write_text("x")
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    out = {"root": "/", "home": str(home), "cwd": ".", "above cwd": ".."}[where]
    watched = Path("/") if where == "root" else home
    before = sorted(os.listdir(watched)) if where == "root" else _snapshot(home)
    assert main(_plan(out, "--adopt")) == 2
    _one_line_error(capsys, "markerplace writes a run into a folder of its own")
    assert (sorted(os.listdir(watched)) if where == "root" else _snapshot(home)) == before


def test_dangling_link_as_out_is_one_line(tmp_path, capsys):
    link = tmp_path / "out"
    link.symlink_to(tmp_path / "nowhere")
    assert main(_plan(link)) == 2
    _one_line_error(capsys, "symbolic link", "does not exist")
    assert not (tmp_path / "nowhere").exists()


def test_linked_tags_and_tagmaps_lead_to_no_write_or_deletion_outside(copy_of, tmp_path, capsys):
    run = copy_of()
    victims = {"victim_tags": {"drawing.svg": "art", "01_tag0.svg": "their own tag sheet"},
               "victim_maps": {"precious.txt": "data", "wpilib_field_layout.json": "{}"}}
    for name, files in victims.items():
        (tmp_path / name).mkdir()
        for f, text in files.items():
            (tmp_path / name / f).write_text(text)
    shutil.rmtree(run / "tags")
    shutil.rmtree(run / "tagmaps")
    (run / "tags").symlink_to(tmp_path / "victim_tags")
    (run / "tagmaps").symlink_to(tmp_path / "victim_maps")
    before = {name: _snapshot(tmp_path / name) for name in victims}
    assert main(_plan(run)) == 2
    _one_line_error(capsys, "is a symbolic link", "never writes or deletes through links")
    for name in ("tags", "tagmaps"):  # a link made while the run holds the folder: refused at the write
        (run / name).unlink()
        (run / name).mkdir()
    try:
        run_folder.open_run_folder(run, "test")
        (run / "tags").rmdir()
        (run / "tags").symlink_to(tmp_path / "victim_tags")
        from markerplace.report.printable import write_tag_sheets

        rec = dict(order=1, tag_id=7, family="tag36h11", size=0.4, position=[1.0, 2.0, 1.5], yaw_deg=0.0)
        with pytest.raises(UserError, match="symbolic link"):
            write_tag_sheets(run / "tags", [rec])
        with pytest.raises(UserError, match="symbolic link"):
            run_folder.remove_stale(run / "tags", [], "*.svg")
        with pytest.raises(UserError, match="symbolic link"):
            run_folder.remove(run / "tags" / "01_tag0.svg")  # in the manifest, but behind a link now
    finally:
        run_folder.close_all()
    assert {name: _snapshot(tmp_path / name) for name in victims} == before


def test_refused_or_failed_run_leaves_no_empty_folder(tmp_path, capsys):
    assert main(_plan(tmp_path / "new" / "run", "--start", "0.0,0.0")) == 2  # refused by discretize
    _one_line_error(capsys, "--start")
    assert not (tmp_path / "new").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(_plan(empty, "--start", "0.0,0.0")) == 2
    assert list(empty.iterdir()) == []


# --- item 2: one run per folder ------------------------------------------------------------------

def _cli(*argv: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "markerplace.cli", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def test_two_concurrent_plans_give_a_correct_plan_and_a_clear_refusal(adopted, tmp_path):
    out = tmp_path / "same"
    runs = [_cli(*_plan(out)) for _ in range(2)]
    results = [(p.wait(timeout=300), *p.communicate()) for p in runs]
    assert any(code == 0 for code, _, _ in results), results
    for code, _, err in results:
        assert "Traceback" not in err, err
        if code != 0:
            lines = err.strip().splitlines()
            assert code == 2 and len(lines) == 1 and "in use by another markerplace run (pid " in lines[0], err
    assert _picks(out) == _picks(adopted)  # the plan made alone
    alone, both = np.load(adopted / "scores.npz"), np.load(out / "scores.npz")
    assert np.array_equal(alone["score_after"], both["score_after"])
    assert not (out / run_folder.LOCK).exists()


def test_live_lock_is_named_and_stale_lock_taken_over(tmp_path, caplog):
    folder = tmp_path / "run"
    try:
        run_folder.open_run_folder(folder, "test")
        other = _cli(*_plan(folder))
        code, _, err = other.wait(timeout=120), *other.communicate()
        assert code == 2 and err.strip().splitlines() == [err.strip()], err
        assert f"pid {os.getpid()} on " in err and "in use by another markerplace run" in err
    finally:
        run_folder.close_all()
    assert not folder.exists()  # it made the folder and wrote nothing into it
    folder.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    import socket

    (folder / run_folder.LOCK).write_text(json.dumps({"pid": dead.pid, "host": socket.gethostname(),
                                                      "command": "plan", "started": "earlier"}))
    try:
        with caplog.at_level("WARNING", logger="markerplace"):
            run_folder.open_run_folder(folder, "test")
        assert json.loads((folder / run_folder.LOCK).read_text())["pid"] == os.getpid()
    finally:
        run_folder.close_all()
    assert any(f"stale lock of markerplace run pid {dead.pid}" in r.getMessage() for r in caplog.records)


# --- item 3: cache keys from content -------------------------------------------------------------

def test_similarity_is_recomputed_when_the_observations_change(copy_of):
    from markerplace.imaging.features import FeatureSet
    from markerplace.plan.similarity.config import SimilarityConfig
    from markerplace.plan.similarity.stage import count_similar
    from markerplace.runtime import cache

    run = copy_of()
    obs = run / "observations"
    old = np.load(run / "similarity.npz")["n_similar"]
    meta = json.loads((run / "observations.meta.json").read_text())
    desc = np.load(obs / "descriptors.npy")
    desc[:] = desc[0]  # a repaired upstream stage with other content: every point looks alike
    np.save(obs / "descriptors.npy", desc)
    cache.mark_done(obs, meta["key"])  # ... and a valid meta file
    sim_key = json.loads((run / "similarity.npz.meta.json").read_text())["key"]
    assert main(_plan(run)) == 0
    assert np.array_equal(np.load(obs / "descriptors.npy"), desc)  # observations reused as they are
    assert json.loads((run / "similarity.npz.meta.json").read_text())["key"] != sim_key
    new = np.load(run / "similarity.npz")["n_similar"]
    feats = FeatureSet.load(obs)
    assert np.array_equal(new, count_similar(feats.descriptors, feats.points_world, SimilarityConfig()))
    assert not np.array_equal(new, old)


def test_a_stage_with_upstream_artifacts_reruns_when_they_change(tmp_path):
    from markerplace.runtime import cache
    from markerplace.runtime.atomic_io import write_json
    from markerplace.runtime.stages import cached

    upstream, out = tmp_path / "map.json", tmp_path / "model.json"
    calls = []

    def fit():
        if not upstream.exists():  # the stage makes its upstream artifact itself
            write_json(upstream, {"map": 1})
            cache.mark_done(upstream, "map-key")
        calls.append(json.loads(upstream.read_text()))
        return calls[-1]

    def run():
        return cached("fit", out, "model-key", fit, lambda r, p: write_json(p, r), lambda p: json.loads(p.read_text()),
                      upstream=[upstream])

    assert run() == {"map": 1} and run() == {"map": 1} and len(calls) == 1  # reused while the map is the same
    write_json(upstream, {"map": 2})  # the upstream stage recomputed with other bytes
    cache.mark_done(upstream, "map-key")
    assert run() == {"map": 2} and len(calls) == 2
    upstream.unlink()  # an upstream cache deleted: the model still stands
    (tmp_path / "map.json.meta.json").unlink()
    assert run() == {"map": 2} and len(calls) == 2


# --- full disk, unwritable paths ------------------------------------------------------------------

@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EACCES, errno.EROFS])
def test_failed_write_is_one_line_and_a_rerun_resumes(code, adopted, copy_of, capsys, monkeypatch):
    run = copy_of()
    for name in ("similarity.npz", "similarity.npz.meta.json", "scores.npz"):
        (run / name).unlink()  # the similarity stage runs again and writes first
    real = np.savez_compressed

    def half_then_fail(fh, **arrays):
        fh.write(b"PK\x03\x04 half a file")
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(np, "savez_compressed", half_then_fail)
    assert main(_plan(run)) == 2
    _one_line_error(capsys, "cannot write", "similarity.npz", os.strerror(code))
    assert not [p.name for p in run.iterdir() if p.name.startswith(".similarity")]  # no temporary file left
    assert not (run / "similarity.npz").exists()
    monkeypatch.setattr(np, "savez_compressed", real)
    assert main(_plan(run)) == 0
    assert _picks(run) == _picks(adopted)
    assert np.array_equal(np.load(run / "similarity.npz")["n_similar"], np.load(adopted / "similarity.npz")["n_similar"])
