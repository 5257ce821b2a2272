"""An adopted folder holding a file of the user's named like one of the run's outputs is refused
before any work, and left as it was found (:mod:`markerplace.runtime.claims`, issue 50 item 5);
the declared outputs cover everything ``plan`` writes."""

from __future__ import annotations

import fnmatch
import json
import os
import time
from pathlib import Path

import pytest

from helpers import FAST
from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.pipelines.check import CHECK_OUTPUTS
from markerplace.pipelines.plan import PLAN_OUTPUTS
from markerplace.runtime import run_folder
from markerplace.runtime.claims import refuse_foreign


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else "dir") for p in folder.rglob("*")}


@pytest.mark.parametrize("name", ["placement.json", "tags.pdf", "report.html", "config.json", "scores.npz",
                                  "tags/01_tag0.svg", "tagmaps/wpilib_field_layout.json", "observations"])
def test_adopting_a_folder_with_a_foreign_output_is_refused_before_any_work(name, tmp_path, capsys):
    out = tmp_path / "theirs"
    (out / name).parent.mkdir(parents=True, exist_ok=True)
    (out / name).write_text("the user's own")  # "observations": a file where the run makes a folder
    (out / "notes.txt").write_text("mine")
    before = _snapshot(out)
    t0 = time.perf_counter()
    assert main(["plan", "tiny", "-k", "2", "--out", str(out), "--adopt", *FAST]) == 2
    seconds = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert err.startswith("markerplace: error: ") and err.count("\n") == 1 and name in err, err
    assert "checked before any work" in err and seconds < 5.0
    assert _snapshot(out) == before  # no half-written folder, no bookkeeping left


def test_check_refuses_a_foreign_output_in_its_adopted_out_before_any_work(run_plan, tmp_path, capsys):
    plan = run_plan(2, folder="claims")
    out = tmp_path / "theirs"
    out.mkdir()
    (out / "check.json").write_text("{}")
    assert main(["check", str(plan), "--installed", str(plan / "placement.json"), "--out", str(out), "--adopt",
                 "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "check.json is not written by markerplace" in err, err
    written = [json.loads(line)[1] for line in (plan / run_folder.MANIFEST).read_text().splitlines()]
    for rel in written:  # every file plan wrote is one it declares (a new output must be declared too)
        if not os.path.isdir(plan / rel):
            assert any(fnmatch.fnmatchcase(rel, p) or p.endswith("/") and rel.startswith(p) for p in PLAN_OUTPUTS), rel
    assert any(fnmatch.fnmatchcase("check_map.png", p) for p in CHECK_OUTPUTS)


@pytest.mark.parametrize("command, name", [("evaluate", "recall.csv"), ("evaluate", "plan/similarity.npz"),
                                           ("evaluate", "report.html"), ("study", "study.md"),
                                           ("study", "runs/default/tables.md"), ("study", "runs")])
def test_evaluate_and_study_refuse_a_foreign_output_in_their_adopted_out_before_any_work(command, name, tmp_path,
                                                                                        capsys):
    out = tmp_path / "theirs"
    (out / name).parent.mkdir(parents=True, exist_ok=True)
    (out / name).write_text("the user's own")  # "runs": a file where study makes a folder
    before = _snapshot(out)
    t0 = time.perf_counter()
    assert main([command, "tiny", "--out", str(out), "--adopt", "--k", "2", "--tests", "10", *FAST]) == 2
    seconds = time.perf_counter() - t0
    err = capsys.readouterr().err
    assert err.startswith("markerplace: error: ") and err.count("\n") == 1 and name in err, err
    assert "checked before any work" in err and seconds < 5.0
    assert _snapshot(out) == before


# refuse_foreign on its own: in an adopted folder, an entry named like an output that markerplace did
# not write is refused (one line); its own files, other names and folders outside a run folder pass.

@pytest.fixture
def adopted(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "placement.json").write_text("the user's own")
    (out / "observations").write_text("a file where the run makes a folder")
    (out / "notes.txt").write_text("mine")
    folder = run_folder.open_run_folder(out, "plan", adopt=True)
    yield out, folder
    run_folder.close_all()


def test_a_foreign_output_is_refused_and_other_names_pass(adopted):
    out, _ = adopted
    refuse_foreign(out, ["scores.npz", "tags/*_tag*.svg", "*.csv"])  # nothing of the user's matches
    with pytest.raises(UserError) as info:
        refuse_foreign(out, ["placement.json"])
    message = str(info.value)
    assert "placement.json is not written by markerplace" in message and "checked before any work" in message
    assert "\n" not in message
    with pytest.raises(UserError, match="observations is a file where markerplace makes a folder"):
        refuse_foreign(out, ["observations/"])


def test_files_markerplace_wrote_and_paths_outside_a_run_folder_pass(adopted, tmp_path):
    out, _ = adopted
    run_folder.prepare_write(out / "scores.npz").write_bytes(b"ours")
    refuse_foreign(out, ["scores.npz"])
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "placement.json").write_text("not a run folder")
    refuse_foreign(tmp_path / "elsewhere", ["placement.json"])
