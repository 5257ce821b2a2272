"""``evaluate --predicted`` outputs: the predicted recall of each placement (the success model,
:mod:`markerplace.testbed.predicted_per_placement`) against its measured recall, and the calibration error.

* ``predicted.csv``: one row per (test set, method, run, k) with :data:`PREDICTED_COLUMNS`
  (shares in [0, 1]; ``difference`` = predicted - measured, in percentage points);
* a section of ``tables.md`` (so of ``report.html``): per test set, method and k the
  predicted, predicted on the drawn poses and measured recall (mean over runs) and their
  difference, then the calibration error;
* one log line per test set and k, and the calibration error in the printed summary.

The *calibration error* of a test set is the mean over its placements (every run of every
method at every k, ``none`` at k = 0 included) of |predicted - measured| in percentage points;
per method the same over that method's placements; ``bias`` is the mean signed difference
(positive: the model is optimistic). Only the clean test images (no query condition) at the
main threshold are compared: the model was fitted on clean map images at that threshold.
"""

from __future__ import annotations

import csv
import logging
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.runtime.atomic_io import atomic_path
from markerplace.simulation.conditions import CLEAN
from markerplace.simulation.marker_sets import NO_MARKERS
from markerplace.testbed.reporting.tables import md_name, md_text, ordered_methods

log = logging.getLogger(__name__)

__all__ = ["PREDICTED_COLUMNS", "calibration_errors", "error_summary", "log_predicted", "predicted_markdown",
           "predicted_rows", "write_predicted_csv"]

PREDICTED_COLUMNS = ("scene", "test_set", "method", "run", "k", "predicted", "predicted_drawn", "measured",
                     "difference", "n_tests")


def predicted_rows(rows: Sequence[dict], predicted: dict, threshold: str) -> list[dict]:
    """Join recall rows (clean, at ``threshold``) with :func:`~markerplace.testbed.predicted_per_placement.predict_recalls`'s
    ``predicted``; a row per placement and test set that has both, in the recall rows' order."""
    out = []
    for r in rows:
        key = (r["test_set"], r["method"], int(r["run"]), int(r["k"]))
        if r["threshold"] != threshold or r.get("condition", CLEAN) != CLEAN or key not in predicted:
            continue
        pred, drawn = predicted[key]
        out.append(dict(scene=r["scene"], test_set=key[0], method=key[1], run=key[2], k=key[3], predicted=pred,
                        predicted_drawn=drawn, measured=float(r["recall"]),
                        difference=100.0 * (pred - float(r["recall"])), n_tests=r["n_tests"]))
    return out


def write_predicted_csv(path: str | Path, rows: Sequence[dict]) -> None:
    """``predicted.csv`` (module docstring), atomically; shares with 6 decimals, points with 3."""
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(PREDICTED_COLUMNS)
        for r in rows:
            w.writerow([r["scene"], r["test_set"], r["method"], r["run"], r["k"], f"{r['predicted']:.6f}",
                        f"{r['predicted_drawn']:.6f}", f"{r['measured']:.6f}", f"{r['difference']:.3f}", r["n_tests"]])


def _stats(rows: Sequence[dict]) -> dict:
    d = np.array([r["difference"] for r in rows], float)
    dd = np.array([100.0 * (r["predicted_drawn"] - r["measured"]) for r in rows], float)
    return {"placements": len(d), "mean_abs": float(np.mean(np.abs(d))), "bias": float(np.mean(d)),
            "mean_abs_drawn": float(np.mean(np.abs(dd)))}


def calibration_errors(rows: Sequence[dict]) -> dict:
    """test set -> {"all": stats, method: stats, ...} over :func:`predicted_rows`'s rows; stats:
    ``placements``, ``mean_abs`` and ``bias`` (points, predicted - measured) and ``mean_abs_drawn``
    (the same with the prediction on the drawn poses)."""
    out: dict = {}
    for ts in dict.fromkeys(r["test_set"] for r in rows):
        of = [r for r in rows if r["test_set"] == ts]
        methods = ([NO_MARKERS] if any(r["method"] == NO_MARKERS for r in of) else []) + ordered_methods(of)
        out[ts] = {"all": _stats(of), **{m: _stats([r for r in of if r["method"] == m]) for m in methods}}
    return out


