"""``evaluate --plan PLAN_DIR`` (markerplace.pipelines.from_plan): the evaluation starts from a
finished plan folder, with its scene, settings and placement, and computes none of the plan's
stages again; the plan folder is only read; options that conflict with the plan are one-line
errors."""

from __future__ import annotations

import csv
import hashlib

import numpy as np
import pytest

from helpers import FAST_2_YAWS
from markerplace.cli.main import main
from markerplace.plan import observe
from markerplace.plan.discretize import stage as discretize_stage
from markerplace.plan.similarity import stage as similarity_stage

EVAL = ["--tests", "8", "--test-sets", "weighted", "--methods", "none,omp", "--runs", "1"]
RUN = ["--workers", "1", "--quiet"]


@pytest.fixture(scope="module")
def plan(run_plan):
    """``plan tiny -k 2`` on a 1 m lattice with 2 yaws."""
    return run_plan(2, options=FAST_2_YAWS)


def _snapshot(folder) -> dict:
    """relative path -> (bytes' SHA-256, mtime) of every file below ``folder``."""
    return {p.relative_to(folder).as_posix(): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _refuse(*args, **kwargs):
    raise AssertionError("evaluate --plan computed a stage the plan had cached")


def test_evaluate_from_a_plan_reuses_its_stages_and_equals_a_fresh_evaluation(plan, tmp_path, monkeypatch):
    ref = tmp_path / "ref"
    assert main(["evaluate", "tiny", "--out", str(ref), "--k", "2", *EVAL, *FAST_2_YAWS]) == 0
    before = _snapshot(plan)
    for module, name in ((discretize_stage, "discretize"), (similarity_stage, "count_similar")):
        monkeypatch.setattr(module, name, _refuse)
    real_observe = observe.observe

    def map_only(*args, **kwargs):  # the plan made no map (no --with-map): observe renders it, nothing else
        if kwargs.get("observations", True):
            _refuse()
        return real_observe(*args, **kwargs)

    monkeypatch.setattr(observe, "observe", map_only)
    out = tmp_path / "from_plan"
    assert main(["evaluate", "--plan", str(plan), "--out", str(out), *EVAL, *RUN]) == 0  # k: the plan's
    assert _snapshot(plan) == before  # the plan folder is only read
    assert list(csv.DictReader((out / "recall.csv").open())) == list(csv.DictReader((ref / "recall.csv").open()))
    a, b = np.load(out / "query_errors.npz"), np.load(ref / "query_errors.npz")
    assert a.files == b.files and a["weighted_method"].tolist() == ["none", "omp"]
    for key in a.files:
        assert np.array_equal(a[key], b[key], equal_nan=a[key].dtype.kind == "f"), key


@pytest.mark.parametrize("args, message", [
    (["--grid-spacing", "0.5"], "--grid-spacing 0.5 conflicts with the plan's 1.0"),
    (["--k", "3"], "--k 3 is more than the 2 tags"),
    (["--seed", "4"], "--seed 4 differs from the plan"),
    (["house"], "is not the scene of the plan"),
    (["tiny"], "is already the scene of the plan"),  # issue 50: its own scene too, not a full evaluation
])
def test_evaluate_from_a_plan_refuses_conflicting_options(plan, tmp_path, capsys, args, message):
    scene = args[:1] if args in (["house"], ["tiny"]) else []
    options = [] if scene else args
    assert main(["evaluate", *scene, "--plan", str(plan), "--out", str(tmp_path / "x"), *options, *RUN]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0], err
    assert not (tmp_path / "x").exists()


def test_evaluate_needs_a_scene_or_a_plan(tmp_path, capsys):
    assert main(["evaluate", "--out", str(tmp_path / "x"), *RUN]) == 2
    assert "--plan PLAN_DIR" in capsys.readouterr().err
