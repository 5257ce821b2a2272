"""How many renders does ``evaluate --tag-ids candidate`` save over ``--tag-ids order``? Measures it.

With ``order`` a placement's tags show ids 0..k-1 in its own order, so the same spot shows a
different code in different placements (and in the same placement at another k), and a map or
test image that sees it must be rendered again for each. With ``candidate`` the tag on spot c
shows id c everywhere, so an image that sees the same spots under two placements is the same
image, and the render store (``cache/renders``) gives it back instead of rendering it again.

The benchmark runs the same ``markerplace evaluate`` twice: first with ``order`` in
``OUT/order``, then with ``candidate`` in ``OUT/candidate``, which starts as a copy of the
first folder without its renders, predictions and outputs (so the plan, the marker-free
features and the VLAD codebook are shared and only the marker stages run again). It prints
``name: value`` lines per mode (``renders_<mode>``: distinct images rendered with tags, the
store's size; ``seconds_<mode>``: the evaluation's map-with-markers and localize stages, from
``timings.json``; ``recall_omp_<mode>``: OMP's recall per k, from ``recall.csv``) and the ratios
``renders_ratio`` and ``seconds_ratio`` (candidate / order). The two modes draw different tag
codes, so their recalls differ by noise; they are printed to show that, not compared.

    .venv/bin/python benchmarks/tag_ids.py [--scene room] [--tests 200] [--k 5,10] [--runs 2] \\
        [--ceiling] [--out DIR]

Default: the built-in room, 200 weighted test images, k = 5 and 10, 2 random and 2 uniform
runs, with the oracle ceiling (13 single-tag runs), in a temporary folder.
"""

from __future__ import annotations

import argparse
import csv
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from markerplace.testbed.render_store import RenderStore  # noqa: E402

MODES = ("order", "candidate")
#: what the candidate run does not take over from the order run: everything made with tags
NOT_COPIED = ("cache/renders", "cache/predictions")


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = f"{value:.6g}"
    print(f"{name}: {value}", flush=True)


def _evaluate(args, out: Path, mode: str) -> float:
    cmd = [sys.executable, "-m", "markerplace.cli", "--quiet", "evaluate", args.scene, "--out", str(out),
           "--tests", str(args.tests), "--test-sets", "weighted", "--k", args.k,
           "--runs", str(args.runs), "--tag-ids", mode]
    if args.ceiling:
        cmd.append("--ceiling")
    start = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT)
    return time.perf_counter() - start


def _copy_without_tags(src: Path, dst: Path) -> None:
    """``src`` copied to ``dst`` without anything rendered with tags or reported."""
    shutil.copytree(src / "plan", dst / "plan")
    (dst / "cache").mkdir(parents=True)
    for entry in (src / "cache").iterdir():
        if f"cache/{entry.name}" in NOT_COPIED:
            continue
        copy = shutil.copytree if entry.is_dir() else shutil.copy2
        copy(entry, dst / "cache" / entry.name)
    for entry in src.glob("test_poses_*"):
        shutil.copy2(entry, dst / entry.name)


def _omp_recall(out: Path) -> str:
    rows = list(csv.DictReader((out / "recall.csv").open()))
    cells = [f"k={r['k']} {float(r['recall']) * 100:.1f}" for r in rows
             if r["method"] == "omp" and r["test_set"] == "weighted" and r["threshold"] == "5cm/5deg"]
    return ", ".join(cells) or "(not found)"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="room")
    parser.add_argument("--tests", type=int, default=200)
    parser.add_argument("--k", default="5,10")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--ceiling", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--out", type=Path, default=None, help="folder kept after the run")
    args = parser.parse_args(argv)

    base = args.out or Path(tempfile.mkdtemp(prefix="markerplace_tag_ids_"))
    renders, seconds = {}, {}
    for mode in MODES:
        out = base / mode
        if mode == "candidate" and not out.exists():
            _copy_without_tags(base / "order", out)
        wall = _evaluate(args, out, mode)
        timings = json.loads((out / "timings.json").read_text())
        renders[mode] = len(RenderStore(out / "cache" / "renders"))
        seconds[mode] = float(timings["map_with_markers"] + timings["localize"])
        emit(f"renders_{mode}", renders[mode])
        emit(f"seconds_{mode}", seconds[mode])
        emit(f"wall_seconds_{mode}", wall)
        emit(f"recall_omp_{mode}", _omp_recall(out))
    emit("renders_ratio", renders["candidate"] / max(renders["order"], 1))
    emit("seconds_ratio", seconds["candidate"] / max(seconds["order"], 1e-9))
    if args.out is None:
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()
