"""Paired comparisons of placements on the same test images (is a lead real or noise?).

Every method is evaluated on the *same* test images, so the difference of two recalls is best
judged image by image: for a method ``a`` and a baseline ``b`` with runs ``r = 1..R``, the
per-image difference is ``d_i = hit_a[i] - mean_r hit_b,r[i]``; its mean is exactly
``recall(a) - mean_r recall(b, r)``. The 95 % interval comes from a paired bootstrap over test
images (resampling images, keeping each image's outcomes under every method together).

The interval covers the sampling of test images only: the spread between baseline runs
(different random / uniform placements) is what the ``± std`` of the recall tables shows.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from .tables import display_name

#: Methods that are baselines (several seeded runs) rather than candidates.
BASELINES = ("random", "uniform")


def bootstrap_mean_ci(diff: np.ndarray, n_boot: int = 2000, seed: int = 0,
                      level: float = 0.95) -> tuple[float, float, float]:
    """Mean of ``diff`` and its percentile-bootstrap confidence interval.

    Args:
        diff: (n,) per-image differences (any real values).
        n_boot: bootstrap resamples.
        seed: seed of ``numpy.random.default_rng``.
        level: confidence level of the two-sided interval.

    Returns:
        (mean, low, high); NaNs for an empty input.
    """
    diff = np.asarray(diff, dtype=float).reshape(-1)
    if diff.size == 0:
        return float("nan"), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    means = np.empty(n_boot)
    for b0 in range(0, n_boot, 256):  # bounded memory for large test sets
        nb = min(256, n_boot - b0)
        means[b0:b0 + nb] = diff[rng.integers(0, diff.size, (nb, diff.size))].mean(axis=1)
    alpha = (1.0 - level) / 2.0
    low, high = np.quantile(means, [alpha, 1.0 - alpha])
    return float(diff.mean()), float(low), float(high)


def paired_differences(hits: Mapping[tuple[str, int, int], np.ndarray], ks: Sequence[int],
                       n_boot: int = 2000, seed: int = 0) -> list[dict]:
    """Every candidate method against every baseline's run mean, per k.

    Args:
        hits: (method, run, k) -> (n,) bool, the test images localized within the threshold;
            all arrays index the same test images.
        ks: marker budgets to compare.
        n_boot, seed: bootstrap settings (:func:`bootstrap_mean_ci`).

    Returns:
        One dict per (method, baseline, k) present: ``method, baseline, k, diff, low, high``
        (differences in recall fractions) and ``runs`` (baseline runs averaged).
    """
    methods = list(dict.fromkeys(m for (m, _, _) in hits if m not in BASELINES and m != "none"))
    out = []
    for method in methods:
        for baseline in BASELINES:
            for k in ks:
                own = [h for (m, _, kk), h in hits.items() if m == method and kk == k]
                base = [h for (m, _, kk), h in hits.items() if m == baseline and kk == k]
                if len(own) != 1 or not base:
                    continue
                diff = own[0].astype(float) - np.mean(np.asarray(base, dtype=float), axis=0)
                mean, low, high = bootstrap_mean_ci(diff, n_boot, seed)
                out.append(dict(method=method, baseline=baseline, k=int(k), diff=mean, low=low,
                                high=high, runs=len(base)))
    return out


def format_difference(d: dict) -> str:
    """``"+1.3 [-0.7, +3.3]"`` in recall percentage points; bold when the interval is above 0."""
    text = f"{100 * d['diff']:+.1f} [{100 * d['low']:+.1f}, {100 * d['high']:+.1f}]"
    return f"**{text}**" if d["low"] > 0 else text


def paired_table(diffs: Sequence[dict], ks: Sequence[int]) -> str:
    """Markdown table: rows method x baseline, columns k, cells :func:`format_difference`."""
    lines = ["| Method | vs. baseline mean | " + " | ".join(f"k={k}" for k in ks) + " |",
             "|---|---|" + "---|" * len(ks)]
    pairs = list(dict.fromkeys((d["method"], d["baseline"]) for d in diffs))
    for method, baseline in pairs:
        cells = []
        for k in ks:
            found = [d for d in diffs if (d["method"], d["baseline"], d["k"]) == (method, baseline, k)]
            cells.append(format_difference(found[0]) if found else "-")
        runs = max(d["runs"] for d in diffs if (d["method"], d["baseline"]) == (method, baseline))
        lines.append(f"| {display_name(method)} | {display_name(baseline)} ({runs} run{'s' if runs != 1 else ''}) | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def paired_markdown(hits_by_test_set: Mapping[str, Mapping[tuple[str, int, int], np.ndarray]],
                    ks: Sequence[int], threshold_label: str, n_boot: int = 2000, seed: int = 0) -> str:
    """The ``tables.md`` section of paired differences, one table per test set ("" if none).

    Args:
        hits_by_test_set: test set -> (method, run, k) -> (n,) bool hits at the threshold.
        ks: marker budgets (columns).
        threshold_label: e.g. ``5cm/5deg``, for the heading.
        n_boot, seed: bootstrap settings.
    """
    parts = []
    for test_set, hits in hits_by_test_set.items():
        diffs = paired_differences(hits, ks, n_boot, seed)
        if diffs:
            parts += [f"### Test set `{test_set}`", "", paired_table(diffs, ks), ""]
    if not parts:
        return ""
    intro = ("Method minus the baseline's mean over runs, on the same test images, in recall "
             "percentage points; the interval is a paired bootstrap over test images (bold: "
             "the whole interval is above zero). It does not include the spread between "
             "baseline runs (the tables' ± std).")
    return "\n".join([f"## Paired differences at {threshold_label} (95 % interval)", "", intro, ""]
                     + parts)
