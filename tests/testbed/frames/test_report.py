"""Recall rows and the gap table of the real-photograph testbed."""

from __future__ import annotations

import numpy as np

from markerplace.testbed.frames.report import frames_markdown, gap_rows, recall_rows


def _hits(pattern: str) -> np.ndarray:
    return np.array([c == "1" for c in pattern])


def test_gap_rows_simulated_minus_real_per_method_and_k():
    hits = {
        "render@render": {("none", 0, 0): _hits("1111100000"), ("random", 0, 3): _hits("1111111100"),
                          ("random", 1, 3): _hits("1111111000")},
        "real@render": {("none", 0, 0): _hits("1100000000"), ("random", 0, 3): _hits("1111000000"),
                        ("random", 1, 3): _hits("1110000000")},
        "real@frames": {("none", 0, 0): _hits("1110000000")},
    }
    rows = {(r["method"], r["k"]): r for r in gap_rows(hits)}
    none = rows[("none", 0)]
    assert none["simulated"] == 0.5 and none["real"] == 0.2 and np.isclose(none["diff"], 0.3)
    assert none["low"] <= 0.3 <= none["high"] and none["real_frames_map"] == 0.3
    rnd = rows[("random", 3)]
    assert rnd["runs"] == 2 and np.isclose(rnd["simulated"], 0.75) and np.isclose(rnd["real"], 0.35)
    assert np.isclose(rnd["diff"], 0.4) and np.isnan(rnd["real_frames_map"])
    # the simulation is optimistic on every image here: the whole interval is above zero
    assert rnd["low"] > 0


def test_recall_rows_and_markdown():
    t = np.array([0.01, 0.04, 0.2, np.inf])
    r = np.array([1.0, 4.0, 2.0, np.inf])
    errors = {("none", 0, 0, "real@frames"): (t, r), ("omp", 0, 2, "real@frames"): (t * 0.5, r * 0.5)}
    rows = recall_rows("kitchen", errors, ((0.05, 5.0), (0.10, 10.0)))
    got = {(x["method"], x["threshold"]): x["recall"] for x in rows}
    assert got[("none", "5cm/5deg")] == 0.5 and got[("omp", "10cm/10deg")] == 0.75
    hits = {"real@frames": {("none", 0, 0): t <= 0.05, ("omp", 0, 2): t * 0.5 <= 0.05}}
    md = frames_markdown("kitchen", rows, hits, hits, [2], "5cm/5deg", "10cm/10deg", ["5cm/5deg", "10cm/10deg"],
                         ["- a header line"])
    assert "a header line" in md and "`real@frames`" in md and "kitchen (50.0)" in md
