"""How much of the oracle ceiling is chosen on the test images themselves? (held-out ceiling)

The oracle ceiling (``evaluate --ceiling``, :mod:`markerplace.testbed.ceiling`) picks its k
candidates greedily on the same test images it is scored on, so part of its lead over random
is selection on those images (a candidate that happens to fix 12 of them is picked because
it did). This splits the test images in halves at random: the greedy picks made on one half
are scored on the other (held out) and set against the picks made on that half itself (in
sample, as the ceiling is) and against random k-subsets of candidates, all in the ceiling's
single-tag estimate (an image counts as localized when no markers or one pick alone localize
it). ``--train-fraction`` sets the share of the images the held-out picks are made on (the
rest are scored); a held-out gain that grows with it says more images would find better
picks. The gap between the in-sample and the held-out figure is the part of the ceiling that
no method planned without the test images could reach, whatever its objective. The computation is
:func:`markerplace.testbed.ceiling.held_out_gains` (``ceiling.md`` carries it with half splits);
this script reads an existing run's cache and varies the splits.

Reads the ``single`` and ``none`` predictions cached by an ``evaluate --ceiling`` run and
prints ``name: value`` lines (recall points over no markers of the scored part; means over
the splits; ``all_images_ceiling_over_random``: the ceiling's own single-tag estimate, picks
made and scored on every image, over random subsets):

    .venv/bin/python benchmarks/ceiling_holdout.py out/eval_apartment --test-set weighted --k 10,20
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from markerplace.plan.discretize import artifact as discretization
from markerplace.simulation.marker_sets import NO_MARKERS
from markerplace.simulation.pose_sampling import TestPoses
from markerplace.simulation.prediction_store import load_prediction
from markerplace.testbed.ceiling import SINGLE, covered, held_out_gains, oracle_order, single_tag_hits


def cached_single_tag_hits(run_dir: Path, test_set: str) -> tuple[np.ndarray, np.ndarray]:
    """(Q,) bool localized without markers and (C, Q) bool localized with candidate c alone,
    from the predictions cached in ``run_dir/cache/predictions`` (main threshold); C is the
    number of candidates of the run's plan (``run_dir/plan``), and every one must be there."""
    for path in (run_dir / f"test_poses_{test_set}.npz", run_dir / "plan" / "discretization.npz"):
        if not path.is_file():
            raise SystemExit(f"{run_dir}: no {path.relative_to(run_dir)}; pass the output folder of "
                             "`markerplace evaluate --ceiling`")
    truth = TestPoses.load(run_dir / f"test_poses_{test_set}.npz").world_from_cam
    n_candidates = len(discretization.load(run_dir / "plan" / "discretization.npz").candidate_world_from_marker)
    folder = run_dir / "cache" / "predictions"
    predictions: dict[tuple, np.ndarray] = {}
    for meta_path in sorted(folder.glob("*.meta.json")):
        meta = json.loads(meta_path.read_text())
        if meta.get("test_set") != test_set or meta.get("method") not in (SINGLE, NO_MARKERS):
            continue
        key = (meta["method"], int(meta["run"]), int(meta["k"]), test_set)
        if key in predictions:
            raise SystemExit(f"{run_dir}: two cached predictions for {key}; "
                             "run this on a folder holding one evaluation's cache")
        est = load_prediction(folder, meta["key"])
        if est is None or len(est) != len(truth):
            raise SystemExit(f"{run_dir}: cached prediction {meta['key']} does not belong to the folder's "
                             f"{len(truth)} {test_set} test images (another test seed?); use the ceiling run's own folder")
        predictions[key] = est
    if (NO_MARKERS, 0, 0, test_set) not in predictions:
        raise SystemExit(f"{run_dir}: no marker-free predictions for {test_set}; run `evaluate --ceiling` first")
    runs = sorted(run for method, run, _, _ in predictions if method == SINGLE)
    if runs != list(range(n_candidates)):
        raise SystemExit(f"{run_dir}: single-tag predictions for {test_set} are missing or incomplete "
                         f"({len(runs)} of {n_candidates} candidates); run `evaluate --ceiling` to the end first "
                         "(an evaluation with k = 1 among its budgets shares cache entries with them: "
                         "leave 1 out of --k)")
    return single_tag_hits(predictions, truth, test_set, n_candidates)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path, help="output folder of `markerplace evaluate --ceiling`")
    ap.add_argument("--test-set", default="weighted")
    ap.add_argument("--k", default="10,20", help="marker budgets, comma-separated")
    ap.add_argument("--splits", type=int, default=100, help="random splits of the test images")
    ap.add_argument("--draws", type=int, default=200, help="random k-subsets of candidates per split")
    ap.add_argument("--train-fraction", type=float, default=0.5,
                    help="share of the test images the held-out picks are made on (0.5: halves)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if not 0.0 < args.train_fraction < 1.0:
        raise SystemExit("--train-fraction must be between 0 and 1 (exclusive), e.g. 0.5")
    try:
        ks = [int(v) for v in args.k.split(",")]
    except ValueError:
        raise SystemExit(f"--k must be comma-separated whole numbers, e.g. 10,20 (got {args.k!r})") from None
    if min(ks) < 1:
        raise SystemExit(f"--k budgets must be at least 1 (got {args.k!r})")
    base, hits = cached_single_tag_hits(args.run_dir, args.test_set)
    C, Q = hits.shape
    if Q < 2:
        raise SystemExit(f"{args.run_dir}: {Q} {args.test_set} test image(s); held-out splits need at least 2")
    fix = hits & ~base[None, :]
    print(f"test_images: {Q}")
    print(f"train_fraction: {args.train_fraction:g}")
    print(f"candidates: {C}")
    print(f"failing_without_markers: {int((~base).sum())}")
    print(f"fixable_by_one_candidate: {int(fix.any(axis=0).sum())}")
    print(f"fixes_per_candidate_median: {float(np.median(fix.sum(axis=1))):.1f}")
    print(f"fixes_per_candidate_max: {int(fix.sum(axis=1).max())}")
    rng = np.random.default_rng(args.seed)
    for k in dict.fromkeys(min(k, C) for k in ks):  # budgets above C are C; each printed once
        i, h, r = (100 * x for x in held_out_gains(base, hits, k, rng, args.train_fraction, args.splits, args.draws))
        full, _ = oracle_order(base, hits, k)
        full_gain = 100 * (covered(base, hits, full) - base.sum()) / Q
        full_random = 100 * np.mean([covered(base, hits, rng.choice(C, k, replace=False)) - base.sum()
                                     for _ in range(args.draws)]) / Q
        print(f"k{k}_all_images_ceiling_estimate: {100 * base.mean() + full_gain:.1f}")
        print(f"k{k}_all_images_ceiling_over_random: {full_gain - full_random:.1f}")
        print(f"k{k}_in_sample_gain: {i:.1f}")
        print(f"k{k}_held_out_gain: {h:.1f}")
        print(f"k{k}_random_gain: {r:.1f}")
        print(f"k{k}_in_sample_over_random: {i - r:.1f}")
        print(f"k{k}_held_out_over_random: {h - r:.1f}")
        print(f"k{k}_held_out_share_of_in_sample: {(h - r) / (i - r) if i > r else float('nan'):.2f}")


if __name__ == "__main__":
    main()
