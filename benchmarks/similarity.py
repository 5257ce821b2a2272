"""Similarity analysis (look-alike counts n_p): FAISS against the pre-FAISS code.

Prints ``name: value`` lines. For each input, three implementations count n_p (cosine > 0.9,
3D distance > 2 m):

* ``faiss``: ``markerplace.plan.similarity.stage.count_similar`` (``auto``: exact ``IndexFlatIP`` up to
  50k points, else the PCA-64 ``IndexIVFFlat`` search);
* ``ref``: the hand-written PCA + inverted file it replaced, kept in
  ``benchmarks/similarity_reference.py`` (``auto``: exact blocks up to 30k points, else approx);
* ``exact``: the exact FAISS path (equal to float64 brute force, see tests/plan/similarity/test_stage.py)
  on ``--sample`` random query points against ALL points: brute force over all P^2 pairs is too
  slow at these sizes, so recall is measured on these queries (printed as ``recall_basis``).

Per implementation: wall and CPU seconds (CPU = all threads of this process), recall of
look-alike pairs on the sampled queries (sum of counts / sum of exact counts), counts exact %,
over-counts (points counted too high: must be 0), and the speedup of ``faiss`` over ``ref``.
Goals: recall >= 0.99 and speedup >= 5x at 1.8M points.

Inputs: ``--points`` synthetic sizes (SIFT-like descriptors with planted look-alikes,
``synthetic_descriptors``, seed 0; default 437000,1800000) and ``--observations`` (real SIFT
points of a plan run: an ``observations.h5`` or a feature folder with ``descriptors.npy`` and
``points_world.npy``). With ``--observations`` the run also measures synthetic points of the
same count (``synthetic_same``) and prints real against synthetic: ``real_over_synthetic_s``
(wall) and ``_cpu``, against the goal (real within 2x, ``real_speed_ok``); ``--repeat N`` times
``faiss`` N times on each, alternating real and synthetic (so a load that comes and goes hits
both), and takes the median. ``--crossover`` times the exact path against the IVF path at smaller
sizes (how ``exact_max_points`` was chosen). ``--threads N`` runs FAISS and the reference's BLAS
on N threads (default: all CPUs).

    .venv/bin/python benchmarks/similarity.py --points 437000
    .venv/bin/python benchmarks/similarity.py --points 1800000 --sample 1000
    .venv/bin/python benchmarks/similarity.py --points 0 --observations out/office/observations
    .venv/bin/python benchmarks/similarity.py --points 0 --no-reference --repeat 3 --observations out/office/observations
    .venv/bin/python benchmarks/similarity.py --points 0 --no-reference --repeat 3 --threads 1 --observations out/office/observations
    .venv/bin/python benchmarks/similarity.py --points 0 --crossover 10000,25000,50000,100000
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path


def _args(argv=None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", default="437000,1800000", help="synthetic sizes, comma-separated (0: none)")
    ap.add_argument("--observations", default=None, help="observations.h5 or feature folder of a plan run")
    ap.add_argument("--sample", type=int, default=2000, help="query points checked against exact counts")
    ap.add_argument("--crossover", default="", help="sizes at which to time exact against ivf")
    ap.add_argument("--threads", type=int, default=0, help="FAISS and BLAS threads (0: all CPUs)")
    ap.add_argument("--no-reference", action="store_true", help="skip the pre-FAISS code")
    ap.add_argument("--repeat", type=int, default=1, help="timed faiss runs on real and same-count synthetic")
    ap.add_argument("--seed", type=int, default=0)
    return ap.parse_args(argv)


ARGS = _args() if __name__ == "__main__" else None
if ARGS is not None and ARGS.threads:  # before numpy loads its BLAS
    os.environ["OPENBLAS_NUM_THREADS"] = os.environ["OMP_NUM_THREADS"] = str(ARGS.threads)

import numpy as np  # noqa: E402

from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.plan.similarity.quality import measure_error, synthetic_descriptors  # noqa: E402
from markerplace.plan.similarity.stage import count_similar, count_similar_exact, count_similar_ivf

sys.path.insert(0, str(Path(__file__).resolve().parent))
from similarity_reference import ReferenceConfig, count_similar_reference  # noqa: E402

GOAL_RECALL = 0.99
GOAL_SPEEDUP = 5.0
GOAL_SPEEDUP_AT = 1_800_000
GOAL_REAL_OVER_SYNTHETIC = 2.0  # issue 37: real SIFT points within 2x of synthetic at the same count


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = f"{value:.6g}"
    print(f"{name}: {value}", flush=True)


def timed(fn, *a, **kw):
    """(result, wall seconds, CPU seconds of all threads)."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn(*a, **kw)
    return out, time.perf_counter() - t0, time.process_time() - c0


