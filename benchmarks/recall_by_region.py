"""Recall of an ``evaluate`` run split by where the test images are (regions of the floor plan).

Reads ``query_errors.npz`` and ``test_poses_<set>.npz`` of an ``evaluate`` run folder and prints
a Markdown table: per method and k (mean over runs), the recall at the main threshold
(5 cm / 5 deg) of the test images whose true camera position falls in each region. Regions are
half-planes of the model frame, tested in the order given (an image belongs to the first that
holds it); the rest form one more region. A condition's image set (``weighted@blur``) uses the
poses of its clean set.

    .venv/bin/python benchmarks/recall_by_region.py out/eval_corridor --region 'lobby:x<0' \\
        --region 'corridor:y>5' --rest "guest rooms" [--test-set weighted]
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

import numpy as np

from markerplace.simulation.conditions import split_set
from markerplace.simulation.metrics import MAIN_THRESHOLD, hit_mask

REGION = re.compile(r"^(?P<name>[^:]+):(?P<axis>[xyz])(?P<op>[<>])(?P<value>-?[0-9.]+)$")


def parse_region(text: str) -> tuple[str, int, str, float]:
    """``name:x<0`` -> (name, axis index, '<' or '>', value in model units)."""
    m = REGION.match(text)
    if m is None:
        raise argparse.ArgumentTypeError(f"region {text!r}: use NAME:AXIS<VALUE or NAME:AXIS>VALUE, e.g. lobby:x<0")
    return m["name"], "xyz".index(m["axis"]), m["op"], float(m["value"])


def region_labels(positions: np.ndarray, regions, rest: str) -> np.ndarray:
    """(n,) region name of each (n, 3) position: the first region that holds it, else ``rest``."""
    labels = np.full(len(positions), rest, dtype=object)
    free = np.ones(len(positions), bool)
    for name, axis, op, value in regions:
        inside = positions[:, axis] < value if op == "<" else positions[:, axis] > value
        labels[free & inside] = name
        free &= ~inside
    return labels


def region_table(errors, test_set: str, labels: np.ndarray, names: list[str]) -> str:
    """Markdown table: rows (method, k), columns regions, cells recall % (mean over runs)."""
    method, k = errors[f"{test_set}_method"], errors[f"{test_set}_k"]
    hits = hit_mask(errors[f"{test_set}_t_err"], errors[f"{test_set}_r_err"], *MAIN_THRESHOLD)
    lines = ["| method | k | runs | " + " | ".join(f"{n} ({int((labels == n).sum())} images)" for n in names) + " | all |",
             "|---|---|---|" + "---|" * (len(names) + 1)]
    for m, kk in dict.fromkeys(zip(method.tolist(), k.tolist())):
        rows = hits[(method == m) & (k == kk)].mean(axis=0)
        cells = [f"{100 * rows[labels == n].mean():.1f}" if (labels == n).any() else "-" for n in names]
        lines.append(f"| {m} | {kk} | {int(((method == m) & (k == kk)).sum())} | " + " | ".join(cells)
                     + f" | {100 * rows.mean():.1f} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run_dir", type=Path, help="output folder of `markerplace evaluate`")
    ap.add_argument("--region", type=parse_region, action="append", default=[],
                    help="NAME:AXIS<VALUE or NAME:AXIS>VALUE (model frame, metres); repeat, first match wins")
    ap.add_argument("--rest", default="rest", help="name of the images in no region")
    ap.add_argument("--test-set", default="weighted", help="image set of query_errors.npz, e.g. weighted@blur")
    args = ap.parse_args(argv)
    clean_set, _ = split_set(args.test_set)
    errors_path, poses_path = args.run_dir / "query_errors.npz", args.run_dir / f"test_poses_{clean_set}.npz"
    if not errors_path.is_file():
        print(f"recall_by_region: {errors_path} not found: give the folder of a finished `markerplace evaluate` run",
              file=sys.stderr)
        return 2
    errors = np.load(errors_path, allow_pickle=False)
    if f"{args.test_set}_method" not in errors.files or not poses_path.is_file():
        sets = sorted({f.rsplit("_", 1)[0] for f in errors.files if f.endswith("_method")})
        print(f"recall_by_region: no test set {args.test_set!r} in {args.run_dir}; it has {', '.join(sets)}",
              file=sys.stderr)
        return 2
    positions = np.load(poses_path, allow_pickle=False)["world_from_cam"][:, :3, 3]
    names = list(dict.fromkeys([r[0] for r in args.region] + [args.rest]))
    print(region_table(errors, args.test_set, region_labels(positions, args.region, args.rest), names))
    return 0


if __name__ == "__main__":
    sys.exit(main())
