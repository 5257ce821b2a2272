"""Hostile meshes end to end: every file of the corpus (tests/helpers/hostile_meshes.py) ends in a
sensible plan or a one-line ``markerplace: error:`` with exit code 2, never a traceback, and a
model with several buildings or storeys is planned whole."""

from __future__ import annotations

import json

import pytest

from helpers.hostile_meshes import CORPUS
from markerplace.cli.main import main

FAST = ["-k", "2", "--yaws", "2", "--grid-spacing", "1.0", "--workers", "1"]


@pytest.mark.parametrize("name", sorted(CORPUS))
def test_hostile_mesh(name, tmp_path, capsys):
    writer, expect = CORPUS[name]
    path = writer(tmp_path)
    out = tmp_path / "plan"
    code = main(["--quiet", "plan", str(path), "--out", str(out), *FAST])
    err = capsys.readouterr().err
    assert code in (0, 2), err
    assert "Traceback" not in err
    if code == 2:
        lines = [ln for ln in err.strip().splitlines() if ln.startswith("markerplace: error:")]
        assert len(lines) == 1, err
        assert expect in ("error", "either"), f"{name}: {lines[0]}"
        return
    assert expect in ("plan", "either"), f"{name} planned but should have been refused"
    plan = json.loads((out / "placement.json").read_text())
    assert len(plan["markers"]) == 2
    summary = plan["summary"]
    if name == "two_storeys":
        assert len(summary["storeys"]) == 2 and summary["planned_storeys"] == [0, 1]
        assert all(s["locations"] > 5 for s in summary["discretization"]["per_storey"])
    if name == "two_disjoint_buildings":
        import numpy as np

        xy = np.load(out / "scores.npz")["locations"]
        assert (xy[:, 0] < 10).sum() > 5 and (xy[:, 0] > 35).sum() > 5


def test_corpus_is_large_enough():
    assert len(CORPUS) >= 30
    kinds = {e for _, e in CORPUS.values()}
    assert kinds >= {"plan", "error"}
