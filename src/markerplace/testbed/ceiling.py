"""The oracle ceiling: how much better could any k-tag placement do on these test images?

A diagnostic, never a placement method: it looks at the test images themselves.

1. Every candidate is evaluated alone (``single`` placements, one tag each, on every test set)
   with the testbed's usual machinery: a test image "is fixed by candidate c" when it localizes
   (main threshold) with c's tag alone.
2. Per test set, a greedy maximum coverage picks k candidates: each round the one that fixes
   the most test images not localized yet (by no markers or an earlier pick), ties to the
   smallest index; once no candidate adds any, the rest follow in index order. The picks are
   nested in k. Single-tag outcomes ignore how tags interact (two tags in one view, a new tag
   changing another image's retrieval), so the picks are then **evaluated as a real placement**
   (``ceiling``, on that test set only); that recall is the ceiling reported, with the
   single-tag estimate beside it.
3. :func:`ceiling_markdown` sets every method against it: OMP's share of the achievable gain
   ``(method - random) / (ceiling - random)`` says whether a scene and k leave room for any
   method to beat the random baseline.
"""

from __future__ import annotations

import logging
from typing import Sequence

import numpy as np

from ..markers import FAMILY, Marker
from .metrics import MAIN_THRESHOLD, hit_mask, pose_errors_batch
from .placements import NO_MARKERS, RESERVED_NAMES, PlacementRun

log = logging.getLogger(__name__)

__all__ = ["SINGLE", "CEILING", "single_placements", "oracle_order", "ceiling_placements", "ceiling_markdown"]

SINGLE, CEILING = RESERVED_NAMES
"""Method names of the one-tag placements (run = candidate index) and of the oracle placements."""


def single_placements(candidate_world_from_marker: np.ndarray, tag_size: float) -> list[PlacementRun]:
    """One placement per candidate with its tag alone (tag id 0; run = candidate index)."""
    return [PlacementRun(SINGLE, c, 1, (Marker(0, tag_size, np.asarray(T, float).copy(), FAMILY),))
            for c, T in enumerate(candidate_world_from_marker)]


def oracle_order(base_hit: np.ndarray, single_hits: np.ndarray, k: int) -> tuple[list[int], list[int]]:
    """Greedy maximum coverage of the test images.

    Args:
        base_hit: (Q,) bool, localized without markers.
        single_hits: (C, Q) bool, localized with candidate c alone.
        k: picks, at most C.

    Returns:
        (k,) candidate indices in pick order and (k,) images each pick newly covers.
    """
    covered = np.asarray(base_hit, bool).copy()
    hits = np.asarray(single_hits, bool)
    C = hits.shape[0]
    remaining = np.ones(C, bool)
    order, gains = [], []
    for _ in range(min(int(k), C)):
        gain = np.where(remaining, (hits & ~covered[None, :]).sum(axis=1), -1)
        m = int(np.argmax(gain))  # first maximum: the smallest index among ties
        order.append(m)
        gains.append(int(gain[m]))
        remaining[m] = False
        covered |= hits[m]
    return order, gains


def _hits(predictions: dict, key: tuple, truth: np.ndarray, threshold) -> np.ndarray:
    return hit_mask(*pose_errors_batch(predictions[key], truth), *threshold)


