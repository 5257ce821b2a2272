"""The predicted-against-measured tables and the calibration error, on a hand-made table."""

from __future__ import annotations

import csv

import pytest

from markerplace.testbed.reporting.predicted_tables import calibration_errors, error_summary, predicted_markdown, predicted_rows, write_predicted_csv

MAIN = "5cm/5deg"


def _rows():
    """Recall rows and predictions: differences +5 (omp k=2), -2 (omp k=4), 0 and -4 (random k=2,
    runs 0 and 1), -1 (none) points."""
    measured = {("none", 0, 0): 0.61, ("omp", 0, 2): 0.75, ("omp", 0, 4): 0.92, ("random", 0, 2): 0.70,
                ("random", 1, 2): 0.74}
    pred = {("none", 0, 0): 0.60, ("omp", 0, 2): 0.80, ("omp", 0, 4): 0.90, ("random", 0, 2): 0.70,
            ("random", 1, 2): 0.70}
    rows = []
    for (m, run, k), v in measured.items():
        for th, cond in ((MAIN, "clean"), ("1m/30deg", "clean"), (MAIN, "blur")):
            rows.append(dict(scene="s", method=m, run=run, k=k, test_set="weighted", condition=cond, threshold=th,
                             recall=v if (th, cond) == (MAIN, "clean") else 0.0, n_tests=100))
    predicted = {("weighted",) + key: (v, v + 0.01) for key, v in pred.items()}
    predicted[("weighted", "human", 0, 2)] = (0.5, 0.5)  # not evaluated: no row
    return rows, predicted


def test_calibration_error_arithmetic(tmp_path):
    rows, predicted = _rows()
    table = predicted_rows(rows, predicted, MAIN)
    assert len(table) == 5  # only the clean rows at the main threshold
    assert sorted(round(r["difference"], 9) for r in table) == [-4.0, -2.0, -1.0, 0.0, 5.0]
    err = calibration_errors(table)["weighted"]
    assert list(err) == ["all", "none", "omp", "random"]
    assert err["all"]["placements"] == 5
    assert err["all"]["mean_abs"] == pytest.approx(2.4) and err["all"]["bias"] == pytest.approx(-0.4)
    assert err["omp"]["mean_abs"] == pytest.approx(3.5) and err["omp"]["bias"] == pytest.approx(1.5)
    assert err["random"]["mean_abs"] == pytest.approx(2.0) and err["random"]["bias"] == pytest.approx(-2.0)
    # on the drawn poses every prediction is 1 point higher: |6| + |-1| + |1| + |-3| + |0| over 5
    assert err["all"]["mean_abs_drawn"] == pytest.approx(2.2)
    md = predicted_markdown(table, MAIN)
    assert "| Ours | 2 | 1 | 80.0 | 81.0 | 75.0 | +5.0 |" in md
    assert "| Rand. | 2 | 2 | 70.0 | 71.0 | 72.0 | -2.0 |" in md  # mean over runs
    assert "| No markers | 0 | 1 | 60.0 | 61.0 | 61.0 | -1.0 |" in md
    assert "| **all** | 5 | 2.4 | -0.4 | 2.2 |" in md
    assert "weighted` test set: 2.4 points" in error_summary(table) and "omp 3.5" in error_summary(table)
    assert predicted_markdown([], MAIN) == ""
    write_predicted_csv(tmp_path / "predicted.csv", table)
    back = list(csv.DictReader((tmp_path / "predicted.csv").open()))
    assert [r["method"] for r in back] == ["none", "omp", "omp", "random", "random"]
    assert back[1]["predicted"] == "0.800000" and back[1]["measured"] == "0.750000" and back[1]["difference"] == "5.000"
