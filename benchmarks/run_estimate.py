"""How honest is the run-size estimate: ``plan`` on room, house and a scan-like house, each into a
fresh folder as a separate process (as a user runs it), its logged estimate against the
measured wall time.

Prints ``name: value`` lines: per scene the estimated and measured seconds and their ratio
(goal: within 2x either way, README), plus the estimate's parts.

    .venv/bin/python benchmarks/run_estimate.py [--scenes room,house,house-scan] [--work out/bench_estimate]
    .venv/bin/python benchmarks/run_estimate.py --scenes campus --args="--grid-spacing 1.0"  # 12,464 poses

``house-scan`` is ``scene export house --as-scan`` (cached in ``--work``), planned with ``--up z``.
"""

from __future__ import annotations

import argparse
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

GOAL_RATIO = 2.0
ESTIMATE = re.compile(r"run size: (\d+) poses; .* took (\d+) ms each .*?so about (.+?) to render.*?, (.+?) for the "
                      r"look-alikes \((\d+) points\), (.+?) for the outputs.*?about (.+?) in all")


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = f"{value:.6g}"
    print(f"{name}: {value}", flush=True)


def seconds(text: str) -> float:
    """'1 h 05 min', '2 min 03 s', '42 s' -> seconds."""
    total = 0.0
    for num, unit in re.findall(r"(\d+) (h|min|s)\b", text):
        total += float(num) * {"h": 3600, "min": 60, "s": 1}[unit]
    return total


def markerplace_exe() -> str:
    """The ``markerplace`` command of this interpreter's environment."""
    return str(Path(sys.executable).with_name("markerplace"))


def house_scan(work: Path) -> Path:
    """``scene export house --as-scan`` cached as ``work/house_scan.ply`` (exported when missing)."""
    scan = work / "house_scan.ply"
    if not scan.exists():
        subprocess.run([markerplace_exe(), "--quiet", "scene", "export", "house", str(scan), "--as-scan"], check=True)
    return scan


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="room,house,house-scan")
    ap.add_argument("--work", default="out/bench_estimate")
    ap.add_argument("-k", type=int, default=10)
    ap.add_argument("--args", default="", help="more plan options for every scene, e.g. --args='--grid-spacing 1.0'")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    exe = markerplace_exe()
    worst = 1.0
    for name in args.scenes.split(","):
        scene_args = [name]
        if name == "house-scan":
            scene_args = [str(house_scan(work)), "--up", "z"]
        out = work / f"plan_{name}"
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.perf_counter()
        run = subprocess.run([exe, "plan", *scene_args, "-k", str(args.k), "--out", str(out), *args.args.split()],
                             capture_output=True, text=True)
        measured = time.perf_counter() - t0
        if run.returncode != 0:
            print(run.stderr[-2000:], file=sys.stderr)
            return 1
        m = ESTIMATE.search(run.stderr)
        if m is None:
            print(run.stderr[-2000:], file=sys.stderr)
            return 1
        poses, ms, observe, sim, points, outputs, total = m.groups()
        estimated = seconds(total)
        ratio = measured / estimated
        worst = max(worst, ratio, 1.0 / ratio)
        stage = dict(re.findall(r"(\w+) (\d+\.\d+)", run.stderr.split("stage seconds:")[-1].splitlines()[0]))
        emit(f"{name}.poses", int(poses))
        emit(f"{name}.sample_ms_per_pose", int(ms))
        emit(f"{name}.estimate.observe_s", seconds(observe))
        emit(f"{name}.measured.observe_s", float(stage.get("observe", "nan")))
        emit(f"{name}.estimate.similarity_s", seconds(sim))
        emit(f"{name}.measured.similarity_s", float(stage.get("similarity", "nan")))
        emit(f"{name}.estimate.total_s", estimated)
        emit(f"{name}.measured.total_s", measured)
        emit(f"{name}.measured_over_estimate", ratio)
    emit("worst_ratio", worst)
    emit("goal_ratio", GOAL_RATIO)
    emit("goal_met", worst <= GOAL_RATIO)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
