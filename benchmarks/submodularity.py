"""How often does the expected-recall objective break diminishing returns? And how tight are the bounds?

``F(T) = sum_p P(s_p(T))`` (docs/design.md section 6c) is monotone but not submodular. This
samples random nested pairs S in T and a tag m outside T (:func:`markerplace.plan.place.upper_bounds.submodularity_sample`)
and prints the share where ``Delta(m | S) < Delta(m | T)``, the worst excess, and the smallest
sampled submodularity ratio (Das & Kempe; a sampled minimum over-estimates the true ratio, so it
is a diagnostic, never a bound), for F and for the mean score (submodular: 0 violations). Then
the expected-recall greedy's predicted recall at k against the valid per-pose upper bound of
any k tags (:func:`markerplace.plan.place.upper_bounds.recall_upper_bound`) and, where there are at
most 5000 k-subsets, the true best k-set by exhaustive search.

Two sources: random synthetic problems with the logistic's midpoint ``--above`` nats over the
median pose score (default), or a plan folder made by ``plan --recall-curve`` (or
``--method expected-recall``): its cached stages and its fitted model (``--plan DIR --scene NAME``,
the same scene and settings the plan had: defaults only).

    .venv/bin/python benchmarks/submodularity.py --trials 400
    .venv/bin/python benchmarks/submodularity.py --scene room --plan out/plan_room_curve --trials 300
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
from pathlib import Path

import numpy as np

from markerplace.pipelines.plan import prepare
from markerplace.plan.config import PlanConfig
from markerplace.plan.place.expected_recall import expected_recall_greedy
from markerplace.plan.place.greedy import apply_coverages
from markerplace.plan.place.recall_curve import recall_curve
from markerplace.plan.place.upper_bounds import recall_upper_bound, submodularity_sample
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.stage import coverages_with_model
from markerplace.plan.score.success_model import SuccessModel
from markerplace.plan.types import MarkerCoverage
from markerplace.scene.spec import SceneSpec

EXHAUSTIVE_MAX = 5000
"""Largest number of k-subsets searched for the true best k-set."""


def synthetic(seed: int, N: int, C: int, above: float, slope: float):
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(N, 6, 6))
    base = 100.0 * np.eye(6) + np.matmul(A, np.swapaxes(A, 1, 2))
    covs = []
    for _ in range(C):
        idx = np.sort(rng.choice(N, size=int(rng.integers(3, N // 2)), replace=False))
        B = rng.normal(size=(len(idx), 6, 2)) * rng.uniform(1, 30)
        covs.append(MarkerCoverage(idx, np.matmul(B, np.swapaxes(B, 1, 2))))
    s0 = float(np.median(-entropy(base)))
    return base, covs, SuccessModel(-slope * (s0 + above), slope, 100, 50, float("nan"), s0 - 10.0)


def from_plan(scene: str, plan_dir: Path):
    config = PlanConfig()
    data = prepare(SceneSpec(scene), config, plan_dir, progress=False)
    model = SuccessModel.from_json(json.loads((plan_dir / "success_model_expected-recall.json").read_text()))
    covs = coverages_with_model(data, "corners", config.noise, config.imaging.camera.K)
    return data.base_info, covs[:data.num_candidates], model


def report(name: str, base, covs, model, trials: int, ks: list[int], seed: int) -> None:
    C = len(covs)
    rng = np.random.default_rng(seed)
    er = submodularity_sample(lambda T: recall_curve(base, covs, T, model)[-1], C, trials, rng)
    sc = submodularity_sample(lambda T: float(np.mean(-entropy(apply_coverages(base, [covs[m] for m in T])))),
                              C, trials, rng)
    print(f"{name}: poses {len(base)}, candidates {C}")
    print(f"  expected_recall_violation_rate: {er['rate']:.3f} ({er['violations']}/{er['trials']}), worst excess "
          f"{100 * er['worst']:.3f} points, sampled ratio min {er['ratio_min']:.3f}")
    print(f"  mean_score_violation_rate: {sc['rate']:.3f}, sampled ratio min {sc['ratio_min']:.3f}")
    for k in ks:
        if k > C:
            continue
        order = expected_recall_greedy(base, covs, k, model).order
        got = recall_curve(base, covs, order, model)[-1]
        ub = recall_upper_bound(base, covs, order, k, model)
        opt = ""
        if math.comb(C, k) <= EXHAUSTIVE_MAX:
            best = max(recall_curve(base, covs, T, model)[-1] for T in itertools.combinations(range(C), k))
            opt = f", best {k}-set (exhaustive) {100 * best:.2f} %"
        print(f"  k={k}: greedy predicted recall {100 * got:.2f} %, upper bound of any {k} tags {100 * ub:.2f} % "
              f"(ratio {got / ub if ub > 0 else float('nan'):.3f}){opt}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--trials", type=int, default=400)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--above", default="-1,0,1,2", help="synthetic: logistic midpoints over the median score, nats")
    ap.add_argument("--scene", default=None)
    ap.add_argument("--plan", default=None, type=Path)
    ap.add_argument("--k", default="3,6,10")
    args = ap.parse_args()
    ks = [int(k) for k in args.k.split(",")]
    if args.scene:
        report(f"{args.scene} ({args.plan})", *from_plan(args.scene, args.plan), args.trials, ks, args.seed)
        return
    for above in (float(a) for a in args.above.split(",")):
        report(f"synthetic, midpoint {above:+g} nats over the median score", *synthetic(args.seed, 60, 14, above, 3.0),
               args.trials, ks, args.seed)


if __name__ == "__main__":
    main()
