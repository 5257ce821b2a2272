"""Does the localizability score predict localization failure? (paper, Fig. 9(b))

Reads ``query_errors.npz`` of an ``evaluate`` run and prints ``name: value`` lines for the
no-marker results of one test set: mean score of failures and successes, the point-biserial
correlation between failure and score, and the failure rate per score quartile.

    .venv/bin/python benchmarks/score_correlation.py out/eval_office_paper [--test-set weighted]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.stats import pointbiserialr


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", help="output folder of `markerplace evaluate`")
    ap.add_argument("--test-set", default="weighted")
    ap.add_argument("--t-max", type=float, default=0.05, help="success threshold, metres")
    ap.add_argument("--r-max", type=float, default=5.0, help="success threshold, degrees")
    args = ap.parse_args(argv)
    q = np.load(Path(args.run_dir) / "query_errors.npz")
    ts = args.test_set
    none = int(np.flatnonzero(q[f"{ts}_method"] == "none")[0])
    ok = (q[f"{ts}_t_err"][none] <= args.t_max) & (q[f"{ts}_r_err"][none] <= args.r_max)
    score = q[f"{ts}_score"]
    fail = ~ok
    print(f"test_images: {len(score)}")
    print(f"no_marker_recall: {ok.mean():.3f}")
    print(f"mean_score_failures: {score[fail].mean():.2f}")
    print(f"mean_score_successes: {score[ok].mean():.2f}")
    r = pointbiserialr(fail, score)
    print(f"pointbiserial_r: {r.statistic:.3f}")
    print(f"pointbiserial_p: {r.pvalue:.2e}")
    edges = np.quantile(score, [0, 0.25, 0.5, 0.75, 1.0])
    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        sel = (score >= a) & (score <= b)
        print(f"failure_rate_quartile_{i + 1}: {fail[sel].mean():.3f}")


if __name__ == "__main__":
    main()
