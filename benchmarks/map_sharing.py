"""What sharing observe's renders with the testbed's map saves: ``plan`` then ``evaluate --plan``,
once as before (the evaluation renders its marker-free map again) and once with
``plan --with-map`` (observe also extracts the map's features from its renders), each command a
separate process as a user runs it.

Prints ``name: value`` lines: per variant the observe stage's seconds (from the plan's
``stage seconds`` log line), the evaluation's map stage (``timings.json: map_no_markers``),
the wall and CPU seconds of plan and evaluate together (CPU of the process and its workers),
whether the evaluation rendered its map (it logs "reusing" when it did not), and whether the two evaluations'
``recall.csv`` are equal.

    .venv/bin/python benchmarks/map_sharing.py [--scene room] [--work out/bench_map_sharing] [--tests 50]

``--scene house-scan`` plans ``scene export house --as-scan`` (cached in ``--work``) with ``--up z``.
"""

from __future__ import annotations

import argparse
import json
import re
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run_estimate import emit, house_scan, markerplace_exe  # noqa: E402

STAGES = re.compile(r"stage seconds: (.*)")


def run(cmd: list[str]) -> tuple[str, float, float]:
    """(stderr text, wall seconds, CPU seconds of the process tree) of ``cmd``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return proc.stderr, wall, cpu


def stage_seconds(log: str) -> dict[str, float]:
    """The last ``stage seconds: a 1.0, b 2.0`` log line as a dict."""
    lines = STAGES.findall(log)
    if not lines:
        return {}
    out = {}
    for part in lines[-1].split(", "):
        name, _, value = part.rpartition(" ")
        out[name] = float(value)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="room")
    ap.add_argument("--work", default="out/bench_map_sharing")
    ap.add_argument("-k", type=int, default=5)
    ap.add_argument("--tests", type=int, default=50)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    scene, extra = (str(house_scan(work)), ["--up", "z"]) if args.scene == "house-scan" else (args.scene, [])
    exe = markerplace_exe()
    emit("scene", args.scene)
    results = {}
    for variant, flags in (("before", []), ("with_map", ["--with-map"])):
        plan_dir, eval_dir = work / f"plan_{variant}", work / f"eval_{variant}"
        for d in (plan_dir, eval_dir):
            shutil.rmtree(d, ignore_errors=True)
        plan_log, plan_wall, plan_cpu = run([exe, "plan", scene, *extra, "-k", str(args.k), "--out", str(plan_dir),
                                             "--workers", str(args.workers), *flags])
        eval_log, eval_wall, eval_cpu = run([exe, "evaluate", "--plan", str(plan_dir), "--out", str(eval_dir),
                                             "--tests", str(args.tests), "--test-sets", "weighted", "--methods", "none",
                                             "--runs", "1", "--workers", str(args.workers)])
        timings = json.loads((eval_dir / "timings.json").read_text())
        observe = stage_seconds(plan_log).get("observe", float("nan"))
        rendered = "map: reusing marker-free features" not in eval_log
        emit(f"{variant}.plan.observe_s", observe)
        emit(f"{variant}.plan.wall_s", plan_wall)
        emit(f"{variant}.plan.cpu_s", plan_cpu)
        emit(f"{variant}.evaluate.map_stage_s", float(timings.get("map_no_markers", float("nan"))))
        emit(f"{variant}.evaluate.map_rendered", rendered)
        emit(f"{variant}.evaluate.wall_s", eval_wall)
        emit(f"{variant}.evaluate.cpu_s", eval_cpu)
        emit(f"{variant}.both.wall_s", plan_wall + eval_wall)
        emit(f"{variant}.both.cpu_s", plan_cpu + eval_cpu)
        results[variant] = (plan_wall + eval_wall, plan_cpu + eval_cpu, observe, eval_dir)
    b, m = results["before"], results["with_map"]
    emit("with_map.observe_ratio", m[2] / b[2])
    emit("plan_then_evaluate.wall_ratio_before_over_with_map", b[0] / m[0])
    emit("plan_then_evaluate.cpu_ratio_before_over_with_map", b[1] / m[1])
    same = (b[3] / "recall.csv").read_text() == (m[3] / "recall.csv").read_text()
    emit("same_recall_csv", same)
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