def ceiling_placements(candidate_world_from_marker: np.ndarray, tag_size: float, predictions: dict,
                       test_poses: dict, ks: Sequence[int], threshold=MAIN_THRESHOLD) -> tuple[list, dict]:
    """The oracle placements of every test set and k, from the single-tag predictions.

    Args:
        candidate_world_from_marker: (C, 4, 4) candidate poses.
        tag_size: black-square edge, metres.
        predictions: holds ``(none, 0, 0, set)`` and ``(single, c, 1, set)`` for every c.
        test_poses: test set -> :class:`~markerplace.testbed.poses.TestPoses`.
        ks: marker budgets.
        threshold: (metres, degrees) of a success.

    Returns:
        the :class:`PlacementRun` list (``ceiling``, k, that test set only) and, per test set,
        the single-tag estimate: k -> images localized by no markers or a pick alone.
    """
    C = len(candidate_world_from_marker)
    runs, estimate = [], {}
    kmax = min(max(ks), C)
    for ts, tp in test_poses.items():
        truth = tp.world_from_cam
        base = _hits(predictions, (NO_MARKERS, 0, 0, ts), truth, threshold)
        singles = np.stack([_hits(predictions, (SINGLE, c, 1, ts), truth, threshold) for c in range(C)]) \
            if C else np.zeros((0, len(truth)), bool)
        order, gains = oracle_order(base, singles, kmax)
        estimate[ts] = {k: int(base.sum() + sum(gains[:k])) for k in ks if k <= kmax}
        log.info("ceiling %s: single-tag greedy picks %s fix %s of %d images that fail without markers", ts,
                 order, gains, int((~base).sum()))
        markers = [Marker(i, tag_size, np.asarray(candidate_world_from_marker[c], float).copy(), FAMILY)
                   for i, c in enumerate(order)]
        for k in sorted(set(ks)):
            if k <= kmax:
                runs.append(PlacementRun(CEILING, 0, k, tuple(markers[:k]), test_sets=(ts,)))
    return runs, estimate


def ceiling_markdown(rows: list[dict], estimate: dict, ks: Sequence[int], threshold_label: str) -> str:
    """``ceiling.md``: per test set and k, the ceiling (evaluated, and the single-tag estimate),
    every method's recall and its share of the achievable gain over the random mean."""
    from .placements import baseline_methods

    def recall(ts, method, k):
        vals = [r["recall"] for r in rows if r["test_set"] == ts and r["method"] == method and r["k"] == k
                and r["threshold"] == threshold_label]
        return float(np.mean(vals)) * 100 if vals else float("nan")

    methods = [m for m in dict.fromkeys(r["method"] for r in rows) if m not in (NO_MARKERS, CEILING, SINGLE)]
    lines = [f"# Oracle ceiling: recall at {threshold_label} (%)", "",
             "`ceiling`: k candidates picked greedily to localize the most test images (from each candidate's "
             "single-tag outcomes on these test images, so only a ceiling, never a method), then evaluated as a "
             "placement; `estimate`: the images localized by no markers or one of the picks alone. Randomized "
             "methods: mean over runs. Share = (method - random) / (ceiling - random): the part of the achievable "
             "gain over random placement that a method realizes.", ""]
    for ts, est in estimate.items():
        n = next((r["n_tests"] for r in rows if r["test_set"] == ts), 0)
        none = recall(ts, NO_MARKERS, 0)
        lines += [f"## {ts} test set ({n} images, no markers {none:.1f})", "",
                  "| | " + " | ".join(f"k = {k}" for k in ks) + " |", "|---|" + "---|" * len(ks)]
        ceil = [recall(ts, CEILING, k) for k in ks]
        lines.append("| ceiling (evaluated) | " + " | ".join(f"{v:.1f}" for v in ceil) + " |")
        lines.append("| ceiling (single-tag estimate) | " + " | ".join(
            f"{100 * est[k] / n:.1f}" if k in est and n else "-" for k in ks) + " |")
        rand = [recall(ts, "random", k) for k in ks] if "random" in methods else [float("nan")] * len(ks)
        for m in methods:
            vals = [recall(ts, m, k) for k in ks]
            lines.append(f"| {m}{' (mean)' if m in baseline_methods() else ''} | " + " | ".join(f"{v:.1f}" for v in vals) + " |")
        for m in methods:
            if m == "random":
                continue
            share = []
            for v, r, c in zip((recall(ts, m, k) for k in ks), rand, ceil):
                room = c - r
                share.append(f"{(v - r) / room:+.2f}" if np.isfinite(room) and room > 0 and np.isfinite(v) else "-")
            lines.append(f"| share of {m} | " + " | ".join(share) + " |")
        lines.append("")
    return "\n".join(lines)
