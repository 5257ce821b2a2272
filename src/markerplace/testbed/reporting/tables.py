"""Recall tables of the testbed: ``recall.csv`` and Markdown tables shaped like the paper's.

A *recall row* is a dict with the ``recall.csv`` columns :data:`CSV_COLUMNS`:
``scene, method, run, k, test_set, threshold, recall, n_tests`` where ``threshold`` is a label
such as ``5cm/5deg`` (see :func:`markerplace.testbed.metrics.threshold_label`), ``recall`` is a
fraction in [0, 1] and the method ``none`` (no markers) has ``k = 0``.

Markdown tables print recall in percent. Methods are listed in registry order
(:data:`~markerplace.plan.place.methods.PLACEMENT_METHODS`), labelled by the method's ``label``, then
other names (``--placements`` files) sorted. Methods with several runs (the randomized ones,
random and uniform) show ``mean ± std`` over runs, std being the sample standard deviation (ddof = 1;
0 for a single run shows just the mean). The best mean per column is bold, as in Table I.
"""

from __future__ import annotations

import csv
from collections import defaultdict
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from markerplace.runtime.atomic_io import atomic_path
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.testbed.marker_sets import NO_MARKERS

CSV_COLUMNS = ("scene", "method", "run", "k", "test_set", "threshold", "recall", "n_tests")

_MD_SPECIAL = str.maketrans({c: "\\" + c for c in "\\`*_[]|~"} | {"<": "&lt;", ">": "&gt;", "&": "&amp;",
                                                                         "\n": " ", "\r": " ", "\t": " "})


def md_text(text) -> str:
    """``text`` (a scene or ``--placements`` folder name, anything a user named) as literal
    Markdown table-cell text: Markdown's special characters backslash-escaped, ``|`` included,
    ``<``, ``>`` and ``&`` as HTML entities (Markdown renderers pass raw HTML through), line
    breaks as spaces. The Markdown counterpart of :func:`markerplace.report.html.esc`."""
    return str(text).translate(_MD_SPECIAL)


def md_name(method: str) -> str:
    """:func:`display_name` for a Markdown table: a registered method's label as written (ours),
    any other name (a ``--placements`` folder) through :func:`md_text`."""
    if method == NO_MARKERS or PLACEMENT_METHODS.get(method) is not None:
        return display_name(method)
    return md_text(method)


def display_name(method: str) -> str:
    """Paper-style label of a method: ``No markers`` for ``none``, a placement method's ``label``
    (``omp`` -> ``Ours``); other names (``--placements`` files) are kept."""
    if method == NO_MARKERS:
        return "No markers"
    cls = PLACEMENT_METHODS.get(method)
    return cls.label if cls is not None and cls.label else method


def write_recall_csv(path: str | Path, rows: Iterable[dict]) -> None:
    """Write recall rows (see module docstring) as CSV, atomically; recall with 6 decimals."""
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS)
            writer.writeheader()
            for r in rows:
                out = {c: r[c] for c in CSV_COLUMNS}
                out["recall"] = f"{float(r['recall']):.6f}"
                writer.writerow(out)


def read_recall_csv(path: str | Path) -> list[dict]:
    """Read ``recall.csv`` back into rows with typed values."""
    with open(path, newline="") as fh:
        return [{**r, "run": int(r["run"]), "k": int(r["k"]), "recall": float(r["recall"]),
                 "n_tests": int(r["n_tests"])} for r in csv.DictReader(fh)]


def format_mean_std(values: Sequence[float], percent: bool = True, digits: int = 1) -> str:
    """``"60.7 ± 0.7"`` for several values, ``"63.7"`` for one, ``"-"`` for none.

    Values are fractions; ``percent`` multiplies by 100. Std is the sample std (ddof = 1).
    """
    vals = np.asarray([v for v in values if np.isfinite(v)], dtype=float) * (100.0 if percent else 1.0)
    if len(vals) == 0:
        return "-"
    if len(vals) == 1:
        return f"{vals[0]:.{digits}f}"
    return f"{vals.mean():.{digits}f} ± {vals.std(ddof=1):.{digits}f}"


def _group(rows: Iterable[dict]) -> dict:
    """(scene, test_set, threshold, method, k) -> list of recalls over runs."""
    out: dict = defaultdict(list)
    for r in rows:
        out[(r["scene"], r["test_set"], r["threshold"], r["method"], int(r["k"]))].append(float(r["recall"]))
    return out


def _methods(rows: Sequence[dict]) -> list[str]:
    present = {r["method"] for r in rows if r["method"] != NO_MARKERS}
    ordered = [m for m in PLACEMENT_METHODS if m in present]
    return ordered + sorted(present - set(ordered))