def _pct(values) -> str:
    return f"{100.0 * float(np.mean(values)):.1f}"


def predicted_markdown(rows: Sequence[dict], threshold: str) -> str:
    """The ``tables.md`` section (module docstring); empty without rows."""
    if not rows:
        return ""
    lines = ["", f"## Predicted against measured recall ({md_text(threshold)}, clean test images)", "",
             "Predicted: the success model's expected share of the test set's source poses that localize (the "
             "model plans use, fitted on map images; the poses weighted as the test set draws them: `uniform` "
             "as a plan's own curve, `weighted` towards low scores, `where` by the where file). On drawn poses: "
             "weighted by the test images actually drawn. Mean over runs; difference = predicted - measured, "
             "percentage points.", ""]
    errors = calibration_errors(rows)
    for ts, stats in errors.items():
        of = [r for r in rows if r["test_set"] == ts]
        lines += [f"### Test set `{md_text(ts)}`", "",
                  "| Method | k | runs | predicted | on drawn poses | measured | difference |", "|---|---|---|---|---|---|---|"]
        for m in [m for m in stats if m != "all"]:
            for k in sorted({r["k"] for r in of if r["method"] == m}):
                sel = [r for r in of if r["method"] == m and r["k"] == k]
                diff = float(np.mean([r["difference"] for r in sel]))
                lines.append(f"| {md_name(m)} | {k} | {len(sel)} | {_pct([r['predicted'] for r in sel])} | "
                             f"{_pct([r['predicted_drawn'] for r in sel])} | {_pct([r['measured'] for r in sel])} | "
                             f"{diff:+.1f} |")
        lines += ["", f"Calibration error, `{md_text(ts)}` (mean over placements, percentage points):", "",
                  "| Method | placements | mean abs. difference | bias (mean difference) | mean abs., on drawn poses |",
                  "|---|---|---|---|---|"]
        for m, s in stats.items():
            name = "**all**" if m == "all" else md_name(m)
            lines.append(f"| {name} | {s['placements']} | {s['mean_abs']:.1f} | {s['bias']:+.1f} | "
                         f"{s['mean_abs_drawn']:.1f} |")
        lines.append("")
    return "\n".join(lines)


def error_summary(rows: Sequence[dict]) -> str:
    """One line per test set for the printed summary: the calibration error, all and per method."""
    out = []
    for ts, stats in calibration_errors(rows).items():
        per = ", ".join(f"{m} {s['mean_abs']:.1f}" for m, s in stats.items() if m != "all")
        a = stats["all"]
        out.append(f"Calibration error, `{ts}` test set: {a['mean_abs']:.1f} points mean |predicted - measured| over "
                   f"{a['placements']} placements (bias {a['bias']:+.1f}; on the drawn poses {a['mean_abs_drawn']:.1f});"
                   f" per method: {per}")
    return "\n".join(out)


def log_predicted(rows: Sequence[dict]) -> None:
    """One log line per test set and k: predicted against measured recall of every method (run means)."""
    for ts in dict.fromkeys(r["test_set"] for r in rows):
        for k in sorted({r["k"] for r in rows if r["test_set"] == ts}):
            sel = [r for r in rows if r["test_set"] == ts and r["k"] == k]
            parts = []
            for m in dict.fromkeys(r["method"] for r in sel):
                of = [r for r in sel if r["method"] == m]
                parts.append(f"{m} {_pct([r['predicted'] for r in of])} vs {_pct([r['measured'] for r in of])}")
            log.info("predicted vs measured recall %%, %s test set, k=%d: %s", ts, k, "; ".join(parts))
