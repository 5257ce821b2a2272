"""Outputs of the real-photograph testbed: recall rows, ``tables.md`` and the gap table.

An image set is ``<queries>@<map>``: ``real@frames`` (real query photographs against a map of
real photographs: the paper's real experiment), ``real@render`` (real queries against renders of
the fused surface: what a plan made from a scan assumes) and ``render@render`` (queries rendered
from the fused surface at the same poses against that rendered map: the simulation). The gap
table sets ``render@render`` against ``real@render`` per placement: the same query poses, the
same map, drawn against photographed, so the simulation's error is a number with a paired
interval over the query frames.

The tables are the simulation testbed's (:mod:`markerplace.testbed.reporting`): recall per
method and k (mean ± std over runs), and each method against the baselines' run mean with a
paired 95 % bootstrap interval.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from markerplace.simulation import metrics
from markerplace.simulation.marker_sets import NO_MARKERS
from markerplace.testbed.reporting.paired import bootstrap_difference, format_difference, paired_markdown
from markerplace.testbed.reporting.tables import display_name, method_table, thresholds_table

__all__ = ["set_label", "recall_rows", "gap_rows", "gap_table", "frames_markdown"]

SET_TITLES = {"real@frames": "real queries, map of real frames (the paper's real experiment)",
              "real@render": "real queries, map rendered from the fused surface (what a plan from a scan assumes)",
              "render@render": "queries rendered from the fused surface, rendered map (the simulation)"}


def set_label(query_kind: str, map_kind: str) -> str:
    """``<queries>@<map>``, e.g. ``real@frames``."""
    return f"{query_kind}@{map_kind}"


def recall_rows(name: str, errors: Mapping[tuple, tuple[np.ndarray, np.ndarray]],
                thresholds: Sequence[tuple[float, float]]) -> list[dict]:
    """Recall rows as the simulation testbed writes them (``recall.csv``).

    Args:
        name: the sequence's label (the tables' scene column).
        errors: (method, run, k, image set) -> ((Q,) metres, (Q,) degrees), ``inf`` for failures.
        thresholds: (metres, degrees) pairs.
    """
    rows = []
    for (method, run, k, image_set), (t_err, r_err) in errors.items():
        for t_max, r_max in thresholds:
            rows.append(dict(scene=name, method=method, run=int(run), k=int(k), test_set=image_set, condition="clean",
                             threshold=metrics.threshold_label((t_max, r_max)),
                             recall=metrics.recall(t_err, r_err, t_max, r_max), n_tests=len(t_err)))
    return rows


def gap_rows(hits: Mapping[str, Mapping[tuple[str, int, int], np.ndarray]], seed: int = 0) -> list[dict]:
    """Per (method, k): recall of ``render@render`` and ``real@render`` (mean over runs), and
    their difference (simulated minus real) with a paired 95 % bootstrap interval over the
    query frames (and the runs); also ``real@frames`` when present.

    Args:
        hits: image set -> (method, run, k) -> (Q,) bool hits at one threshold.
    """
    sim, real, frames = hits.get("render@render", {}), hits.get("real@render", {}), hits.get("real@frames", {})
    out = []
    for method, k in dict.fromkeys((m, k) for (m, _, k) in sim):
        runs = sorted(r for (m, r, kk) in sim if (m, kk) == (method, k) and (m, r, kk) in real)
        if not runs:
            continue
        own = np.mean([sim[(method, r, k)] for r in runs], axis=0)
        base = np.array([real[(method, r, k)] for r in runs], float)
        diff, low, high = bootstrap_difference(own, base, seed=seed)
        fr = [frames[(method, r, k)].mean() for r in runs if (method, r, k) in frames]
        out.append(dict(method=method, k=int(k), runs=len(runs), simulated=float(own.mean()),
                        real=float(base.mean()), real_frames_map=float(np.mean(fr)) if fr else float("nan"),
                        diff=diff, low=low, high=high))
    return out


def gap_table(rows: Sequence[dict]) -> str:
    """Markdown: one row per (method, k) of :func:`gap_rows`."""
    lines = ["| Method | k | runs | simulated (render@render) | real (real@render) | simulated - real, points "
             "[95 %] | real@frames |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        frames = "-" if not np.isfinite(r["real_frames_map"]) else f"{100 * r['real_frames_map']:.1f}"
        lines.append(f"| {display_name(r['method'])} | {r['k']} | {r['runs']} | {100 * r['simulated']:.1f} | "
                     f"{100 * r['real']:.1f} | {format_difference(r)} | {frames} |")
    return "\n".join(lines)


def frames_markdown(name: str, rows: Sequence[dict], hits: Mapping[str, Mapping[tuple, np.ndarray]],
                    hits_loose: Mapping[str, Mapping[tuple, np.ndarray]], ks: Sequence[int], main: str, loose: str,
                    labels: Sequence[str], header: Sequence[str], seed: int = 0) -> str:
    """The whole ``tables.md``: what was run (``header`` lines), per image set the recall table
    at the main and the loose threshold and the paired differences, then the gap table."""
    parts = [f"# Real frames: {name}", "", *header, ""]
    for image_set in hits:
        parts += [f"## `{image_set}`: {SET_TITLES.get(image_set, image_set)}", ""]
        for label in (main, loose):
            sub = [r for r in rows if r["test_set"] == image_set]
            parts += [f"Recall at {label} (%):", "", method_table(sub, image_set, label, ks), ""]
        parts.append(paired_markdown({image_set: hits[image_set]}, ks, main, seed=seed).replace("## ", "### "))
        parts.append(paired_markdown({image_set: hits_loose[image_set]}, ks, loose, seed=seed).replace("## ", "### "))
    gap = gap_rows(hits, seed)
    if gap:
        parts += [f"## The simulation's error (gap table) at {main}", "",
                  "The same query poses and the same rendered map; the queries drawn by the renderer from the fused "
                  "surface (tags drawn) against the real photographs (tags composited). Positive: the simulation "
                  "is optimistic. Interval: paired bootstrap over the query frames (and runs).", "",
                  gap_table(gap), ""]
        gap_l = gap_rows(hits_loose, seed)
        parts += [f"At {loose}:", "", gap_table(gap_l), ""]
    parts += ["## Every threshold", "", thresholds_table(rows, list(labels), ks), ""]
    return "\n".join(parts)


def no_marker_first(keys: Sequence[tuple]) -> list[tuple]:
    """(method, run, k) keys with ``none`` first (report order)."""
    return sorted(keys, key=lambda t: (t[0] != NO_MARKERS, t))