def method_table(rows: Sequence[dict], test_set: str, threshold: str, ks: Sequence[int]) -> str:
    """Markdown table like the paper's Table I for one test set and threshold.

    Rows: scene (with its no-marker recall in parentheses) x method; columns: k. Cells are
    recall in percent, ``mean ± std`` over runs.
    """
    groups = _group(rows)
    methods = _methods(rows)
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    lines = ["| Scene (no markers) | Method | " + " | ".join(f"k={k}" for k in ks) + " |",
             "|---|---|" + "---|" * len(ks)]
    for scene in scenes:
        base = groups.get((scene, test_set, threshold, "none", 0), [])
        scene_cell = f"{md_text(scene)} ({format_mean_std(base)})"
        means = {(m, k): np.mean(groups[(scene, test_set, threshold, m, k)])
                 for m in methods for k in ks if groups.get((scene, test_set, threshold, m, k))}
        best = {k: max((v for (m, kk), v in means.items() if kk == k), default=None) for k in ks}
        for i, m in enumerate(methods):
            cells = []
            for k in ks:
                vals = groups.get((scene, test_set, threshold, m, k), [])
                text = format_mean_std(vals)
                if vals and len(methods) > 1 and np.isclose(np.mean(vals), best[k]):
                    text = f"**{text}**"
                cells.append(text)
            lines.append(f"| {scene_cell if i == 0 else ''} | {md_name(m)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def thresholds_table(rows: Sequence[dict], thresholds: Sequence[str], ks: Sequence[int]) -> str:
    """Markdown table of every (scene, test set, method, threshold): k = 0 (no markers) then ks."""
    groups = _group(rows)
    methods = _methods(rows)
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    test_sets = list(dict.fromkeys(r["test_set"] for r in rows))
    lines = ["| Scene | Test set | Method | Threshold | k=0 | " + " | ".join(f"k={k}" for k in ks) + " |",
             "|---|---|---|---|---|" + "---|" * len(ks)]
    for scene in scenes:
        for ts in test_sets:
            for m in methods:
                for th in thresholds:
                    base = format_mean_std(groups.get((scene, ts, th, "none", 0), []))
                    cells = [format_mean_std(groups.get((scene, ts, th, m, k), [])) for k in ks]
                    lines.append(f"| {md_text(scene)} | {ts} | {md_name(m)} | {th} | {base} | "
                                 + " | ".join(cells) + " |")
    return "\n".join(lines)


def main_tables_markdown(rows: Sequence[dict], ks: Sequence[int], main_threshold: str) -> str:
    """One Table-I-like table per test set at the main threshold (what ``evaluate`` prints)."""
    parts = ["# Localization recall (%)", ""]
    for ts in dict.fromkeys(r["test_set"] for r in rows):
        parts += [f"## Test set `{ts}`, recall at {main_threshold} (mean ± std over runs)", "",
                  method_table(rows, ts, main_threshold, ks), ""]
    return "\n".join(parts)


def tables_markdown(rows: Sequence[dict], ks: Sequence[int], main_threshold: str,
                    thresholds: Sequence[str]) -> str:
    """The whole ``tables.md``: :func:`main_tables_markdown`, then the table of all thresholds."""
    return main_tables_markdown(rows, ks, main_threshold) + "\n" + "\n".join(
        ["## All thresholds", "", thresholds_table(rows, thresholds, ks), ""])


def recall_curves(rows: Sequence[dict], scene: str, test_set: str, threshold: str,
                  ks: Sequence[int]) -> dict[str, tuple[np.ndarray, np.ndarray | None]]:
    """Curves for :func:`markerplace.report.figures.recall_vs_k` in percent, k = 0 then ``ks``.

    Every method starts at the no-marker recall (k = 0). Methods with one run get no std band.
    """
    groups = _group(rows)
    base = groups.get((scene, test_set, threshold, "none", 0), [])
    base_mean = 100.0 * float(np.mean(base)) if base else np.nan
    curves = {}
    for m in _methods(rows):
        means, stds, multi = [base_mean], [0.0], False
        for k in ks:
            vals = 100.0 * np.asarray(groups.get((scene, test_set, threshold, m, k), [np.nan]), dtype=float)
            means.append(float(np.mean(vals)))
            stds.append(float(np.std(vals, ddof=1)) if len(vals) > 1 else 0.0)
            multi |= len(vals) > 1
        curves[display_name(m)] = (np.array(means), np.array(stds) if multi else None)
    if not curves and base:
        curves[display_name("none")] = (np.full(len(ks) + 1, base_mean), None)
    return curves