def load_observations(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(P, 128) descriptors and (P, 3) points of a plan run; rows without a 3D point dropped."""
    p = Path(path)
    if p.is_dir():
        D = np.load(p / "descriptors.npy")
        X = np.load(p / "points_world.npy")
    else:
        import h5py

        with h5py.File(p, "r") as f:
            D, X = f["descriptors"][:], f["points_world"][:]
    ok = np.all(np.isfinite(X), axis=1)
    return D[ok], X[ok].astype(np.float64)


def compare(tag: str, D: np.ndarray, X: np.ndarray, args) -> tuple[float, float]:
    """Time faiss and ref on (D, X) and measure both against exact counts of sampled queries;
    returns faiss's (wall, CPU) seconds."""
    P = len(D)
    emit(f"{tag}_points", P)
    cfg = SimilarityConfig(threads=args.threads)
    rng = np.random.default_rng(args.seed)
    sample = np.sort(rng.choice(P, size=min(args.sample, P), replace=False))
    exact, wall, cpu = timed(count_similar_exact, D, X, cfg, queries=sample)
    emit(f"{tag}_recall_basis", f"exact FAISS IndexFlatIP (= float64 brute force) on {len(sample)} "
                                f"random query points against all {P}")
    emit(f"{tag}_exact_sample_s", wall)
    emit(f"{tag}_exact_mean_n_p", float(exact.mean()))
    runs = {"faiss": lambda: count_similar(D, X, cfg)}
    if not args.no_reference:
        runs["ref"] = lambda: count_similar_reference(D, X, ReferenceConfig())
    walls = {}
    for name, fn in runs.items():
        n, wall, cpu = timed(fn)
        walls[name] = (wall, cpu)
        m = measure_error(n[sample], exact)
        emit(f"{tag}_{name}_s", wall)
        emit(f"{tag}_{name}_cpu_s", cpu)
        emit(f"{tag}_{name}_mean_n_p", float(n.mean()))
        emit(f"{tag}_{name}_recall", m["recall"])
        emit(f"{tag}_{name}_counts_exact_pct", 100.0 * m["frac_points_exact"])
        emit(f"{tag}_{name}_mean_abs_error", m["mean_abs_error"])
        emit(f"{tag}_{name}_over_counts", m["over_counts"])
        if name == "faiss":
            emit(f"{tag}_faiss_recall_goal", GOAL_RECALL)
            emit(f"{tag}_faiss_recall_ok", m["recall"] >= GOAL_RECALL and m["over_counts"] == 0)
    if "ref" in walls:
        speed = walls["ref"][0] / walls["faiss"][0]
        emit(f"{tag}_speedup", speed)
        emit(f"{tag}_speedup_cpu", walls["ref"][1] / walls["faiss"][1])
        if P >= GOAL_SPEEDUP_AT:
            emit(f"{tag}_speedup_goal", GOAL_SPEEDUP)
            emit(f"{tag}_speedup_ok", speed >= GOAL_SPEEDUP)
    return walls["faiss"]


def real_against_synthetic(D: np.ndarray, X: np.ndarray, args) -> None:
    """Real points against synthetic points of the same count: accuracy of each, then the
    median of ``--repeat`` timed runs, alternating, and their ratio against the goal."""
    P = len(D)
    Ds, Xs = synthetic_descriptors(P, seed=args.seed)
    first = {"real": compare("real", D, X, args), "synthetic_same": compare("synthetic_same", Ds, Xs, args)}
    times = {k: [v] for k, v in first.items()}
    cfg = SimilarityConfig(threads=args.threads)
    for _ in range(args.repeat - 1):
        for tag, (d, x) in (("real", (D, X)), ("synthetic_same", (Ds, Xs))):
            _, wall, cpu = timed(count_similar, d, x, cfg)
            times[tag].append((wall, cpu))
    med = {k: np.median(np.array(v), axis=0) for k, v in times.items()}
    for tag in times:
        emit(f"{tag}_faiss_runs_s", " ".join(f"{w:.2f}" for w, _ in times[tag]))
        emit(f"{tag}_faiss_median_s", float(med[tag][0]))
        emit(f"{tag}_faiss_median_cpu_s", float(med[tag][1]))
    ratio = float(med["real"][0] / med["synthetic_same"][0])
    emit("real_over_synthetic_s", ratio)
    emit("real_over_synthetic_cpu", float(med["real"][1] / med["synthetic_same"][1]))
    emit("real_over_synthetic_goal", GOAL_REAL_OVER_SYNTHETIC)
    emit("real_speed_ok", ratio <= GOAL_REAL_OVER_SYNTHETIC)


def crossover(sizes: list[int], args) -> None:
    """Exact against ivf at each size (synthetic): where ``auto`` should switch."""
    cfg = SimilarityConfig(threads=args.threads)
    for P in sizes:
        D, X = synthetic_descriptors(P, seed=args.seed)
        _, we, _ = timed(count_similar_exact, D, X, cfg)
        _, wi, _ = timed(count_similar_ivf, D, X, cfg)
        emit(f"crossover_{P}_exact_s", we)
        emit(f"crossover_{P}_ivf_s", wi)
        emit(f"crossover_{P}_exact_over_ivf", we / wi)
    emit("crossover_exact_max_points", SimilarityConfig().exact_max_points)


def main(args) -> None:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    emit("cpus", len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count())
    emit("threads", args.threads or "all")
    emit("load_average_1min_at_start", load)
    for P in [int(s) for s in args.points.split(",") if int(s) > 0]:
        t0 = time.perf_counter()
        D, X = synthetic_descriptors(P, seed=args.seed)
        emit(f"synthetic_{P}_generate_s", time.perf_counter() - t0)
        compare(f"synthetic_{P}", D, X, args)
        del D, X
    if args.observations:
        D, X = load_observations(args.observations)
        real_against_synthetic(D, X, args)
    if args.crossover:
        crossover([int(s) for s in args.crossover.split(",")], args)
    if hasattr(os, "getloadavg"):
        emit("load_average_1min_at_end", os.getloadavg()[0])


if __name__ == "__main__":
    main(ARGS)
