"""Which camera poses see a placement's tags: coverage of the map poses, and of the poorly
localizable ones.

For each ``--placement NAME=PATH[:K]`` (a ``placement.json``; its first K markers by pick
order, default all), with the plan's candidate visibility (``observations/
extra_candidate_unoccluded.npy``: (N poses, C candidates) bool, the candidate wholly visible in
the marker-free map image) and the marker-free score of every pose (``scores.npz`` of a
``plan`` run on the same discretization, ``score_before``), prints one markdown row:

* ``poses seeing a tag``: % of the N map poses that see at least one of the markers;
* ``lowest-score quarter``: the same over the poses in the lowest quarter of the score (the
  poses that need a tag: they fail most often without markers);
* ``tags per pose``: mean number of the markers a pose sees;
* ``poses per tag``: mean number of poses that see each marker.

Markers must come from a plan with the same candidates (``candidate_index`` in the file).

    .venv/bin/python benchmarks/placement_coverage.py --plan out/eval_office/plan \\
        --scores out/office_plan/scores.npz --placement omp=out/office_plan/placement.json:10 \\
        --placement human=out/office_human/placement.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def candidate_indices(path: Path, k: int | None) -> list[int]:
    """Candidate index of the first ``k`` markers of a placement file, in pick order."""
    markers = json.loads(path.read_text())["markers"]
    if any("candidate_index" not in m or m["candidate_index"] is None for m in markers):
        sys.exit(f"error: {path} has markers without candidate_index: use a placement of `markerplace plan`")
    order = sorted(markers, key=lambda m: m.get("order", 0))
    return [int(m["candidate_index"]) for m in order][:k]


def coverage_row(visible: np.ndarray, low: np.ndarray, indices: list[int]) -> tuple[float, float, float, float]:
    """(% poses seeing a tag, % of the ``low`` poses seeing one, tags per pose, poses per tag)
    for the candidates ``indices`` of the (N, C) ``visible`` matrix."""
    seen = visible[:, indices]
    any_tag = seen.any(axis=1)
    return (100.0 * any_tag.mean(), 100.0 * any_tag[low].mean(), float(seen.sum(axis=1).mean()),
            float(seen.sum(axis=0).mean()))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plan", required=True, type=Path, help="plan folder with observations/")
    ap.add_argument("--scores", required=True, type=Path, help="scores.npz of a plan run on the same discretization")
    ap.add_argument("--placement", action="append", required=True, metavar="NAME=PATH[:K]",
                    help="a placement.json and how many of its first markers (repeatable)")
    args = ap.parse_args(argv)
    vis_path = args.plan / "observations" / "extra_candidate_unoccluded.npy"
    if not vis_path.exists():
        sys.exit(f"error: {vis_path} not found: give the plan folder of a plan or evaluate run")
    visible = np.load(vis_path, allow_pickle=False)
    with np.load(args.scores, allow_pickle=False) as z:
        score = np.asarray(z["score_before"], float)
    if len(score) != len(visible):
        sys.exit(f"error: {args.scores} scores {len(score)} poses, the plan has {len(visible)}: same discretization?")
    low = score <= np.quantile(score, 0.25)
    print(f"{len(visible)} map poses, {visible.shape[1]} candidates; poses per candidate: mean "
          f"{visible.sum(axis=0).mean():.0f}, median {np.median(visible.sum(axis=0)):.0f}")
    print("| placement | k | poses seeing a tag (%) | lowest-score quarter (%) | tags per pose | poses per tag |")
    print("|---|---|---|---|---|---|")
    for spec in args.placement:
        name, _, rest = spec.partition("=")
        path, _, k = rest.rpartition(":") if rest.rpartition(":")[2].isdigit() else (rest, "", "")
        indices = candidate_indices(Path(path), int(k) if k else None)
        cov, cov_low, per_pose, per_tag = coverage_row(visible, low, indices)
        print(f"| {name} | {len(indices)} | {cov:.1f} | {cov_low:.1f} | {per_pose:.2f} | {per_tag:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
