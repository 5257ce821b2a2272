"""Paired comparisons of placements on the same test images, with bootstrap intervals.

Every method is evaluated on the *same* test images, so two recalls are best compared image by
image. For a candidate method ``a`` (one placement) and a baseline ``b`` with runs
``r = 1..R`` (different random / uniform placements), the reported difference is
``recall(a) - mean_r recall(b, r)``.

Its 95 % interval is a two-stage bootstrap: each replicate resamples the test images (keeping
an image's outcomes under every method together: the pairing) and, when ``R >= 2``, also the
baseline runs. It therefore covers both the choice of test images and the spread between
baseline placements, as far as ``R`` runs can show it. With one run the interval covers the
test images only. The cells of a table are not corrected for multiple comparisons.

With query conditions (``evaluate --conditions``), :func:`condition_markdown` compares each
placement under a condition with the *same* placement on the *same* clean images: the per-image
difference of its hits (mean over its runs, run r under the condition against run r clean),
and the tags' gain under the condition (placement minus no markers) against their clean gain.
Those intervals resample the test images only: the placements are fixed, the question is what
the condition does to them.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from markerplace.simulation.conditions import CLEAN, set_name, split_set
from markerplace.simulation.marker_sets import NO_MARKERS, baseline_methods
from markerplace.testbed.reporting.tables import md_name


def bootstrap_difference(own: np.ndarray, base: np.ndarray, n_boot: int = 2000, seed: int = 0,
                         level: float = 0.95) -> tuple[float, float, float]:
    """Mean difference ``own - base`` over images (and base runs) with a bootstrap interval.

    Args:
        own: (n,) per-image outcomes of the candidate (e.g. hits as 0/1).
        base: (R, n) per-image outcomes of the baseline's R runs on the same images.
        n_boot: bootstrap replicates (>= 1).
        seed: seed of ``numpy.random.default_rng``.
        level: two-sided confidence level in (0, 1).

    Returns:
        (difference, low, high): ``mean(own) - mean(base)`` and the percentile interval of the
        replicates, which resample images and, for R >= 2, runs. NaNs for no images.
    """
    if n_boot < 1 or not 0.0 < level < 1.0:
        raise ValueError("n_boot must be >= 1 and level in (0, 1)")
    own = np.asarray(own, dtype=float).reshape(-1)
    base = np.atleast_2d(np.asarray(base, dtype=float))
    if base.shape[1] != own.size:
        raise ValueError("own and base must cover the same test images")
    n, runs = own.size, base.shape[0]
    if n == 0:
        return float("nan"), float("nan"), float("nan")
    rng = np.random.default_rng(seed)
    reps = np.empty(n_boot)
    for b0 in range(0, n_boot, 256):  # bounded memory for large test sets
        nb = min(256, n_boot - b0)
        images = rng.integers(0, n, (nb, n))
        base_means = base[:, images].mean(axis=2)  # (R, nb): each run on the resampled images
        if runs > 1:
            picked = rng.integers(0, runs, (nb, runs))
            base_mean = np.take_along_axis(base_means.T, picked, axis=1).mean(axis=1)
        else:
            base_mean = base_means[0]
        reps[b0:b0 + nb] = own[images].mean(axis=1) - base_mean
    alpha = (1.0 - level) / 2.0
    low, high = np.quantile(reps, [alpha, 1.0 - alpha])
    return float(own.mean() - base.mean()), float(low), float(high)


def paired_differences(hits: Mapping[tuple[str, int, int], np.ndarray], ks: Sequence[int],
                       n_boot: int = 2000, seed: int = 0) -> list[dict]:
    """Every candidate method against every baseline's run mean, per k.

    Args:
        hits: (method, run, k) -> (n,) bool, the test images localized within the threshold;
            all arrays index the same test images. Candidates are the methods other than
            ``none`` and the baselines (the randomized placement methods,
            :func:`~markerplace.simulation.marker_sets.baseline_methods`).
        ks: marker budgets to compare.
        n_boot, seed: bootstrap settings (:func:`bootstrap_difference`).

    Returns:
        One dict per (method, baseline, k) present: ``method, baseline, k, diff, low, high``
        (differences in recall fractions) and ``runs`` (baseline runs averaged).
    """
    baselines = baseline_methods()
    methods = list(dict.fromkeys(m for (m, _, _) in hits if m not in baselines and m != NO_MARKERS))
    out = []
    for method in methods:
        for baseline in baselines:
            for k in ks:
                own = [h for (m, _, kk), h in hits.items() if m == method and kk == k]
                base = [h for (m, _, kk), h in sorted(hits.items(), key=lambda kv: kv[0])
                        if m == baseline and kk == k]
                if len(own) != 1 or not base:
                    continue
                diff, low, high = bootstrap_difference(own[0], np.asarray(base), n_boot, seed)
                out.append(dict(method=method, baseline=baseline, k=int(k), diff=diff, low=low,
                                high=high, runs=len(base)))
    return out


def format_difference(d: dict) -> str:
    """``"+1.3 [-0.7, +3.3]"`` in recall percentage points; bold when the whole interval is above
    zero, italic when it is below zero."""
    text = f"{100 * d['diff']:+.1f} [{100 * d['low']:+.1f}, {100 * d['high']:+.1f}]"
    if d["low"] > 0:
        return f"**{text}**"
    if d["high"] < 0:
        return f"*{text}*"
    return text


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
        lines.append(f"| {md_name(method)} | {md_name(baseline)} "
                     f"({runs} run{'s' if runs != 1 else ''}) | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines)


def fixed_broken(hits: Mapping[tuple[str, int, int], np.ndarray], ks: Sequence[int]) -> list[dict]:
    """Test images each placement fixes and breaks relative to no markers.

    Args:
        hits: (method, run, k) -> (n,) bool hits on the same test images; must hold
            ``("none", 0, 0)``.
        ks: marker budgets.

    Returns:
        One dict per (method, k) present: ``method, k, fixed, broken, runs``: the mean over runs
        of the number of images that fail without markers and succeed with them (``fixed``)
        and the reverse (``broken``). Empty without a ``none`` entry.
    """
    none = hits.get(("none", 0, 0))
    if none is None:
        return []
    out = []
    for method in dict.fromkeys(m for (m, _, _) in hits if m != "none"):
        for k in ks:
            runs = [h for (m, _, kk), h in hits.items() if m == method and kk == k]
            if runs:
                h = np.asarray(runs, dtype=bool)
                out.append(dict(method=method, k=int(k), fixed=float((h & ~none).sum(1).mean()),
                                broken=float((~h & none).sum(1).mean()), runs=len(runs)))
    return out


def fixed_broken_table(rows: Sequence[dict], ks: Sequence[int]) -> str:
    """Markdown table: rows methods, columns k, cells ``+fixed / -broken`` (run means)."""
    lines = ["| Method | " + " | ".join(f"k={k}" for k in ks) + " |", "|---|" + "---|" * len(ks)]
    for method in dict.fromkeys(r["method"] for r in rows):
        cells = []
        for k in ks:
            r = next((r for r in rows if (r["method"], r["k"]) == (method, k)), None)
            digits = 1 if r is not None and r["runs"] > 1 else 0
            cells.append("-" if r is None else f"+{r['fixed']:.{digits}f} / -{r['broken']:.{digits}f}")
        lines.append(f"| {md_name(method)} | " + " | ".join(cells) + " |")
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
        changes = fixed_broken(hits, ks)
        if changes:
            parts += [f"Test images of `{test_set}` fixed / broken by the markers (failing without "
                      "markers and localized with them / the reverse; mean over runs):", "",
                      fixed_broken_table(changes, ks), ""]
    if not parts:
        return ""
    intro = ("Method minus the baseline's mean over runs, on the same test images, in recall "
             "percentage points, with a 95 % bootstrap interval that resamples the test images "
             "(paired) and, with 2 or more runs, the baseline runs. Bold: the whole interval is "
             "above zero; italic: below zero. Cells are not corrected for multiple comparisons.")
    return "\n".join([f"## Paired differences at {threshold_label} (95 % interval)", "", intro, ""]
                     + parts)


def _run_mean(hits: Mapping[tuple[str, int, int], np.ndarray], method: str,
              k: int) -> tuple[list[int], np.ndarray | None]:
    """(runs, (n,) per-image mean over those runs) of ``method`` at ``k`` in ``hits`` (None
    when it has no run there)."""
    runs = sorted(r for (m, r, kk) in hits if m == method and kk == k)
    return runs, np.mean([np.asarray(hits[(method, r, k)], float) for r in runs], axis=0) if runs else None


def condition_differences(hits_by_set: Mapping[str, Mapping[tuple[str, int, int], np.ndarray]],
                          n_boot: int = 2000, seed: int = 0) -> list[dict]:
    """Every placement under each query condition against itself on the clean images.

    Args:
        hits_by_set: image set name (``weighted``, ``weighted@blur``:
            :func:`~markerplace.simulation.conditions.set_name`) -> (method, run, k) -> (n,) bool hits
            at the threshold; a condition's set holds the same test images as its clean set.
        n_boot, seed: bootstrap settings (:func:`bootstrap_difference`).

    Returns:
        One dict per (test set, condition other than clean, method, k) whose runs are present
        both ways: ``test_set, condition, method, k, runs`` and two differences in recall
        fractions, each with its 95 % interval over the test images: ``diff, diff_low, diff_high``
        (recall under the condition minus clean recall, run by run) and, for placements with
        markers, ``gain, gain_low, gain_high`` (the gain over no markers under the condition
        minus the clean gain; NaN for no markers or where no markers is missing).
    """
    out = []
    for name, hits in hits_by_set.items():
        test_set, condition = split_set(name)
        clean = hits_by_set.get(set_name(test_set, CLEAN))
        if condition == CLEAN or clean is None:
            continue
        for method, k in dict.fromkeys((m, kk) for (m, _, kk) in hits):
            runs, under = _run_mean(hits, method, k)
            clean_runs, before = _run_mean(clean, method, k)
            if runs != clean_runs:
                continue
            zero = np.zeros((1, under.size))
            diff, low, high = bootstrap_difference(under - before, zero, n_boot, seed)
            gain = (float("nan"),) * 3
            none_key = (NO_MARKERS, 0, 0)
            if method != NO_MARKERS and none_key in hits and none_key in clean:
                change = (under - np.asarray(hits[none_key], float)) - (before - np.asarray(clean[none_key], float))
                gain = bootstrap_difference(change, zero, n_boot, seed)
            out.append(dict(test_set=test_set, condition=condition, method=method, k=int(k), runs=len(runs),
                            diff=diff, diff_low=low, diff_high=high,
                            gain=gain[0], gain_low=gain[1], gain_high=gain[2]))
    return out


def condition_table(diffs: Sequence[dict], key: str) -> str:
    """Markdown table of one test set's :func:`condition_differences`: rows (method, k), columns
    conditions, cells :func:`format_difference` of ``key`` (``diff`` or ``gain``); rows whose
    cells are all NaN are left out."""
    conditions = list(dict.fromkeys(d["condition"] for d in diffs))
    lines = ["| Method | k | " + " | ".join(f"`{c}`" for c in conditions) + " |",
             "|---|---|" + "---|" * len(conditions)]
    for method, k in dict.fromkeys((d["method"], d["k"]) for d in diffs):
        cells = []
        for c in conditions:
            d = next((d for d in diffs if (d["method"], d["k"], d["condition"]) == (method, k, c)), None)
            ok = d is not None and not np.isnan(d[key])
            cells.append(format_difference(dict(diff=d[key], low=d[f"{key}_low"], high=d[f"{key}_high"]))
                         if ok else "-")
        if any(c != "-" for c in cells):
            runs = max(d["runs"] for d in diffs if (d["method"], d["k"]) == (method, k))
            label = md_name(method) + (f" ({runs} runs)" if runs > 1 else "")
            lines.append(f"| {label} | {k} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def condition_markdown(hits_by_set: Mapping[str, Mapping[tuple[str, int, int], np.ndarray]],
                       threshold_label: str, n_boot: int = 2000, seed: int = 0) -> str:
    """The ``tables.md`` section "Query conditions against clean" ("" without a non-clean
    condition): per test set, what each condition costs every placement (its recall under the
    condition minus its clean recall), then what it does to the tags' gain over no markers.

    Args:
        hits_by_set: as :func:`condition_differences`.
        threshold_label: e.g. ``5cm/5deg``, for the heading.
        n_boot, seed: bootstrap settings.
    """
    diffs = condition_differences(hits_by_set, n_boot, seed)
    if not diffs:
        return ""
    parts = [f"## Query conditions against clean, paired, at {threshold_label} (95 % interval)", "",
             "Each placement under a condition minus the same placement on the same clean test images "
             "(run by run, then the mean over runs), in recall percentage points; the interval resamples "
             "the test images. Bold: the whole interval is above zero; italic: below zero. Not corrected "
             "for multiple comparisons.", ""]
    for test_set in dict.fromkeys(d["test_set"] for d in diffs):
        mine = [d for d in diffs if d["test_set"] == test_set]
        parts += [f"### Test set `{test_set}`: recall under the condition minus clean recall", "",
                  condition_table(mine, "diff"), ""]
        if any(not np.isnan(d["gain"]) for d in mine):
            parts += [f"### Test set `{test_set}`: the tags' gain over no markers under the condition "
                      "minus their clean gain", "", condition_table(mine, "gain"), ""]
    return "\n".join(parts)
