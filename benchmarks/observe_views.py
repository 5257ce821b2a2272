"""Does looking at a camera location once (``plan --observe-views``) plan the same, and how much
faster? One ``plan`` per mode of the same scene in one run of this script, one after the other.

Prints ``name: value`` lines.

* modes: ``pose`` (every pose rendered and extracted: the reference), ``location-renders``
  (every other yaw rendered as a larger face, the yaws between resampled from the faces; SIFT
  per pose) and ``location-features`` (the yaws between also take the faces' features)
  (:mod:`markerplace.imaging.location_views`).
* per mode: ``markerplace plan SCENE -k K --out DIR --workers W --observe-views MODE`` into a
  fresh ``DIR``: wall and CPU seconds of the process tree, peak memory, the logged stage seconds
  (benchmarks/plan_speedup.py's ``run_plan``); ``SCENE`` as in plan_speedup.py (``NAME-scan``: the
  fused simulated scan of built-in NAME).
* per mode against ``pose``: CPU and wall ratios (pose / mode), the Spearman rank correlation of
  the per-pose scores (``scores.npz: score_before``, the issue's fidelity goal >= 0.98), the same
  over the even and the odd poses of each location alone, the greedy objective's relative
  difference (goal within 1 %), whether the same candidates were picked in the same order, and
  the mean features per pose.
* ``cross_objective``: each mode's picks, in its order, scored on the reference's own problem
  (``pose``'s observations, look-alikes and coverages, loaded from its run folder): the sum of
  the picks' percentile gains as the reference's greedy would count them, against the
  reference's own objective (``pose.objective``). Where the picks differ after a near tie, this
  says whether the other path is as good under the reference's model (goal: within 1 %).
* the even poses of ``location-renders`` see the same rays as ``pose`` (their images are crops
  of the faces, equal up to 1 grey level in a few per cent of the pixels): their correlation
  shows how much SIFT's sensitivity alone moves the scores, a floor for any change of renderer.

    .venv/bin/python benchmarks/observe_views.py [--scene house-scan] [--work out/bench_views] [-k 10]
        [--workers 2] [--modes pose,location-renders,location-features]
"""

from __future__ import annotations

import argparse
import os
import subprocess
from pathlib import Path

import numpy as np
from plan_speedup import REPO, plan_figures, run_plan, scene_args  # benchmarks/ is on sys.path
from scan_plan import emit
from scipy.stats import spearmanr

GOAL_RANK = 0.98


def sequence_objective(run_dir: Path, plan_scene: list[str], order: list[int]) -> float:
    """Sum of the percentile gains of ``order`` placed one after the other on the problem of the
    plan folder ``run_dir`` (its cached stages; omp's gain rule, plan/place/greedy.py)."""
    from markerplace.config_file import read_config_file
    from markerplace.pipelines.plan import prepare
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.place.greedy import GreedyProblem, coverage_percentages, weighted_q_from_v
    from markerplace.scene.spec import SceneSpec

    config = read_config_file(run_dir / "config.json", PlanConfig())
    up = plan_scene[plan_scene.index("--up") + 1] if "--up" in plan_scene else None
    data = prepare(SceneSpec(plan_scene[0], up), config, run_dir, progress=False)
    cov = data.coverages[:data.num_candidates]
    N = data.base_info.shape[0]
    q, _ = weighted_q_from_v(coverage_percentages(cov, N, None), config.placement.methods.omp.v, False)
    prob = GreedyProblem(data.base_info.copy(), cov, q)
    total = 0.0
    for m in order:
        qg, _ = prob.evaluate(np.array([m]))
        total += float(qg[0])
        prob.add(cov[m])
    return total
GOAL_OBJECTIVE = 0.01


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="house-scan")
    ap.add_argument("--work", default="out/bench_views")
    ap.add_argument("-k", type=int, default=10)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--modes", default="pose,location-renders,location-features")
    ap.add_argument("--compare-only", action="store_true", help="compare the plan folders already in --work")
    args = ap.parse_args()
    work = Path(args.work).resolve() / args.scene
    work.mkdir(parents=True, exist_ok=True)
    plan_scene = scene_args(args.scene, work.parent)
    emit("scene", args.scene)
    emit("code", subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True).stdout.strip())
    emit("cpus", os.cpu_count())
    modes = args.modes.split(",")
    runs, figs = {}, {}
    for mode in modes:
        out = work / f"plan_{mode}"
        if args.compare_only:
            runs[mode] = {"wall_s": float("nan"), "cpu_s": float("nan")}
        else:
            runs[mode] = run_plan(mode, REPO / "src", plan_scene, out, args, f"--observe-views {mode}")
        figs[mode] = plan_figures(out)
        counts = np.diff(np.load(out / "observations" / "offsets.npy")) if (out / "observations" / "offsets.npy").exists() \
            else None
        if counts is not None:
            emit(f"{mode}.features_per_pose_mean", float(counts.mean()))
    ref = figs.get("pose")
    if ref is None:
        return 0
    emit("poses", ref["poses"])
    emit("area.open_floor_m2", ref["area"])
    odd = np.arange(ref["poses"]) % 2 == 1  # locations hold an even number of yaws (8 by default)
    for mode in modes:
        if mode == "pose":
            continue
        c = figs[mode]
        for what in ("wall_s", "cpu_s"):
            emit(f"{mode}.speedup.{what}", runs["pose"][what] / runs[mode][what])
        if len(c["score"]) != len(ref["score"]):
            emit(f"{mode}.fidelity.same_poses", False)
            continue
        rho = float(spearmanr(ref["score"], c["score"]).statistic)
        emit(f"{mode}.fidelity.score_rank_correlation", rho)
        emit(f"{mode}.fidelity.score_rank_correlation.meets_goal", bool(rho >= GOAL_RANK))
        emit(f"{mode}.fidelity.score_rank_correlation.even_poses",
             float(spearmanr(ref["score"][~odd], c["score"][~odd]).statistic))
        emit(f"{mode}.fidelity.score_rank_correlation.odd_poses",
             float(spearmanr(ref["score"][odd], c["score"][odd]).statistic))
        rel = abs(c["objective"] - ref["objective"]) / max(abs(ref["objective"]), 1e-12)
        emit(f"{mode}.fidelity.objective.relative_difference", rel)
        emit(f"{mode}.fidelity.objective.meets_goal", bool(rel <= GOAL_OBJECTIVE))
        emit(f"{mode}.fidelity.same_picks_in_order", ref["picks"] == c["picks"])
        emit(f"{mode}.fidelity.same_picks_any_order", sorted(ref["picks"]) == sorted(c["picks"]))
        if ref["picks"] != c["picks"]:
            cross = sequence_objective(work / "plan_pose", plan_scene, c["picks"])
            emit(f"{mode}.fidelity.cross_objective", cross)
            emit(f"{mode}.fidelity.cross_objective.relative_to_pose", cross / ref["objective"])
            emit(f"{mode}.fidelity.cross_objective.meets_goal", bool(cross >= (1 - GOAL_OBJECTIVE) * ref["objective"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
