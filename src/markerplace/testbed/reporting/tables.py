"""Recall tables of the testbed: ``recall.csv`` and Markdown tables shaped like the paper's.

A *recall row* is a dict with the ``recall.csv`` columns :data:`CSV_COLUMNS`:
``scene, method, run, k, test_set, threshold, recall, n_tests`` where ``threshold`` is a label
such as ``5cm/5deg`` (see :func:`markerplace.simulation.metrics.threshold_label`), ``recall`` is a
fraction in [0, 1] and the method ``none`` (no markers) has ``k = 0``. A row may also carry
``condition``, the query condition (:mod:`markerplace.simulation.conditions`; ``clean`` when
absent); ``recall.csv`` has a ``condition`` column (after ``test_set``) only when some row's
condition is not ``clean``, and the tables then key each test set by condition
(``weighted@blur``, :func:`~markerplace.simulation.conditions.set_name`) and add a table of
recall per condition.

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

from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.runtime.atomic_io import atomic_path
from markerplace.simulation.conditions import CLEAN, set_name, split_set
from markerplace.simulation.marker_sets import NO_MARKERS

CSV_COLUMNS = ("scene", "method", "run", "k", "test_set", "threshold", "recall", "n_tests")
#: ``recall.csv``'s columns when some row has a query condition other than ``clean``.
CONDITION_COLUMNS = CSV_COLUMNS[:5] + ("condition",) + CSV_COLUMNS[5:]


def has_conditions(rows: Iterable[dict]) -> bool:
    """Some row's query condition is not ``clean``."""
    return any(r.get("condition", CLEAN) != CLEAN for r in rows)


def image_set(row: dict) -> str:
    """The image set of a recall row: its test set, ``<test set>@<condition>`` under a condition."""
    return set_name(row["test_set"], row.get("condition", CLEAN))

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
    rows = list(rows)
    columns = CONDITION_COLUMNS if has_conditions(rows) else CSV_COLUMNS
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=columns)
            writer.writeheader()
            for r in rows:
                out = {c: r.get(c, CLEAN) if c == "condition" else r[c] for c in columns}
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
    """(scene, image set, threshold, method, k) -> list of recalls over runs (image set:
    :func:`image_set`)."""
    out: dict = defaultdict(list)
    for r in rows:
        out[(r["scene"], image_set(r), r["threshold"], r["method"], int(r["k"]))].append(float(r["recall"]))
    return out


def ordered_methods(rows: Sequence[dict]) -> list[str]:
    """The methods of ``rows`` but ``none``, in table order (module docstring)."""
    present = {r["method"] for r in rows if r["method"] != NO_MARKERS}
    ordered = [m for m in PLACEMENT_METHODS if m in present]
    return ordered + sorted(present - set(ordered))


def method_table(rows: Sequence[dict], test_set: str, threshold: str, ks: Sequence[int]) -> str:
    """Markdown table like the paper's Table I for one image set (:func:`image_set`) and threshold.

    Rows: scene (with its no-marker recall in parentheses) x method; columns: k. Cells are
    recall in percent, ``mean ± std`` over runs.
    """
    groups = _group(rows)
    methods = ordered_methods(rows)
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
    """Markdown table of every (scene, test set, [condition,] method, threshold): k = 0 (no
    markers) then ks (the condition column only when some row has one, :func:`has_conditions`)."""
    groups = _group(rows)
    methods = ordered_methods(rows)
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    test_sets = list(dict.fromkeys(image_set(r) for r in rows))
    cond = has_conditions(rows)
    lines = ["| Scene | Test set | " + ("Condition | " if cond else "") + "Method | Threshold | k=0 | "
             + " | ".join(f"k={k}" for k in ks) + " |",
             "|---|---|---|---|---|" + ("---|" if cond else "") + "---|" * len(ks)]
    for scene in scenes:
        for ts in test_sets:
            label = " | ".join(split_set(ts)) if cond else ts
            for m in methods:
                for th in thresholds:
                    base = format_mean_std(groups.get((scene, ts, th, "none", 0), []))
                    cells = [format_mean_std(groups.get((scene, ts, th, m, k), [])) for k in ks]
                    lines.append(f"| {md_text(scene)} | {label} | {md_name(m)} | {th} | {base} | "
                                 + " | ".join(cells) + " |")
    return "\n".join(lines)


def main_tables_markdown(rows: Sequence[dict], ks: Sequence[int], main_threshold: str) -> str:
    """One Table-I-like table per test set (and query condition, when some row has one) at the
    main threshold (what ``evaluate`` prints), then :func:`conditions_table` when there are
    conditions."""
    parts = ["# Localization recall (%)", ""]
    for name in dict.fromkeys(image_set(r) for r in rows):
        ts, cond = split_set(name)
        where = f"`{ts}`" + (f", condition `{cond}`" if has_conditions(rows) else "")
        parts += [f"## Test set {where}, recall at {main_threshold} (mean ± std over runs)", "",
                  method_table(rows, name, main_threshold, ks), ""]
    if has_conditions(rows):
        parts += [f"## Recall per query condition at {main_threshold} (mean ± std over runs)", "",
                  conditions_table(rows, main_threshold, ks), ""]
    return "\n".join(parts)


def conditions_table(rows: Sequence[dict], threshold: str, ks: Sequence[int]) -> str:
    """Markdown table of recall at ``threshold`` per (scene, test set, method, k) row and query
    condition column (no markers at k = 0), to read what each condition costs."""
    groups = _group(rows)
    conds = list(dict.fromkeys(r.get("condition", CLEAN) for r in rows))
    lines = ["| Scene | Test set | Method | k | " + " | ".join(f"`{c}`" for c in conds) + " |",
             "|---|---|---|---|" + "---|" * len(conds)]
    for scene in dict.fromkeys(r["scene"] for r in rows):
        for ts in dict.fromkeys(r["test_set"] for r in rows):
            for m, k in [("none", 0)] + [(m, k) for m in ordered_methods(rows) for k in ks]:
                cells = [format_mean_std(groups.get((scene, set_name(ts, c), threshold, m, k), [])) for c in conds]
                lines.append(f"| {md_text(scene)} | {ts} | {md_name(m)} | {k} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


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
    for m in ordered_methods(rows):
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
