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
codes, so their recalls differ by noise; how much is printed, not tested: per marker set (method,
run, k) on the same test images, ``flipped_images_mean`` / ``flipped_images_max`` (test images
localized at 5 cm / 5 deg in one mode and not in the other, as a share of the test images) and
``recall_change_mean`` / ``recall_change_max`` (absolute recall change, points).

    .venv/bin/python benchmarks/tag_ids.py [--scene room] [--tests 200] [--k 5,10] [--runs 2] \\
        [--ceiling] [--out DIR] [--report-only]

``--report-only`` prints the figures of an earlier run kept with ``--out`` without running it
again (its ``seconds_*`` are that run's, from ``timings.json``).

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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from markerplace.simulation.metrics import hit_mask  # noqa: E402
from markerplace.simulation.render_store import RenderStore  # noqa: E402

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


def _successes(out: Path) -> tuple[list[tuple], np.ndarray]:
    """(method, run, k) per marker set and its (sets, images) bool success at 5 cm / 5 deg."""
    with np.load(out / "query_errors.npz", allow_pickle=False) as z:
        sets = list(zip(z["weighted_method"].tolist(), z["weighted_run"].tolist(), z["weighted_k"].tolist()))
        success = hit_mask(z["weighted_t_err"], z["weighted_r_err"], 0.05, 5.0)
    return sets, success


def _code_noise(base: Path) -> dict[str, float]:
    """Flipped test images and recall changes between the two modes, over the marker sets with tags."""
    sets_a, ok_a = _successes(base / MODES[0])
    sets_b, ok_b = _successes(base / MODES[1])
    common = [s for s in sets_a if s in sets_b and s[2] > 0]
    flips = np.array([(ok_a[sets_a.index(s)] != ok_b[sets_b.index(s)]).mean() for s in common])
    change = np.array([abs(ok_a[sets_a.index(s)].mean() - ok_b[sets_b.index(s)].mean()) * 100 for s in common])
    return {"marker_sets_compared": len(common), "flipped_images_mean": float(flips.mean()),
            "flipped_images_max": float(flips.max()), "recall_change_mean": float(change.mean()),
            "recall_change_max": float(change.max())}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="room")
    parser.add_argument("--tests", type=int, default=200)
    parser.add_argument("--k", default="5,10")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--ceiling", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--out", type=Path, default=None, help="folder kept after the run")
    parser.add_argument("--report-only", action="store_true", help="print an earlier --out run's figures")
    args = parser.parse_args(argv)
    if args.report_only and args.out is None:
        parser.error("--report-only needs --out, the folder of an earlier run")

    base = args.out or Path(tempfile.mkdtemp(prefix="markerplace_tag_ids_"))
    if not args.report_only and any((base / mode / "timings.json").exists() for mode in MODES):
        parser.error(f"{base} already holds a run (its seconds would be a resumed run's): "
                     "pass --report-only to print it, or a new --out")
    renders, seconds = {}, {}
    for mode in MODES:
        out = base / mode
        if not args.report_only:
            if mode == "candidate" and not out.exists():
                _copy_without_tags(base / "order", out)
            emit(f"wall_seconds_{mode}", _evaluate(args, out, mode))
        timings = json.loads((out / "timings.json").read_text())
        renders[mode] = len(RenderStore(out / "cache" / "renders"))
        seconds[mode] = float(timings["map_with_markers"] + timings["localize"])
        emit(f"renders_{mode}", renders[mode])
        emit(f"seconds_{mode}", seconds[mode])
        emit(f"recall_omp_{mode}", _omp_recall(out))
    emit("renders_ratio", renders["candidate"] / max(renders["order"], 1))
    emit("seconds_ratio", seconds["candidate"] / max(seconds["order"], 1e-9))
    for name, value in _code_noise(base).items():
        emit(name, value)
    if args.out is None:
        shutil.rmtree(base, ignore_errors=True)


if __name__ == "__main__":
    main()
