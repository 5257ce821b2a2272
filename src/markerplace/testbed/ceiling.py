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
4. Because the picks are made on the images they are scored on, part of the ceiling's lead is
   selection (a candidate that happens to fix many of these images is picked because it did).
   :func:`held_out_gains` measures it from the same single-tag outcomes: picks made on a random
   half of the test images are scored on the other half, beside picks made on that half itself
   and random k-subsets of candidates (``ceiling.md``'s held-out rows).
"""

from __future__ import annotations

import logging
from typing import Sequence

import numpy as np

from markerplace.markers import FAMILY, Marker
from markerplace.simulation.marker_sets import NO_MARKERS, RESERVED_NAMES, PlacementRun, baseline_methods, with_candidate_ids
from markerplace.simulation.metrics import MAIN_THRESHOLD, hit_mask, pose_errors_batch
from markerplace.simulation.placement_localization import PredictContext, predict_placements
from markerplace.simulation.success_fit import MAP_SET

log = logging.getLogger(__name__)

__all__ = ["SINGLE", "CEILING", "single_placements", "oracle_order", "ceiling_placements", "ceiling_markdown",
           "single_tag_hits", "single_tag_outcomes", "covered", "held_out_gains", "held_out_estimate", "run_ceiling"]

SINGLE, CEILING = RESERVED_NAMES
"""Method names of the one-tag placements (run = candidate index) and of the oracle placements."""
HELD_OUT_SPLITS = 100
"""Random half splits of the test images behind ``ceiling.md``'s held-out rows."""
HELD_OUT_DRAWS = 100
"""Random k-subsets of candidates per split (the random reference of the held-out rows)."""


def single_placements(candidate_world_from_marker: np.ndarray, tag_size: float) -> list[PlacementRun]:
    """One placement per candidate with its tag alone (tag id 0; run = candidate index).

    Args:
        candidate_world_from_marker: (C, 4, 4) candidate marker poses, world frame, metres.
        tag_size: black-square edge, metres.

    Returns:
        C ``single`` placements of k = 1, in candidate order.
    """
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
    localized = np.asarray(base_hit, bool).copy()
    hits = np.asarray(single_hits, bool)
    C = hits.shape[0]
    remaining = np.ones(C, bool)
    order, gains = [], []
    for _ in range(min(int(k), C)):
        gain = np.where(remaining, (hits & ~localized[None, :]).sum(axis=1), -1)
        m = int(np.argmax(gain))  # first maximum: the smallest index among ties
        order.append(m)
        gains.append(int(gain[m]))
        remaining[m] = False
        localized |= hits[m]
    return order, gains


def _hits(predictions: dict, key: tuple, truth: np.ndarray, threshold) -> np.ndarray:
    return hit_mask(*pose_errors_batch(predictions[key], truth), *threshold)


def single_tag_hits(predictions: dict, truth: np.ndarray, test_set: str, C: int,
                    threshold=MAIN_THRESHOLD) -> tuple[np.ndarray, np.ndarray]:
    """(Q,) bool localized without markers and (C, Q) bool localized with candidate c alone.

    Args:
        predictions: ``(method, run, k, test set)`` -> (Q, 4, 4) estimates; holds the marker-free
            and every single-tag run of ``test_set``.
        truth: (Q, 4, 4) true ``world_from_cam`` of the test images.
        test_set: the test set's name (the fourth element of the keys).
        C: candidates.
        threshold: (metres, degrees) a test image's errors must be within to count as localized.
    """
    base = _hits(predictions, (NO_MARKERS, 0, 0, test_set), truth, threshold)
    singles = np.stack([_hits(predictions, (SINGLE, c, 1, test_set), truth, threshold) for c in range(C)]) \
        if C else np.zeros((0, len(truth)), bool)
    return base, singles


def covered(base: np.ndarray, hits: np.ndarray, picks) -> int:
    """Images localized by no markers (``base``, (Q,) bool) or one of ``picks`` alone (rows of
    ``hits``, (C, Q) bool)."""
    picks = list(picks)
    return int((base | hits[picks].any(axis=0)).sum()) if picks else int(base.sum())


def held_out_gains(base: np.ndarray, hits: np.ndarray, k: int, rng: np.random.Generator,
                   train_fraction: float = 0.5, splits: int = HELD_OUT_SPLITS,
                   draws: int = HELD_OUT_DRAWS) -> tuple[float, float, float]:
    """How much of the ceiling's lead is selection on the test images.

    Over ``splits`` random splits of the Q images, the greedy picks (:func:`oracle_order`)
    made on a ``train_fraction`` share are scored on the rest (held out), beside the picks
    made on the scored part itself (in sample, as the ceiling is) and ``draws`` random
    k-subsets of candidates, all as single-tag estimates (:func:`covered`).

    Args:
        base: (Q,) bool, localized without markers; Q >= 2.
        hits: (C, Q) bool, localized with candidate c alone.
        k: picks (at most C).
        rng: the random splits and subsets.
        train_fraction: share of the Q images the held-out picks are made on (the rest, at least
            one image, are scored; at least one image is picked on).
        splits: random splits.
        draws: random k-subsets of candidates per split.

    Returns:
        mean gains over no markers, as shares of the scored images: (in sample, held out, random).
    """
    C, Q = hits.shape
    k = min(int(k), C)
    n_train = min(max(int(round(train_fraction * Q)), 1), Q - 1)
    if n_train < 1:
        raise ValueError(f"held-out gains need at least 2 test images, got {Q}")
    in_sample, held_out, random_gain = [], [], []
    for _ in range(splits):
        train = np.zeros(Q, bool)
        train[rng.permutation(Q)[:n_train]] = True
        scored = ~train
        n_scored, base_scored = int(scored.sum()), int(base[scored].sum())
        base_s, hits_s = base[scored], hits[:, scored]
        picks_train, _ = oracle_order(base[train], hits[:, train], k)
        picks_scored, _ = oracle_order(base_s, hits_s, k)
        in_sample.append((covered(base_s, hits_s, picks_scored) - base_scored) / n_scored)
        held_out.append((covered(base_s, hits_s, picks_train) - base_scored) / n_scored)
        random_gain.append(np.mean([covered(base_s, hits_s, rng.choice(C, k, replace=False)) - base_scored
                                    for _ in range(draws)]) / n_scored)
    return float(np.mean(in_sample)), float(np.mean(held_out)), float(np.mean(random_gain))


def single_tag_outcomes(predictions: dict, test_poses: dict, C: int, threshold=MAIN_THRESHOLD) -> dict:
    """:func:`single_tag_hits` of every test set (test set -> :class:`~markerplace.simulation.pose_sampling.TestPoses`):
    test set -> ((Q,) bool without markers, (C, Q) bool with candidate c alone)."""
    return {ts: single_tag_hits(predictions, tp.world_from_cam, ts, C, threshold) for ts, tp in test_poses.items()}


def held_out_estimate(outcomes: dict, ks: Sequence[int], seed: int) -> dict:
    """:func:`held_out_gains` of every test set and k (k <= the candidates), as recall points.

    Args:
        outcomes: :func:`single_tag_outcomes`.
        ks: marker budgets; those above the candidates are left out.
        seed: seed of the splits and random subsets (one stream over the test sets and ks in order).

    Returns:
        test set -> k -> (in sample, held out, random) gains over no markers, points; test sets
        with fewer than 2 images or no candidates are left out.
    """
    rng = np.random.default_rng(seed)
    out = {}
    for ts, (base, singles) in outcomes.items():
        C = len(singles)
        if len(base) < 2 or C == 0:
            continue
        out[ts] = {k: tuple(100 * v for v in held_out_gains(base, singles, k, rng)) for k in sorted(set(ks)) if k <= C}
    return out


def ceiling_placements(candidate_world_from_marker: np.ndarray, tag_size: float, outcomes: dict,
                       ks: Sequence[int]) -> tuple[list, dict]:
    """The oracle placements of every test set and k, from the single-tag outcomes.

    Args:
        candidate_world_from_marker: (C, 4, 4) candidate poses.
        tag_size: black-square edge, metres.
        outcomes: :func:`single_tag_outcomes` (every test set).
        ks: marker budgets.

    Returns:
        the :class:`PlacementRun` list (``ceiling``, k, that test set only) and, per test set,
        the single-tag estimate: k -> images localized by no markers or a pick alone.
    """
    C = len(candidate_world_from_marker)
    runs, estimate = [], {}
    kmax = min(max(ks), C)
    for ts, (base, singles) in outcomes.items():
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


def ceiling_markdown(rows: list[dict], estimate: dict, ks: Sequence[int], threshold_label: str,
                     held_out: dict | None = None) -> str:
    """``ceiling.md``: per test set and k, the ceiling (evaluated, and the single-tag estimate),
    every method's recall and its share of the achievable gain over the random mean; with
    ``held_out`` the ceiling's lead over random subsets picked in sample and held out.

    Args:
        rows: the evaluation's recall rows (``test_set``, ``method``, ``k``, ``threshold``,
            ``recall`` in [0, 1], ``n_tests``), as :func:`~markerplace.testbed.reporting.summary.write_outputs` returns.
        estimate: test set -> k -> images localized by no markers or one pick alone
            (:func:`ceiling_placements`).
        ks: marker budgets (columns).
        threshold_label: the recall threshold the table reports (e.g. ``5cm/5deg``).
        held_out: :func:`held_out_estimate`, or None to leave its rows out.
    """
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
    if held_out:
        lines += ["`held out`: the picks are made on the images they are scored on, so part of the ceiling's "
                  "lead is selection. Over random half splits of the test images, greedy picks made on one half "
                  "and scored on the other, against picks made on the scored half itself (`in sample`); both as "
                  "single-tag estimates, in points over random k-subsets of candidates. Where `held out` is far "
                  "below `in sample`, the shares understate the methods.", ""]
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
        if held_out and ts in held_out:
            gains = held_out[ts]
            for label, i in (("in sample", 0), ("held out", 1)):
                lines.append(f"| ceiling over random subsets, {label} | " + " | ".join(
                    f"{gains[k][i] - gains[k][2]:+.1f}" if k in gains else "-" for k in ks) + " |")
        lines.append("")
    return "\n".join(lines)


def run_ceiling(ctx: PredictContext, placements: list, singles: list, sets: dict, test_poses: dict,
                candidate_world_from_marker: np.ndarray, tag_size: float, ks: Sequence[int], seed: int,
                threshold, by_spot: bool) -> tuple[list, dict, dict, dict]:
    """The oracle ceiling of an evaluation: every candidate alone on the test images, then the
    oracle's greedy picks per k evaluated as placements.

    Args:
        placements: the evaluated placements, the marker-free one first; ``singles`` one per
            candidate (:func:`single_placements`).
        sets: image sets by name (the map's own set is left out here).
        by_spot: tag codes by candidate spot (``--tag-ids candidate``).

    Returns:
        (the ceiling placements, their predictions and the singles', the greedy estimate
        per k, the held-out estimate per k).
    """
    test_sets = {name: s for name, s in sets.items() if name != MAP_SET}
    predictions = predict_placements(ctx, placements[:1] + singles, test_sets)
    outcomes = single_tag_outcomes(predictions, test_poses, len(candidate_world_from_marker), threshold)
    ceiling_runs, estimate = ceiling_placements(candidate_world_from_marker, tag_size, outcomes, ks)
    held_out = held_out_estimate(outcomes, ks, seed)
    if by_spot:
        ceiling_runs = with_candidate_ids(ceiling_runs, candidate_world_from_marker)
    predictions.update(predict_placements(ctx, placements[:1] + ceiling_runs, test_sets))
    return ceiling_runs, predictions, estimate, held_out
