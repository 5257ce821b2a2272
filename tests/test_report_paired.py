"""Paired differences of recall on shared test images, with bootstrap intervals."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.report.paired import (
    bootstrap_mean_ci,
    format_difference,
    paired_differences,
    paired_markdown,
    paired_table,
)


def test_bootstrap_interval_contains_mean_and_is_seeded() -> None:
    rng = np.random.default_rng(0)
    diff = rng.choice([-1.0, 0.0, 1.0], size=400, p=[0.1, 0.7, 0.2])
    mean, low, high = bootstrap_mean_ci(diff, n_boot=1000, seed=3)
    assert mean == pytest.approx(diff.mean())
    assert low < mean < high
    # the interval is about +-1.96 standard errors
    se = diff.std(ddof=1) / np.sqrt(diff.size)
    assert high - low == pytest.approx(2 * 1.96 * se, rel=0.15)
    assert bootstrap_mean_ci(diff, n_boot=1000, seed=3) == (mean, low, high)
    assert bootstrap_mean_ci(np.full(50, 0.25), n_boot=100) == (0.25, 0.25, 0.25)
    assert all(np.isnan(bootstrap_mean_ci(np.zeros(0))))


def test_paired_difference_is_recall_difference() -> None:
    rng = np.random.default_rng(1)
    n = 300
    omp = rng.random(n) < 0.8
    hits = {("none", 0, 0): rng.random(n) < 0.5, ("omp", 0, 10): omp}
    for run in range(3):
        hits[("random", run, 10)] = rng.random(n) < 0.6
        hits[("uniform", run, 10)] = omp.copy()  # identical outcomes: difference exactly 0
    diffs = {(d["method"], d["baseline"]): d for d in paired_differences(hits, [10], n_boot=500)}
    assert set(diffs) == {("omp", "random"), ("omp", "uniform")}
    rnd = diffs[("omp", "random")]
    expected = omp.mean() - np.mean([hits[("random", r, 10)].mean() for r in range(3)])
    assert rnd["diff"] == pytest.approx(expected) and rnd["runs"] == 3
    assert rnd["low"] > 0  # a 20-point lead on 300 images is clear
    same = diffs[("omp", "uniform")]
    assert (same["diff"], same["low"], same["high"]) == (0.0, 0.0, 0.0)
    # a k with no candidate result gives no row
    assert paired_differences(hits, [5]) == []


def test_paired_table_and_markdown() -> None:
    d_pos = dict(method="omp", baseline="random", k=10, diff=0.05, low=0.01, high=0.09, runs=5)
    d_zero = dict(method="omp", baseline="random", k=20, diff=0.01, low=-0.02, high=0.04, runs=5)
    assert format_difference(d_pos) == "**+5.0 [+1.0, +9.0]**"
    assert format_difference(d_zero) == "+1.0 [-2.0, +4.0]"
    table = paired_table([d_pos, d_zero], [5, 10, 20])
    assert "| Ours | Rand. (5 runs) | - | **+5.0 [+1.0, +9.0]** | +1.0 [-2.0, +4.0] |" in table
    hits = {("omp", 0, 5): np.ones(10, bool), ("random", 0, 5): np.zeros(10, bool)}
    md = paired_markdown({"weighted": hits, "uniform": {}}, [5], "5cm/5deg", n_boot=50)
    assert "## Paired differences at 5cm/5deg" in md and "### Test set `weighted`" in md
    assert "`uniform`" not in md
    assert paired_markdown({"weighted": {("none", 0, 0): np.ones(3, bool)}}, [5], "x") == ""
