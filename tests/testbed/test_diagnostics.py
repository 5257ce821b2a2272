"""The oracle ceiling, the score's calibration on map images (leave one location out) and the
expected-recall method that uses it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import REPO
from markerplace.cli.main import main
from markerplace.localization.database import MapDatabase
from markerplace.localization.localizer import SiftPnP
from markerplace.localization.vlad import VladCodebook
from markerplace.markers import Marker
from markerplace.simulation.success_fit import placement_candidates
from markerplace.testbed.ceiling import oracle_order

FAST = ["--grid-spacing", "1.0", "--yaws", "4", "--workers", "2", "--quiet"]


def _db(M: int = 12, seed: int = 0) -> MapDatabase:
    rng = np.random.default_rng(seed)
    codebook = VladCodebook(rng.standard_normal((4, 128)).astype(np.float32))
    images = []
    for i in range(M):
        T = np.eye(4)
        T[:3, 3] = [i, 0, 1.5]
        d = np.abs(rng.standard_normal((20, 128))).astype(np.float32)
        images.append((T, rng.uniform(0, 600, (20, 2)), d, rng.uniform(0, 5, (20, 3)), []))
    return MapDatabase.build(images, [], codebook)


def test_retrieval_leaves_out_excluded_images_and_keeps_the_order_of_the_rest():
    from markerplace.simulation.placement_localization import Retrieval

    db = _db()
    loc = SiftPnP(db, np.eye(3), num_candidates=5)
    q = db.vlad[3] + 0.1 * db.vlad[7]
    q /= np.linalg.norm(q)
    full = loc.retrieve(q, [])
    assert full[0] == 3 and len(full) == 5
    cut = loc.retrieve(q, [], exclude=[3, full[1]])
    assert 3 not in cut and full[1] not in cut and len(cut) == 5
    order = [i for i in np.argsort(-(db.vlad @ q), kind="stable") if i not in (3, full[1])]
    assert cut == [int(i) for i in order[:5]]
    # the in-process replay that decides which images a placement cannot change agrees
    replay = Retrieval.__new__(Retrieval)
    replay.n = 5
    assert list(replay.candidates(db.vlad, q, (3, full[1]))) == cut
    assert list(replay.candidates(db.vlad, q)) == full


def test_oracle_order_is_greedy_maximum_coverage():
    base = np.array([1, 0, 0, 0, 0, 0], bool)
    hits = np.array([[1, 1, 0, 0, 0, 0],     # c0 adds 1 (image 0 already localizes)
                     [0, 1, 1, 1, 0, 0],     # c1 adds 3
                     [0, 0, 0, 1, 1, 0],     # c2 adds 2, then 1 after c1
                     [0, 1, 1, 0, 0, 0]], bool)  # c3 adds 2, then 0 after c1
    order, gains = oracle_order(base, hits, 4)
    # c1 (+3), then c2 (+1: image 4); c0 and c3 add nothing more: ties to the smaller index
    assert order == [1, 2, 0, 3] and gains == [3, 1, 0, 0]
    assert oracle_order(base, hits, 2) == ([1, 2], [3, 1])  # nested in k


def test_placement_candidates_match_exactly_or_not_at_all():
    T = np.stack([np.eye(4) for _ in range(3)])
    T[:, 0, 3] = [0.0, 1.0, 2.0]
    assert placement_candidates([Marker(0, 0.4, T[2]), Marker(1, 0.4, T[0])], T, 0.4).tolist() == [2, 0]
    rounded = np.round(T[1], 6)  # as placement.json stores it
    rounded[0, 3] += 4e-7
    assert placement_candidates([Marker(0, 0.4, rounded)], T, 0.4).tolist() == [1]
    moved = T[1].copy()
    moved[1, 3] += 0.01
    assert placement_candidates([Marker(0, 0.4, moved)], T, 0.4) is None
    assert placement_candidates([Marker(0, 0.5, T[1])], T, 0.4) is None  # printed at another size


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory):
    out = tmp_path_factory.mktemp("diag") / "eval"
    code = main(["evaluate", "tiny", "--out", str(out), "--tests", "12", "--k", "2,3", "--runs", "1",
                 "--methods", "none,omp,random,expected-recall", "--ceiling", "--calibration", *FAST])
    assert code == 0
    return out


def test_ceiling_rows_and_shares(evaluation):
    import csv

    rows = list(csv.DictReader((evaluation / "recall.csv").open()))
    main_rows = [r for r in rows if r["threshold"] == "5cm/5deg"]
    methods = {r["method"] for r in main_rows}
    assert methods == {"none", "omp", "random", "expected-recall", "ceiling"}  # the single-tag runs stay out
    for ts in ("weighted", "uniform"):
        ceil = {int(r["k"]): float(r["recall"]) for r in main_rows if r["method"] == "ceiling" and r["test_set"] == ts}
        assert sorted(ceil) == [2, 3]
    md = (evaluation / "ceiling.md").read_text()
    for ts in ("weighted", "uniform"):
        assert f"## {ts} test set (12 images" in md
    assert md.count("| ceiling (evaluated) |") == 2 and md.count("| share of omp |") == 2
    for label in ("in sample", "held out"):  # the ceiling's selection on the test images, per test set
        rows_ = [line for line in md.splitlines() if line.startswith(f"| ceiling over random subsets, {label} |")]
        assert len(rows_) == 2 and all(np.isfinite(float(v)) for line in rows_ for v in line.strip("|").split("|")[1:])
    est = [line for line in md.splitlines() if line.startswith("| ceiling (single-tag estimate) |")]
    none = {r["test_set"]: float(r["recall"]) for r in main_rows if r["method"] == "none"}
    for line, ts in zip(est, ("weighted", "uniform")):
        values = [float(v) for v in line.strip("|").split("|")[1:]]
        # no markers plus what the picks fix alone: never below no markers, growing with k
        assert values[0] >= 100 * none[ts] - 1e-9 and values[1] >= values[0]


def test_calibration_outputs(evaluation):
    md = (evaluation / "calibration.md").read_text()
    assert "| paper |" in md and "| corners |" in md and "## corners: calibration" in md
    z = np.load(evaluation / "map_outcomes.npz")
    N = 32  # tiny at 1 m x 4 yaws
    for model in ("paper", "corners"):
        s, y, tagged = z[f"{model}_score"], z[f"{model}_success"], z[f"{model}_tagged"]
        assert len(s) == len(y) == len(tagged) and int((~tagged).sum()) == N and tagged.any()
        assert y.dtype == bool and 0 < y.mean() <= 1
    assert (evaluation / "calibration.png").stat().st_size > 0
    # the same tag sets under both models: the same samples, other scores
    assert np.array_equal(z["paper_success"], z["corners_success"])
    assert not np.array_equal(z["paper_score"][z["paper_tagged"]], z["corners_score"][z["corners_tagged"]])


def test_expected_recall_plan_is_calibrated_on_map_images_and_cached(tmp_path):
    out = tmp_path / "plan"
    args = ["plan", "tiny", "-k", "3", "--method", "expected-recall", "--out", str(out), *FAST]
    assert main(args) == 0
    model_file = out / "success_model_expected-recall.json"
    model = json.loads(model_file.read_text())
    assert model["slope"] >= 0 and model["n"] > 32 and 0 <= model["successes"] <= model["n"]
    assert (out / "calibration" / "map_base").is_dir()
    placed = json.loads((out / "placement.json").read_text())["markers"]
    assert len({tuple(m["position"]) for m in placed}) == 3
    stamp = model_file.stat().st_mtime_ns
    assert main(args) == 0  # the calibration stage is reused
    assert model_file.stat().st_mtime_ns == stamp
    doc = json.loads((out / "placement.json").read_text())
    assert doc["markers"] == placed
    pr = doc["predicted_recall"]
    assert pr["available"] and pr["k"] == [0, 1, 2, 3] and pr["target"] is None
    assert pr["recall"] == sorted(pr["recall"]) and pr["upper_bound"]["recall"] >= pr["recall"][-1]
    # --target-recall with OMP on the same folder: the fit is reused (where the greedy stops is no part of it)
    assert main(["plan", "tiny", "--target-recall", "1.0", "--out", str(out), *FAST]) == 0
    assert model_file.stat().st_mtime_ns == stamp
    doc = json.loads((out / "placement.json").read_text())
    t = doc["predicted_recall"]["target"]
    assert t["target"] == 1.0 and not t["reached"] and t["limit"] == "with the candidates"
    assert len(doc["markers"]) == t["tags"] == t["best_tags"] and t["most_tags"] == doc["summary"]["num_candidates"]
    assert "How many tags" in (out / "report.html").read_text() and "not reachable" in (out / "report.html").read_text()


def test_expected_recall_offgrid_calibration_fits_on_test_like_renders(tmp_path, monkeypatch):
    from dataclasses import replace

    from markerplace.plan.place.methods import ExpectedRecall

    monkeypatch.setattr(ExpectedRecall, "default_conf", replace(ExpectedRecall.default_conf, calibration_images=40))
    out = tmp_path / "plan"
    args = ["plan", "tiny", "-k", "3", "--method", "expected-recall", "--calibration-poses", "offgrid",
            "--out", str(out), *FAST]
    assert main(args) == 0
    model = json.loads((out / "success_model_expected-recall.json").read_text())
    # the 40 off-grid images without tags, plus those whose source pose a calibration set changes
    assert 40 < model["n"] <= 40 * 4 and model["slope"] >= 0
    assert (out / "calibration" / "offgrid_base").is_dir()
    assert len(json.loads((out / "placement.json").read_text())["markers"]) == 3
    _check_offgrid_success_benchmark(out, 40)
    map_out = tmp_path / "map"
    assert main([*args[:-len(FAST) - 4], "--calibration-poses", "map", "--out", str(map_out), *FAST]) == 0
    assert json.loads((map_out / "success_model_expected-recall.json").read_text())["n"] != model["n"]


def _check_offgrid_success_benchmark(plan_dir, images: int) -> None:
    """benchmarks/offgrid_success.py rebuilds the plan's off-grid poses: with the plan's seed its
    success rate is the plan's own; with another seed the cached predictions belong to other poses."""
    import contextlib
    import importlib.util
    import io

    path = REPO / "benchmarks" / "offgrid_success.py"
    spec = importlib.util.spec_from_file_location("offgrid_success", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)

    def run(*extra) -> dict[str, str]:
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            bench.main([str(plan_dir), "--images", str(images), *extra])
        return dict(line.split(": ", 1) for line in buf.getvalue().splitlines())

    own = run()
    assert int(own["offgrid_images"]) == images
    per_storey = [int(v) for k, v in own.items() if k.startswith("offgrid_storey") and k.endswith("_images")]
    assert sum(per_storey) == images
    rate = float(own["offgrid_no_marker_success"])
    assert rate >= 0.5  # the tiny scene's test-like renders mostly localize
    for k, v in own.items():
        if "failure_quartile" in k and v != "nan":
            assert 0.0 <= float(v) <= 1.0
    wrong = float(run("--seed", "1")["offgrid_no_marker_success"])
    assert wrong < rate - 0.3  # predictions scored against poses they were not made for


