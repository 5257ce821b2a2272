"""Paired differences of recall on shared test images, with bootstrap intervals."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from markerplace.testbed.reporting.paired import (
    bootstrap_difference,
    condition_differences,
    condition_markdown,
    fixed_broken,
    fixed_broken_table,
    format_difference,
    paired_differences,
    paired_markdown,
    paired_table,
)


def test_bootstrap_interval_covers_images_and_runs() -> None:
    rng = np.random.default_rng(0)
    n = 400
    own = (rng.random(n) < 0.8).astype(float)
    one_run = (rng.random((1, n)) < 0.7).astype(float)
    diff, low, high = bootstrap_difference(own, one_run, n_boot=1000, seed=3)
    assert diff == pytest.approx(own.mean() - one_run.mean())
    assert low < diff < high
    # one run: the interval is about +-1.96 standard errors of the per-image differences
    se = (own - one_run[0]).std(ddof=1) / np.sqrt(n)
    assert high - low == pytest.approx(2 * 1.96 * se, rel=0.15)
    assert bootstrap_difference(own, one_run, n_boot=1000, seed=3) == (diff, low, high)
    # runs that disagree widen the interval (resampling runs); identical runs do not
    spread = np.stack([(rng.random(n) < p).astype(float) for p in (0.5, 0.6, 0.7, 0.8, 0.9)])
    same = np.repeat(spread[2:3], 5, axis=0)
    w_spread = np.subtract(*bootstrap_difference(own, spread, 1000, 3)[2:0:-1])
    w_same = np.subtract(*bootstrap_difference(own, same, 1000, 3)[2:0:-1])
    assert w_spread > 1.5 * w_same
    assert bootstrap_difference(np.full(50, 1.0), np.full((2, 50), 0.75), n_boot=100) == (0.25, 0.25, 0.25)
    assert all(np.isnan(bootstrap_difference(np.zeros(0), np.zeros((1, 0)))))
    with pytest.raises(ValueError):
        bootstrap_difference(own, one_run, n_boot=0)
    with pytest.raises(ValueError):
        bootstrap_difference(own, one_run[:, :10])


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
    assert np.allclose((same["diff"], same["low"], same["high"]), 0.0, atol=1e-12)
    # a k with no candidate result gives no row
    assert paired_differences(hits, [5]) == []


def test_paired_table_and_markdown() -> None:
    d_pos = dict(method="omp", baseline="random", k=10, diff=0.05, low=0.01, high=0.09, runs=5)
    d_zero = dict(method="omp", baseline="random", k=20, diff=0.01, low=-0.02, high=0.04, runs=5)
    assert format_difference(d_pos) == "**+5.0 [+1.0, +9.0]**"
    assert format_difference(d_zero) == "+1.0 [-2.0, +4.0]"
    assert format_difference({**d_zero, "diff": -0.05, "low": -0.08, "high": -0.01}) == "*-5.0 [-8.0, -1.0]*"
    table = paired_table([d_pos, d_zero], [5, 10, 20])
    assert "| Ours | Rand. (5 runs) | - | **+5.0 [+1.0, +9.0]** | +1.0 [-2.0, +4.0] |" in table
    hits = {("omp", 0, 5): np.ones(10, bool), ("random", 0, 5): np.zeros(10, bool)}
    md = paired_markdown({"weighted": hits, "uniform": {}}, [5], "5cm/5deg", n_boot=50)
    assert "## Paired differences at 5cm/5deg" in md and "### Test set `weighted`" in md
    assert "`uniform`" not in md
    assert paired_markdown({"weighted": {("none", 0, 0): np.ones(3, bool)}}, [5], "x") == ""


def test_fixed_and_broken_images() -> None:
    none = np.array([1, 1, 0, 0, 0], bool)
    hits = {("none", 0, 0): none,
            ("omp", 0, 5): np.array([1, 0, 1, 1, 0], bool),      # fixes 2, breaks 1
            ("random", 0, 5): np.array([1, 1, 1, 0, 0], bool),   # fixes 1
            ("random", 1, 5): np.array([0, 1, 1, 1, 1], bool)}   # fixes 3, breaks 1
    rows = {(r["method"], r["k"]): r for r in fixed_broken(hits, [5, 10])}
    assert set(rows) == {("omp", 5), ("random", 5)}
    assert (rows[("omp", 5)]["fixed"], rows[("omp", 5)]["broken"]) == (2.0, 1.0)
    assert (rows[("random", 5)]["fixed"], rows[("random", 5)]["broken"], rows[("random", 5)]["runs"]) == (2.0, 0.5, 2)
    table = fixed_broken_table(list(rows.values()), [5, 10])
    assert "| Ours | +2 / -1 | - |" in table and "| Rand. | +2.0 / -0.5 | - |" in table
    assert fixed_broken({k: v for k, v in hits.items() if k[0] != "none"}, [5]) == []
    md = paired_markdown({"weighted": hits}, [5], "5cm/5deg", n_boot=50)
    assert "fixed / broken" in md and "| Ours | +2 / -1 |" in md


def _condition_hits(n: int = 300):
    """Clean and blurred hits of no markers and of a 2-run baseline on the same n test images."""
    rng = np.random.default_rng(5)
    none_clean = rng.random(n) < 0.6
    base_clean = [none_clean | (rng.random(n) < 0.3) for _ in range(2)]
    lost = rng.random(n) < 0.25  # blur loses a quarter of the images in every placement
    return {
        "weighted": {("none", 0, 0): none_clean, ("random", 0, 5): base_clean[0], ("random", 1, 5): base_clean[1]},
        "weighted@blur": {("none", 0, 0): none_clean & ~lost, ("random", 0, 5): base_clean[0] & ~lost,
                          ("random", 1, 5): base_clean[1] & ~lost},
    }, lost


def test_condition_differences_pair_each_placement_with_itself_clean() -> None:
    hits, lost = _condition_hits()
    diffs = condition_differences(hits, n_boot=500, seed=1)
    assert [(d["condition"], d["method"], d["k"], d["runs"]) for d in diffs] == [("blur", "none", 0, 1),
                                                                                 ("blur", "random", 5, 2)]
    none, rand = diffs
    clean, blur = hits["weighted"], hits["weighted@blur"]
    assert none["diff"] == pytest.approx(blur[("none", 0, 0)].mean() - clean[("none", 0, 0)].mean())
    assert none["diff"] < 0 and none["diff_low"] < none["diff"] < none["diff_high"] < 0
    assert np.isnan(none["gain"])  # no markers has no gain over itself
    run_mean = lambda h: np.mean([h[("random", r, 5)] for r in (0, 1)], axis=0)  # noqa: E731
    assert rand["diff"] == pytest.approx(run_mean(blur).mean() - run_mean(clean).mean())
    gain_change = (run_mean(blur) - blur[("none", 0, 0)]) - (run_mean(clean) - clean[("none", 0, 0)])
    assert rand["gain"] == pytest.approx(gain_change.mean())
    assert rand["gain_low"] <= rand["gain"] <= rand["gain_high"]
    # a condition that changes nothing gives zero with a zero-width interval
    same = condition_differences({"weighted": hits["weighted"], "weighted@noise": hits["weighted"]}, n_boot=50)
    assert all((d["diff"], d["diff_low"], d["diff_high"]) == (0.0, 0.0, 0.0) for d in same)
    # runs that do not match both ways, and sets without their clean set, are left out
    partial = {"weighted": hits["weighted"], "weighted@blur": {("random", 0, 5): blur[("random", 0, 5)]},
               "uniform@blur": hits["weighted@blur"]}
    assert condition_differences(partial, n_boot=50) == []


def test_condition_markdown_tables() -> None:
    hits, _ = _condition_hits()
    md = condition_markdown(hits, "5cm/5deg", n_boot=200)
    assert md.startswith("## Query conditions against clean, paired, at 5cm/5deg (95 % interval)")
    assert "### Test set `weighted`: recall under the condition minus clean recall" in md
    assert "| Method | k | `blur` |" in md
    rows = [line for line in md.splitlines() if line.startswith("| No markers") or line.startswith("| Rand.")]
    assert len(rows) == 3  # no markers and random in the first table, random alone in the gain table
    assert rows[0].startswith("| No markers | 0 | *-") and rows[1].startswith("| Rand. (2 runs) | 5 | *-")
    assert condition_markdown({"weighted": hits["weighted"]}, "5cm/5deg") == ""  # clean only: no section


def test_a_placement_missing_from_the_clean_images_is_left_out_quietly() -> None:
    hits = {"weighted": {("none", 0, 0): np.ones(5, bool)},
            "weighted@blur": {("none", 0, 0): np.ones(5, bool), ("omp", 0, 5): np.ones(5, bool)}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "mean of empty slice" for the missing clean runs
        assert [d["method"] for d in condition_differences(hits, n_boot=20)] == ["none"]
