"""Similarity analysis (look-alike counts n_p): speed and approximation error.

Prints ``name: value`` lines.

* real: the SIFT points of a planned scene (``--observations``, an ``observations.h5`` written
  by ``markerplace plan``; default: plan ``--scene`` into a temporary directory first): time of
  ``count_similar`` (auto -> approx above 30k points) and the approximation error against exact
  brute force on a random sample of ``--sample`` points (exact is O(P^2)).
* synthetic: ``--synthetic`` SIFT-like descriptors with planted near-duplicates (stress size).

    .venv/bin/python benchmarks/similarity.py [--observations out/office/observations.h5] [--synthetic 200000]
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from markerplace.plan.observe import Observations, SceneSpec
from markerplace.plan.similarity import SimilarityConfig, benchmark_similarity, count_similar, measure_error


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = round(value, 4)
    print(f"{name}: {value}", flush=True)


def real(args) -> None:
    path = args.observations
    tmp = None
    if path is None:
        from markerplace.plan.planner import PlanConfig, prepare

        tmp = tempfile.TemporaryDirectory()
        prepare(SceneSpec(args.scene), PlanConfig(), tmp.name, progress=False)
        path = f"{tmp.name}/observations.h5"
    obs = Observations.load(path)
    config = SimilarityConfig()
    emit("real_points", len(obs.pose_index))
    emit("real_points_per_pose", len(obs.pose_index) / max(obs.num_poses, 1))
    t0 = time.perf_counter()
    n = count_similar(obs.descriptors, obs.points_world, config)
    emit("real_count_similar_s", time.perf_counter() - t0)
    emit("real_mean_n_p", float(n.mean()))
    rng = np.random.default_rng(0)
    idx = rng.choice(len(n), size=min(args.sample, len(n)), replace=False)
    err = measure_error(obs.descriptors[idx], obs.points_world[idx], config)
    for k, v in err.items():
        emit(f"real_sample_{k}", v)
    if tmp is not None:
        tmp.cleanup()


def synthetic(args) -> None:
    res = benchmark_similarity(args.synthetic, seed=0)
    for k, v in res.items():
        emit(f"synthetic_{k}", v)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--observations", default=None, help="observations.h5 of a plan run")
    ap.add_argument("--scene", default="office", help="scene to plan when no --observations is given")
    ap.add_argument("--sample", type=int, default=20000, help="points checked against exact counts")
    ap.add_argument("--synthetic", type=int, default=200000, help="synthetic points (0: skip)")
    args = ap.parse_args(argv)
    real(args)
    if args.synthetic:
        synthetic(args)


if __name__ == "__main__":
    main()
