"""What sharing observe's renders with the testbed's marker-free map saves, against the code
before it (``--baseline``, default 9f98284), each command a separate process as a user runs it.

Two flows, each run with the baseline's ``src/`` (``git archive``, as
``benchmarks/plan_speedup.py``) and with the current code:

* ``evaluate``: ``evaluate SCENE`` (it runs observe itself; the baseline then renders the map
  again, the current code takes the map from observe's renders);
* ``plan_then_evaluate``: ``plan SCENE`` then ``evaluate --plan`` (the current code's plan with
  ``--with-map``; the baseline's evaluation renders the map again).

Prints ``name: value`` lines: per flow and code the wall and CPU seconds of each command (CPU of
the process and its workers), the totals, the ratios baseline / current, the plan's observe
seconds (its ``stage seconds`` log line), the evaluation's ``plan_prepare`` and
``map_no_markers`` seconds (timings.json), and whether every evaluation's ``recall.csv`` is the
baseline's.

    .venv/bin/python benchmarks/map_sharing.py [--scene room] [--work out/bench_map_sharing] [--tests 50]

``--scene house-scan`` plans ``scene export house --as-scan`` (cached in ``--work``) with ``--up z``.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from plan_speedup import baseline_source, scene_args  # noqa: E402
from run_estimate import emit, markerplace_exe  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def run(label: str, cmd: list[str], src: Path) -> dict:
    """Run ``cmd`` with ``src`` first on ``PYTHONPATH``; its wall and CPU seconds (process tree)
    and its log."""
    env = dict(os.environ, PYTHONPATH=str(src))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"{label}: {' '.join(cmd)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    emit(f"{label}.command", f"PYTHONPATH={src} " + " ".join(cmd))
    emit(f"{label}.wall_s", wall)
    emit(f"{label}.cpu_s", cpu)
    return {"wall": wall, "cpu": cpu, "log": proc.stderr}


def observe_seconds(log: str) -> float:
    """The observe entry of the last ``stage seconds:`` log line."""
    lines = re.findall(r"stage seconds: (.*)", log)
    found = re.search(r"(?:^|, )observe ([0-9.]+)", lines[-1]) if lines else None
    return float(found.group(1)) if found else float("nan")


def evaluation_figures(label: str, out: Path) -> None:
    timings = json.loads((out / "timings.json").read_text())
    for name in ("plan_prepare", "map_no_markers"):
        emit(f"{label}.{name}_s", float(timings.get(name, float("nan"))))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="room")
    ap.add_argument("--work", default="out/bench_map_sharing")
    ap.add_argument("--baseline", default="9f98284")
    ap.add_argument("-k", type=int, default=5)
    ap.add_argument("--tests", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    work = Path(args.work).resolve()
    work.mkdir(parents=True, exist_ok=True)
    scene = scene_args(args.scene, work)
    exe = markerplace_exe()
    codes = {"baseline": baseline_source(args.baseline, work), "current": REPO / "src"}
    evaluate = ["--tests", str(args.tests), "--test-sets", "weighted", "--methods", "none", "--runs", "1",
                "--workers", str(args.workers)]
    emit("scene", args.scene)
    emit("baseline", args.baseline)
    totals, recalls = {}, {}
    for code, src in codes.items():
        out = work / f"eval_{code}"
        shutil.rmtree(out, ignore_errors=True)
        r = run(f"evaluate.{code}", [exe, "evaluate", *scene, "--out", str(out), "--k", str(args.k),
                                     *evaluate[:4], "--methods", "none,omp", *evaluate[6:]], src)
        evaluation_figures(f"evaluate.{code}", out)
        totals[("evaluate", code)] = (r["wall"], r["cpu"])
        recalls[("evaluate", code)] = (out / "recall.csv").read_text()
    for code, src in codes.items():
        plan, out = work / f"plan_{code}", work / f"eval_plan_{code}"
        for d in (plan, out):
            shutil.rmtree(d, ignore_errors=True)
        flags = ["--with-map"] if code == "current" else []
        p = run(f"plan_then_evaluate.{code}.plan", [exe, "plan", *scene, "-k", str(args.k), "--out", str(plan),
                                                    "--workers", str(args.workers), *flags], src)
        emit(f"plan_then_evaluate.{code}.plan.observe_s", observe_seconds(p["log"]))
        e = run(f"plan_then_evaluate.{code}.evaluate", [exe, "evaluate", "--plan", str(plan), "--out", str(out),
                                                        *evaluate], src)
        evaluation_figures(f"plan_then_evaluate.{code}.evaluate", out)
        totals[("plan_then_evaluate", code)] = (p["wall"] + e["wall"], p["cpu"] + e["cpu"])
        recalls[("plan_then_evaluate", code)] = (out / "recall.csv").read_text()
    for flow in ("evaluate", "plan_then_evaluate"):
        (bw, bc), (cw, cc) = totals[(flow, "baseline")], totals[(flow, "current")]
        emit(f"{flow}.total.baseline.wall_s", bw)
        emit(f"{flow}.total.current.wall_s", cw)
        emit(f"{flow}.total.baseline.cpu_s", bc)
        emit(f"{flow}.total.current.cpu_s", cc)
        emit(f"{flow}.wall_ratio_baseline_over_current", bw / cw)
        emit(f"{flow}.cpu_ratio_baseline_over_current", bc / cc)
        emit(f"{flow}.same_recall_csv", recalls[(flow, "baseline")] == recalls[(flow, "current")])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
