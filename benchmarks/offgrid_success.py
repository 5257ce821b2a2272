"""How often do off-grid calibration renders localize, overall and per storey, against the test images?

Reads a plan folder made with ``--method expected-recall --calibration-poses offgrid`` (its
cached no-marker predictions of the off-grid renders, ``calibration/predictions``) and,
optionally, an ``evaluate`` folder of the same scene (``query_errors.npz``), and prints
``name: value`` lines: no-marker success rate of the off-grid renders and of the test images,
per storey, and the failure rate per score quartile (quartile edges from the off-grid renders'
scores, so both sets share them). Successes are within the main threshold (5 cm, 5 deg).

    .venv/bin/python benchmarks/offgrid_success.py out/house_er_offgrid --eval out/eval_house
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from markerplace.plan.discretize import artifact as discretization
from markerplace.simulation.metrics import MAIN_THRESHOLD, hit_mask, pose_errors_batch
from markerplace.simulation.success_fit import offgrid_poses


def _no_marker_prediction(plan_dir: Path) -> np.ndarray:
    for meta in sorted((plan_dir / "calibration" / "predictions").glob("*.npz.meta.json")):
        m = json.loads(meta.read_text())
        if m["method"] == "none" and m["test_set"] == "calibration":
            return np.load(meta.with_name(meta.name[: -len(".meta.json")]))["est"]
    raise SystemExit(f"{plan_dir}: no off-grid no-marker prediction; plan with --calibration-poses offgrid")


def _report(name: str, ok: np.ndarray, storey: np.ndarray, score: np.ndarray, edges: np.ndarray) -> None:
    print(f"{name}_images: {len(ok)}")
    print(f"{name}_no_marker_success: {ok.mean():.3f}")
    quart = np.searchsorted(edges, score)
    for s in np.unique(storey):
        m = storey == s
        print(f"{name}_storey{s}_images: {int(m.sum())}")
        print(f"{name}_storey{s}_no_marker_success: {ok[m].mean():.3f}")
        print(f"{name}_storey{s}_mean_score: {score[m].mean():.2f}")
        for q in range(4):
            mq = m & (quart == q)
            rate = f"{1.0 - ok[mq].mean():.3f}" if mq.any() else "nan"
            print(f"{name}_storey{s}_failure_quartile{q + 1}: {rate}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan_dir", help="folder of `markerplace plan --calibration-poses offgrid`")
    ap.add_argument("--eval", help="folder of `markerplace evaluate` on the same scene (optional)")
    ap.add_argument("--test-set", default="weighted")
    ap.add_argument("--images", type=int, default=1000, help="calibration_images of the plan (default 1000)")
    ap.add_argument("--seed", type=int, default=0, help="calibration_seed of the plan (default 0)")
    args = ap.parse_args(argv)
    plan_dir = Path(args.plan_dir)
    disc = discretization.load(plan_dir / "discretization.npz")
    scores = np.load(plan_dir / "scores.npz")["score_before"]
    spacing = json.loads((plan_dir / "config.json").read_text())["discretize"]["grid_spacing"]
    queries = offgrid_poses(SimpleNamespace(disc=disc, base_score=scores), spacing, args.images, args.seed)
    est = _no_marker_prediction(plan_dir)
    ok = hit_mask(*pose_errors_batch(est, queries.world_from_cam), *MAIN_THRESHOLD)
    score = scores[queries.source_index]
    edges = np.quantile(score, [0.25, 0.5, 0.75])
    _report("offgrid", ok, disc.pose_storey[queries.source_index], score, edges)
    if args.eval:
        q = np.load(Path(args.eval) / "query_errors.npz")
        ts = args.test_set
        none = int(np.flatnonzero(q[f"{ts}_method"] == "none")[0])
        tok = (q[f"{ts}_t_err"][none] <= MAIN_THRESHOLD[0]) & (q[f"{ts}_r_err"][none] <= MAIN_THRESHOLD[1])
        height = q[f"{ts}_world_from_cam"][:, 2, 3]  # eye level lies above its storey's floor
        storey = np.searchsorted(np.asarray(disc.storeys, float), height, side="right") - 1
        _report(ts, tok, storey, q[f"{ts}_score"], edges)


if __name__ == "__main__":
    main()