def test_calibration_poses_without_expected_recall_warns(tmp_path, caplog):
    import logging

    with caplog.at_level(logging.WARNING):
        assert main(["plan", "tiny", "-k", "2", "--calibration-poses", "offgrid", "--out", str(tmp_path / "p"), *FAST]) == 0
    assert any("--calibration-poses offgrid has no effect with --method omp" in r.getMessage() for r in caplog.records)
    assert not (tmp_path / "p" / "success_model_expected-recall.json").exists()
    doc = json.loads((tmp_path / "p" / "placement.json").read_text())  # no model: the curve says how to get it
    assert doc["predicted_recall"]["available"] is False and "--recall-curve" in doc["predicted_recall"]["how"]
    sb = doc["score_bound"]
    assert sb["k"] == 2 and sb["mean_score_upper_bound"] >= sb["mean_score_plan"] >= sb["mean_score_existing"]


def test_unknown_calibration_poses_is_a_one_line_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["plan", "tiny", "--method", "expected-recall", "--calibration-poses", "test", "--out", str(tmp_path)])
    assert e.value.code == 2
    assert "--calibration-poses" in capsys.readouterr().err


def _ceiling_holdout():
    import importlib.util

    path = REPO / "benchmarks" / "ceiling_holdout.py"
    spec = importlib.util.spec_from_file_location("ceiling_holdout", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench


def test_held_out_ceiling_tells_selection_on_the_test_images_from_a_real_gain():
    from markerplace.testbed.ceiling import held_out_gains

    rng = np.random.default_rng(0)
    Q, C = 400, 120
    base = np.zeros(Q, bool)
    noise = rng.random((C, Q)) < 0.03  # every candidate fixes a few images at random: nothing generalizes
    i, h, r = held_out_gains(base, noise, 5, np.random.default_rng(1), 0.5, 20, 50)
    assert i - r > 0.04          # picked on the scored images: looks well above random
    assert abs(h - r) < 0.01     # picked on the other images: no better than random
    real = noise.copy()
    real[7] = True               # one candidate fixes every image
    i, h, r = held_out_gains(base, real, 1, np.random.default_rng(1), 0.5, 20, 50)
    assert i == h == 1.0 and r < 0.1


def test_ceiling_holdout_reads_the_evaluations_single_tag_runs(evaluation):
    import contextlib
    import io

    bench = _ceiling_holdout()
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        bench.main([str(evaluation), "--test-set", "weighted", "--k", "2,3", "--splits", "4", "--draws", "5"])
    got = dict(line.split(": ", 1) for line in buf.getvalue().splitlines())
    assert int(got["test_images"]) == 12
    assert int(got["fixable_by_one_candidate"]) <= int(got["failing_without_markers"])
    md = (evaluation / "ceiling.md").read_text().split("## uniform")[0]
    est = next(line for line in md.splitlines() if line.startswith("| ceiling (single-tag estimate) |"))
    # the same greedy picks from the same cached predictions as the evaluation's ceiling
    assert [float(v) for v in est.strip("|").split("|")[1:]] == \
        [float(got["k2_all_images_ceiling_estimate"]), float(got["k3_all_images_ceiling_estimate"])]


def test_ceiling_holdout_refuses_a_run_whose_last_single_tag_runs_are_missing(evaluation, tmp_path):
    """An interrupted `--ceiling` run holds the single-tag runs of the first candidates only: the
    benchmark must refuse it, not report on fewer candidates."""
    import json
    import shutil

    import pytest

    run = tmp_path / "run"
    (run / "plan").mkdir(parents=True)
    shutil.copy(evaluation / "plan" / "discretization.npz", run / "plan")
    shutil.copy(evaluation / "test_poses_weighted.npz", run)
    shutil.copytree(evaluation / "cache" / "predictions", run / "cache" / "predictions")
    metas = {}
    for path in (run / "cache" / "predictions").glob("*.meta.json"):
        meta = json.loads(path.read_text())
        if meta.get("method") == "single" and meta.get("test_set") == "weighted":
            metas[int(meta["run"])] = path
    last = max(metas)
    metas[last].unlink()  # the last candidate's run never finished
    with pytest.raises(SystemExit, match=f"{last} of {last + 1} candidates"):
        _ceiling_holdout().cached_single_tag_hits(run, "weighted")


def test_main_threshold_falls_back_to_the_first_when_the_papers_is_not_measured():
    from markerplace.simulation.metrics import MAIN_THRESHOLD, THRESHOLDS, main_threshold

    assert main_threshold(THRESHOLDS) == MAIN_THRESHOLD
    assert main_threshold(((0.1, 10.0), (1.0, 30.0))) == (0.1, 10.0)
