"""Which camera poses see a placement's tags: coverage of the map poses, and of the poorly
localizable ones.

For each ``--placement NAME=PATH[:K]`` (a ``placement.json`` of ``markerplace plan`` on the same
scene and discretization; its first K markers by pick order, default all), with the plan's
visibility (:attr:`PlanData.visible`: the candidate in view of the pose and wholly unoccluded
in its marker-free image, what OMP's coverage uses) and the marker-free score of every pose
(:attr:`PlanData.base_score`), prints one markdown row:

* ``poses seeing a tag``: % of the N map poses that see at least one of the markers;
* ``lowest-score quarter``: the same over the poses in the lowest quarter of the score (the
  poses that need a tag: they fail most often without markers);
* ``tags per pose``: mean number of the markers a pose sees;
* ``poses per tag``: mean number of poses that see each marker.

The plan's artifacts are copied to a scratch folder and reused there by ``prepare`` with the
default plan settings (nothing under ``--plan`` is written)::

    .venv/bin/python benchmarks/placement_coverage.py --plan out/eval_office/plan \\
        --placement omp=out/coverage_office/omp/placement.json:10 \\
        --placement human=out/coverage_office/human10/placement.json [--scene office]
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tempfile
from pathlib import Path

import numpy as np


def parse_spec(spec: str) -> tuple[str, Path, int | None]:
    """``NAME=PATH[:K]`` -> (name, path, k or None); exits with a one-line error when malformed."""
    name, sep, rest = spec.partition("=")
    path, colon, k = rest.rpartition(":")
    if not colon or not k.isdigit():
        path, k = rest, ""
    if not sep or not name or not path:
        sys.exit(f"error: --placement {spec!r}: give NAME=PATH[:K], e.g. omp=out/plan/placement.json:10")
    if k and int(k) < 1:
        sys.exit(f"error: --placement {spec!r}: K must be at least 1")
    if not Path(path).is_file():
        sys.exit(f"error: --placement {spec!r}: {path} is not a file")
    return name, Path(path), int(k) if k else None


def candidate_indices(path: Path, k: int | None, num_candidates: int) -> list[int]:
    """Candidate index of the first ``k`` markers of a placement file, in pick order."""
    markers = json.loads(path.read_text())["markers"]
    indices = [m.get("candidate_index") for m in sorted(markers, key=lambda m: m.get("order", 0))][:k]
    if any(i is None or not 0 <= int(i) < num_candidates for i in indices):
        sys.exit(f"error: {path}: markers without a candidate index of this plan (0..{num_candidates - 1}): "
                 "use a placement of `markerplace plan` on the same scene")
    return [int(i) for i in indices]


def coverage_row(visible: np.ndarray, low: np.ndarray, indices: list[int]) -> tuple[float, float, float, float]:
    """(% poses seeing a tag, % of the ``low`` poses seeing one, tags per pose, poses per tag)
    for the candidates ``indices`` of the (N, C) bool ``visible`` matrix; ``low`` (N,) bool."""
    seen = visible[:, indices]
    any_tag = seen.any(axis=1)
    return (100.0 * any_tag.mean(), 100.0 * any_tag[low].mean(), float(seen.sum(axis=1).mean()),
            float(seen.sum(axis=0).mean()))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="office", help="built-in scene name (default office)")
    ap.add_argument("--plan", required=True, type=Path, help="plan folder (discretization.npz, observations/)")
    ap.add_argument("--placement", action="append", required=True, metavar="NAME=PATH[:K]",
                    help="a placement.json and how many of its first markers (repeatable)")
    args = ap.parse_args(argv)
    specs = [parse_spec(s) for s in args.placement]
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)

    from evaluation_profile import copy_plan  # the benchmarks' one plan copier (same folder)

    from markerplace.pipelines.plan import prepare
    from markerplace.plan.config import PlanConfig
    from markerplace.runtime.executor import RuntimeConfig, make_executor
    from markerplace.scene.spec import SceneSpec

    with tempfile.TemporaryDirectory(prefix="placement_coverage_") as tmp:
        copy_plan(args.plan, Path(tmp) / "plan")
        with make_executor(RuntimeConfig(workers=1)) as ex:
            data = prepare(SceneSpec(args.scene), PlanConfig(), Path(tmp) / "plan", progress=False, executor=ex)
    C = data.num_candidates
    visible = np.asarray(data.visible, bool)[:, :C]
    score = np.asarray(data.base_score, float)
    low = score <= np.quantile(score, 0.25)
    print(f"{len(visible)} map poses, {C} candidates; poses per candidate: mean {visible.sum(axis=0).mean():.0f}, "
          f"median {np.median(visible.sum(axis=0)):.0f}")
    print("| placement | k | poses seeing a tag (%) | lowest-score quarter (%) | tags per pose | poses per tag |")
    print("|---|---|---|---|---|---|")
    for name, path, k in specs:
        indices = candidate_indices(path, k, C)
        cov, cov_low, per_pose, per_tag = coverage_row(visible, low, indices)
        print(f"| {name} | {len(indices)} | {cov:.1f} | {cov_low:.1f} | {per_pose:.2f} | {per_tag:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
