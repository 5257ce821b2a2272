"""Is ``plan`` faster than a baseline commit, and does it still plan the same? Both codes plan the
same scan-like model in one run of this script, one after the other, as a user runs them.

Prints ``name: value`` lines.

* the model: ``--scene NAME-scan`` is ``scene export NAME --as-scan`` (a fused simulated scan of
  the built-in NAME, cached in ``--work`` as ``NAME_scan.ply``), planned with ``--up z``; any
  other value is passed to ``plan`` as is (``frames:DIR``: ``plan --frames DIR``, e.g. the 7-Scenes
  kitchen with ``--baseline-args``/``--current-args`` ``"--tag-size 0.16 --marker-spacing 0.5"``) (a built-in name or a mesh file). The floor area comes
  from the discretization summary (``open_floor_m2`` summed over storeys).
* the baseline: ``git archive BASELINE src`` unpacked in ``--work`` and put first on
  ``PYTHONPATH`` of its ``plan`` process (same interpreter, same packages); the current code is
  this checkout's ``src``.
* per code: ``markerplace plan SCENE -k K --out DIR --workers W`` into a fresh ``DIR``: wall
  seconds, CPU seconds of the process tree (workers included, from ``getrusage`` of reaped
  children), peak resident memory of the tree (sampled), and the logged stage seconds.
* ratios: baseline / current for wall and CPU seconds (goal >= 3, issue 37).
* fidelity (the planner must see the same): Spearman rank correlation of the per-pose scores
  (``scores.npz: score_before``; goal >= 0.98), the greedy objective (sum of the picked
  markers' gains) and its relative difference (goal within 1 %), whether the same candidates
  were picked in the same order, and the observation's feature counts.

    .venv/bin/python benchmarks/plan_speedup.py [--scene house-scan] [--baseline fa74cb0]
        [--work out/bench_speedup] [-k 10] [--workers 2] [--order baseline-first|current-first]
        [--baseline-args="..."] [--current-args="..."]

``--baseline HEAD --current-args="--observe-views location"`` compares a setting of today's code
with its default in the same run (``HEAD`` is unpacked like any commit, so uncommitted changes
are only in ``current``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from plan_profile import TreeSampler  # benchmarks/ is on sys.path when run as a script
from run_estimate import markerplace_exe
from scan_plan import emit
from scipy.stats import spearmanr

REPO = Path(__file__).resolve().parents[1]
GOAL_SPEEDUP = 3.0
GOAL_RANK = 0.98
GOAL_OBJECTIVE = 0.01


def scene_args(scene: str, work: Path) -> list[str]:
    """``plan`` arguments of ``scene`` (exports ``NAME-scan`` once into ``work``; ``frames:DIR`` is
    ``--frames DIR``, a real RGB-D sequence)."""
    if scene.startswith("frames:"):
        return ["--frames", scene[len("frames:"):]]
    if not scene.endswith("-scan"):
        return [scene]
    name = scene[: -len("-scan")]
    scan = work / f"{name}_scan.ply"
    if not scan.exists():
        subprocess.run([markerplace_exe(), "--quiet", "scene", "export", name, str(scan), "--as-scan"], check=True)
    return [str(scan), "--up", "z"]


def baseline_source(ref: str, work: Path) -> Path:
    """``src/`` of commit ``ref`` unpacked under ``work`` (once)."""
    commit = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", ref], check=True, capture_output=True,
                            text=True).stdout.strip()
    root = work / f"baseline_{commit}"
    if not (root / "src" / "markerplace").is_dir():
        shutil.rmtree(root, ignore_errors=True)
        root.mkdir(parents=True)
        archive = subprocess.run(["git", "-C", str(REPO), "archive", commit, "src"], check=True, capture_output=True)
        subprocess.run(["tar", "-x", "-C", str(root)], input=archive.stdout, check=True)
    return root / "src"


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_plan(label: str, src: Path, plan_scene: list[str], out: Path, args, extra: str = "") -> dict:
    """One ``plan`` process with ``src`` first on its path (and ``extra`` plan arguments); its
    wall, CPU and peak memory."""
    shutil.rmtree(out, ignore_errors=True)
    env = dict(os.environ, PYTHONPATH=str(src))
    cmd = [markerplace_exe(), "plan", *plan_scene, "-k", str(args.k), "--out", str(out), "--workers", str(args.workers),
           *extra.split()]
    emit(f"{label}.command", f"PYTHONPATH={src} " + " ".join(cmd))
    cpu0, t0 = children_cpu(), time.perf_counter()
    with open(out.with_suffix(".log"), "w") as log:
        proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=log)
        sampler = TreeSampler(proc.pid, 0.5).start()
        proc.wait()
    wall, cpu = time.perf_counter() - t0, children_cpu() - cpu0
    sampler.stop()
    text = out.with_suffix(".log").read_text()
    if proc.returncode != 0:
        print(text[-3000:], file=sys.stderr)
        raise SystemExit(f"{label} plan failed ({proc.returncode})")
    stages = re.findall(r"stage seconds: (.*)", text)
    result = {"wall_s": wall, "cpu_s": cpu, "peak_rss_mib": max((m for _, m, _ in sampler.samples), default=float("nan")),
              "stages": stages[-1] if stages else ""}
    for name, value in result.items():
        emit(f"{label}.{name}", value)
    return result


def plan_figures(out: Path) -> dict:
    """Scores, picks, objective and feature count of a finished plan folder."""
    scores = np.load(out / "scores.npz")
    meta = json.loads((out / "observations.meta.json").read_text()) if (out / "observations.meta.json").exists() else {}
    placement = json.loads((out / "placement.json").read_text())
    storeys = placement["summary"]["discretization"]["per_storey"]
    return {"score": np.asarray(scores["score_before"], float), "picks": [int(c) for c in scores["candidates"]],
            "objective": float(np.sum(scores["gains"])), "area": float(sum(s["open_floor_m2"] for s in storeys)),
            "poses": len(scores["score_before"]), "meta": meta}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="house-scan")
    ap.add_argument("--baseline", default="fa74cb0", help="commit of the code to compare with")
    ap.add_argument("--work", default="out/bench_speedup")
    ap.add_argument("-k", type=int, default=10)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--order", default="baseline-first", choices=("baseline-first", "current-first"))
    ap.add_argument("--baseline-args", default="", help="more plan arguments for the baseline")
    ap.add_argument("--current-args", default="", help="more plan arguments for the current code")
    args = ap.parse_args()
    work = Path(args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    plan_scene = scene_args(args.scene, work)
    codes = {"baseline": baseline_source(args.baseline, work), "current": REPO / "src"}
    emit("scene", args.scene)
    emit("baseline", args.baseline)
    emit("current", subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True,
                                   text=True).stdout.strip())
    emit("cpus", os.cpu_count())
    labels = ["baseline", "current"] if args.order == "baseline-first" else ["current", "baseline"]
    extra = {"baseline": args.baseline_args, "current": args.current_args}
    runs = {label: run_plan(label, codes[label], plan_scene, work / f"plan_{label}", args, extra[label])
            for label in labels}
    figs = {label: plan_figures(work / f"plan_{label}") for label in labels}
    emit("area.open_floor_m2", figs["current"]["area"])
    emit("poses", figs["current"]["poses"])
    for what in ("wall_s", "cpu_s"):
        ratio = runs["baseline"][what] / runs["current"][what]
        emit(f"speedup.{what}", ratio)
        emit(f"speedup.{what}.meets_goal", bool(ratio >= GOAL_SPEEDUP))
    b, c = figs["baseline"], figs["current"]
    same_poses = len(b["score"]) == len(c["score"])
    emit("fidelity.same_poses", same_poses)
    if same_poses:
        rho = float(spearmanr(b["score"], c["score"]).statistic)
        emit("fidelity.score_rank_correlation", rho)
        emit("fidelity.score_rank_correlation.meets_goal", bool(rho >= GOAL_RANK))
        emit("fidelity.score_max_abs_difference", float(np.max(np.abs(b["score"] - c["score"]))))
    emit("fidelity.objective.baseline", b["objective"])
    emit("fidelity.objective.current", c["objective"])
    rel = abs(c["objective"] - b["objective"]) / max(abs(b["objective"]), 1e-12)
    emit("fidelity.objective.relative_difference", rel)
    emit("fidelity.objective.meets_goal", bool(rel <= GOAL_OBJECTIVE))
    emit("fidelity.same_picks_in_order", b["picks"] == c["picks"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
