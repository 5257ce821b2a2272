"""``evaluate --predicted``: each placement's predicted recall is the plans' prediction (same
model, same function) on the poses weighted as each test set draws them; and a small run."""

from __future__ import annotations

import csv
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from helpers.recall_problems import plan_data
from markerplace.cli.main import main
from markerplace.markers import FAMILY, Marker
from markerplace.plan.place.config import PlacementConfig
from markerplace.plan.place.predicted_recall import marker_set_curve, predicted_recall
from markerplace.plan.place.stage import place
from markerplace.simulation.marker_sets import PlacementRun
from markerplace.simulation.pose_sampling import sampling_probabilities
from markerplace.testbed.predicted_per_placement import drawn_weights, predict_recalls, test_set_weights

RECALL = PlacementConfig().recall_model  # the calibrated method whose model predicts recall

SIZE = 0.4


def _run(data, method, run, cands, shift=0.0):
    markers = []
    for i, c in enumerate(cands):
        T = data.disc.candidate_world_from_marker[c].copy()
        T[0, 3] += shift
        markers.append(Marker(i, SIZE, T, FAMILY))
    return PlacementRun(method, run, len(cands), tuple(markers))


def test_a_placements_prediction_is_the_plans_curve_at_its_k():
    data = plan_data(5, N=40, C=9, E=0)
    conf = PlacementConfig(method="omp", k=4)
    order = [int(c) for c in place(data, conf, progress=False).candidates]
    curve = predicted_recall(data, place(data, conf, progress=False), conf)["recall"]
    rng = np.random.default_rng(1)
    poses = {ts: SimpleNamespace(source_index=rng.integers(0, 40, 25)) for ts in ("weighted", "uniform")}
    runs = [PlacementRun("none", 0, 0, ()), _run(data, "omp", 0, order[:2]), _run(data, "omp", 0, order),
            _run(data, "random", 1, [0, 5]), _run(data, "shifted", 0, order[:2], shift=0.3),
            _run(data, "ceiling", 0, order[:2]), _run(data, "single", 3, [3])]
    got = predict_recalls(data, runs, poses, SIZE, RECALL)
    # none, omp k=2, omp k=4 and random, on both sets; off-candidate and ceiling runs left out
    assert {k[1:] for k in got} == {("none", 0, 0), ("omp", 0, 2), ("omp", 0, 4), ("random", 1, 2)}
    for k in (0, 2, 4):  # uniform: the plan's own curve (no --where) at the same k
        key = ("uniform", "none" if k == 0 else "omp", 0, k)
        assert got[key][0] == pytest.approx(curve[k], abs=1e-6)
    w = 40 * sampling_probabilities(data.base_score, "weighted")
    assert np.allclose(test_set_weights(data.base_score, "weighted"), w)
    assert got[("weighted", "omp", 0, 2)][0] == pytest.approx(marker_set_curve(data, order[:2], w, RECALL)[-1], abs=1e-12)
    drawn = drawn_weights(40, poses["weighted"].source_index)
    assert drawn.sum() == pytest.approx(40) and np.count_nonzero(drawn) == len(np.unique(poses["weighted"].source_index))
    assert got[("weighted", "random", 1, 2)][1] == pytest.approx(marker_set_curve(data, [0, 5], drawn, RECALL)[-1], abs=1e-12)


def test_the_where_test_set_uses_the_plans_pose_weights():
    data = plan_data(3, N=30, C=6)
    w = np.zeros(30)
    w[:10] = 3.0  # the where file's weights, summing to N
    data = replace(data, pose_weight=w)
    conf = PlacementConfig(method="omp", k=2)
    placement = place(data, conf, progress=False)
    curve = predicted_recall(data, placement, conf)["recall"]  # a plan made with --where
    poses = {"where": SimpleNamespace(source_index=np.arange(10))}
    got = predict_recalls(data, [_run(data, "omp", 0, [int(c) for c in placement.candidates])], poses, SIZE, RECALL)
    assert got[("where", "omp", 0, 2)][0] == pytest.approx(curve[2], abs=1e-6)
    assert np.allclose(test_set_weights(data.base_score, "where", w), w)


def test_evaluate_predicted_on_tiny(tmp_path):
    out = tmp_path / "eval"
    code = main(["evaluate", "tiny", "--out", str(out), "--tests", "12", "--k", "2", "--runs", "1",
                 "--methods", "none,omp,random", "--predicted", "--grid-spacing", "1.0", "--yaws", "4",
                 "--workers", "2", "--quiet"])
    assert code == 0
    assert (out / "plan" / "success_model_expected-recall.json").is_file()  # fitted for --predicted
    rows = list(csv.DictReader((out / "predicted.csv").open()))
    assert {(r["test_set"], r["method"], r["k"]) for r in rows} == {
        (ts, m, k) for ts in ("weighted", "uniform") for m, k in (("none", "0"), ("omp", "2"), ("random", "2"))}
    recall = {(r["test_set"], r["method"], r["k"]): float(r["recall"])
              for r in csv.DictReader((out / "recall.csv").open()) if r["threshold"] == "5cm/5deg"}
    for r in rows:
        assert 0 <= float(r["predicted"]) <= 1 and float(r["measured"]) == pytest.approx(
            recall[(r["test_set"], r["method"], r["k"])], abs=1e-6)
        assert float(r["difference"]) == pytest.approx(100 * (float(r["predicted"]) - float(r["measured"])), abs=2e-3)
    md = (out / "tables.md").read_text()
    assert "## Predicted against measured recall" in md and md.count("| **all** | 3 |") == 2
    assert "Predicted against measured recall" in (out / "report.html").read_text()
