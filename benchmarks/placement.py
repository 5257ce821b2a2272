"""Planner speed: localizability scoring and greedy placement.

Prints ``name: value`` lines.

* part a, scoring throughput: batched :func:`pose_information` for ``--poses`` poses x
  ``--landmarks`` landmarks each, against the per-pose GTSAM factor-graph reference (the paper's
  graph: camera prior, projection factors, landmark priors, ``Marginals``) on identical inputs,
  timed on ``--ref-poses`` poses. Goal: speedup >= 1000x. The batched kernel is timed with all
  numba threads (what ``plan`` uses) and with one thread; GTSAM runs on one thread.
* part b, greedy: OMP with k = ``--k`` on ``--grid`` x ``--grid`` locations x 8 yaws (>= 10,000
  poses) and ``--candidates`` wall candidates ('paper' marker model, visibility rules), plain
  vs lazy: seconds, evaluations, identical picks. Goal: lazy < 5 s.
* part c, end to end: ``plan office -k 20`` (discretize, observe, similarity, score, place) in
  a fresh run directory: seconds per stage and peak resident memory of the main process and of
  the largest worker. Goal: < 5 min, < 4 GB.

    .venv/bin/python benchmarks/placement.py [--part a|b|c|all] [--seed 0]

To add a part, write ``def part_x(args) -> None`` printing ``name: value`` lines and register it
in ``PARTS``.
"""

from __future__ import annotations

import argparse
import time
from typing import Callable

import numba
import numpy as np

from markerplace.geometry import Intrinsics, world_from_cam_poses, world_from_marker_pose
from markerplace.plan.place.greedy import omp_greedy
from markerplace.plan.score.localizability import NoiseConfig, entropy, marker_visibility, pose_information
from markerplace.plan.score.marker_models import get_marker_model
from markerplace.plan.types import MarkerCoverage

GOAL_SPEEDUP = 1000.0
GOAL_LAZY_S = 5.0


def emit(name: str, value) -> None:
    """One ``name: value`` benchmark line."""
    if isinstance(value, float):
        value = f"{value:.6g}"
    print(f"{name}: {value}", flush=True)


def synthetic_observations(rng: np.random.Generator, n_poses: int, per_pose: int, intr: Intrinsics,
                           room: float = 10.0, max_depth: float = 6.0):
    """Level cameras at 1.5 m and ``per_pose`` landmarks per pose inside the image, 0.5 m to
    ``max_depth`` deep (all within 10 m). Returns (N,4,4) poses, (P,3) points, (P,) pose index,
    (P,) look-alike counts, grouped by pose."""
    T = world_from_cam_poses(np.c_[rng.uniform(0, room, (n_poses, 2)), np.full(n_poses, 1.5)],
                             rng.uniform(0, 2 * np.pi, n_poses))
    K = intr.K
    z = rng.uniform(0.5, max_depth, (n_poses, per_pose))
    u = rng.uniform(0, intr.width, (n_poses, per_pose))
    v = rng.uniform(0, intr.height, (n_poses, per_pose))
    pc = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], -1)
    pw = np.einsum("nij,nmj->nmi", T[:, :3, :3], pc) + T[:, None, :3, 3]
    idx = np.repeat(np.arange(n_poses), per_pose)
    n_sim = rng.integers(0, 21, n_poses * per_pose)
    return T, pw.reshape(-1, 3), idx, n_sim


def gtsam_reference(T: np.ndarray, pts: np.ndarray, n_sim: np.ndarray, K: np.ndarray,
                    noise: NoiseConfig) -> np.ndarray:
    """The paper's per-pose factor graph in GTSAM: (6, 6) marginal covariance of the camera."""
    import gtsam
    from gtsam.symbol_shorthand import L, X

    cal = gtsam.Cal3_S2(K[0, 0], K[1, 1], 0.0, K[0, 2], K[1, 2])
    pix = gtsam.noiseModel.Isotropic.Sigma(2, noise.pixel_sigma)
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    pose = gtsam.Pose3(T)
    values.insert(X(0), pose)
    graph.add(gtsam.PriorFactorPose3(X(0), pose, gtsam.noiseModel.Isotropic.Sigma(6, noise.prior_sigma)))
    cam = gtsam.PinholeCameraCal3_S2(pose, cal)
    for i, p in enumerate(pts):
        graph.add(gtsam.GenericProjectionFactorCal3_S2(cam.project(p), pix, X(0), L(i), cal))
        s = noise.landmark_sigma * np.sqrt(1.0 + n_sim[i])
        graph.add(gtsam.PriorFactorPoint3(L(i), p, gtsam.noiseModel.Isotropic.Sigma(3, s)))
        values.insert(L(i), p)
    return gtsam.Marginals(graph, values).marginalCovariance(X(0))


def part_a(args) -> None:
    """Scoring throughput: batched closed form vs per-pose GTSAM graphs."""
    rng = np.random.default_rng(args.seed)
    intr = Intrinsics()
    K = intr.K
    noise = NoiseConfig()
    T, pts, idx, n_sim = synthetic_observations(rng, args.poses, args.landmarks, intr)
    pose_information(T[:10], K, pts[idx < 10], idx[idx < 10], n_sim[idx < 10], noise)  # warm-up/JIT

    def best_of(threads: int) -> tuple[float, np.ndarray]:
        numba.set_num_threads(threads)
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            lam = pose_information(T, K, pts, idx, n_sim, noise)
            times.append(time.perf_counter() - t0)
        return min(times), lam

    threads = numba.config.NUMBA_NUM_THREADS
    batched_1, _ = best_of(1)
    batched, lam = best_of(threads)
    n_ref = min(args.ref_poses, args.poses)
    t0 = time.perf_counter()
    diffs = []
    for n in range(n_ref):
        sel = slice(n * args.landmarks, (n + 1) * args.landmarks)
        cov = gtsam_reference(T[n], pts[sel], n_sim[sel], K, noise)
        ld_ref = np.linalg.slogdet(cov)[1]
        diffs.append(abs(-np.linalg.slogdet(lam[n])[1] - ld_ref) / abs(ld_ref))
    ref = (time.perf_counter() - t0) / n_ref
    per_pose = batched / args.poses
    emit("scoring_poses", args.poses)
    emit("scoring_landmarks_per_pose", args.landmarks)
    emit("scoring_threads", threads)
    emit("scoring_batched_s", batched)
    emit("scoring_batched_ms_per_pose", per_pose * 1e3)
    emit("scoring_batched_1thread_ms_per_pose", batched_1 / args.poses * 1e3)
    emit("scoring_gtsam_ref_poses", n_ref)
    emit("scoring_gtsam_ms_per_pose", ref * 1e3)
    emit("scoring_speedup", ref / per_pose)
    emit("scoring_speedup_1thread", ref / (batched_1 / args.poses))
    emit("scoring_goal_speedup", GOAL_SPEEDUP)
    emit("scoring_max_rel_logdet_diff", float(max(diffs)))
    emit("scoring_mean_entropy", float(entropy(lam).mean()))


def synthetic_placement_problem(rng: np.random.Generator, grid: int, n_candidates: int,
                                spacing: float = 0.7, landmarks_max: int = 200,
                                marker_range: float = 8.0):
    """A square room with ``grid``^2 locations x 8 yaws and wall candidates ('paper' model).

    Base information from random landmarks (0..``landmarks_max`` per pose, so localizability
    varies); candidates evenly spaced along the 4 walls at 1.5 m; coverage by
    :func:`marker_visibility` with range ``marker_range``.
    """
    intr = Intrinsics()
    K = intr.K
    side = grid * spacing
    xy = (np.stack(np.meshgrid(np.arange(grid), np.arange(grid), indexing="ij"), -1).reshape(-1, 2) + 0.5) * spacing
    yaws = np.arange(8) * np.pi / 4
    pos = np.c_[np.repeat(xy, 8, axis=0), np.full(len(xy) * 8, 1.5)]
    T = world_from_cam_poses(pos, np.tile(yaws, len(xy)))
    N = T.shape[0]
    counts = rng.integers(0, landmarks_max + 1, N)
    idx = np.repeat(np.arange(N), counts)
    z = rng.uniform(0.5, 8.0, len(idx))
    u = rng.uniform(0, intr.width, len(idx))
    v = rng.uniform(0, intr.height, len(idx))
    pc = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], -1)
    pw = np.einsum("pij,pj->pi", T[idx, :3, :3], pc) + T[idx, :3, 3]
    base = pose_information(T, K, pw, idx, rng.integers(0, 21, len(idx)))
    s = (np.arange(n_candidates) + 0.5) * 4 * side / n_candidates
    coverages = []
    for a in s:
        wall, d = int(a // side), a % side
        centre, normal = [
            (np.array([d, 0.0, 1.5]), np.array([0.0, 1.0, 0.0])),
            (np.array([side, d, 1.5]), np.array([-1.0, 0.0, 0.0])),
            (np.array([side - d, side, 1.5]), np.array([0.0, -1.0, 0.0])),
            (np.array([0.0, side - d, 1.5]), np.array([1.0, 0.0, 0.0])),
        ][wall]
        Tm = world_from_marker_pose(centre, normal)
        vis = marker_visibility(T, Tm, K, (intr.width, intr.height), max_range=marker_range)
        coverages.append(MarkerCoverage(np.flatnonzero(vis), get_marker_model("paper").information(T[vis], Tm, 0.4, K)))
    return base, coverages


def part_b(args) -> None:
    """Greedy placement: plain vs lazy on >= 10,000 poses and >= 500 candidates."""
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    base, covs = synthetic_placement_problem(rng, args.grid, args.candidates)
    setup = time.perf_counter() - t0
    results = {}
    for lazy in (False, True):
        t0 = time.perf_counter()
        results[lazy] = (omp_greedy(base, covs, args.k, v=90.0, lazy=lazy), time.perf_counter() - t0)
    (plain, t_plain), (lazy_r, t_lazy) = results[False], results[True]
    emit("greedy_poses", base.shape[0])
    emit("greedy_candidates", len(covs))
    emit("greedy_mean_poses_per_candidate", float(np.mean([len(c) for c in covs])))
    emit("greedy_setup_s", setup)
    emit("greedy_k", args.k)
    emit("greedy_q", plain.q)
    emit("greedy_plain_s", t_plain)
    emit("greedy_plain_evaluations", plain.evaluations)
    emit("greedy_lazy_s", t_lazy)
    emit("greedy_lazy_evaluations", lazy_r.evaluations)
    emit("greedy_lazy_speedup", t_plain / t_lazy)
    emit("greedy_identical", lazy_r.order == plain.order and lazy_r.gains == plain.gains)
    emit("greedy_goal_lazy_s", GOAL_LAZY_S)
    emit("greedy_first_gains", " ".join(f"{g:.3f}" for g in lazy_r.gains[:5]))


def part_c(args) -> None:
    """End to end `plan SCENE -k 20` in a fresh run directory: seconds per stage, peak memory."""
    import resource
    import tempfile

    from markerplace.pipelines.plan import prepare
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.place.config import PlacementConfig
    from markerplace.plan.place.stage import place
    from markerplace.scene.spec import SceneSpec

    config = PlanConfig(placement=PlacementConfig(k=args.k))
    with tempfile.TemporaryDirectory() as run_dir:
        t0 = time.perf_counter()
        data = prepare(SceneSpec(args.scene), config, run_dir, progress=False)
        t1 = time.perf_counter()
        result = place(data, config.placement, progress=False)
        t2 = time.perf_counter()
    emit("plan_scene", args.scene)
    emit("plan_poses", len(data.disc.world_from_cam))
    emit("plan_candidates", data.num_candidates)
    for stage, seconds in data.timings.items():
        emit(f"plan_{stage}_s", round(seconds, 2))
    emit("plan_place_s", round(t2 - t1, 3))
    emit("plan_total_s", round(t2 - t0, 2))
    emit("plan_goal_total_s", 300)
    emit("plan_markers", len(result.markers))
    main_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    child_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    emit("plan_peak_rss_main_mb", round(main_mb, 1))
    emit("plan_peak_rss_worker_mb", round(child_mb, 1))
    emit("plan_goal_peak_mb", 4096)


PARTS: dict[str, Callable] = {"a": part_a, "b": part_b, "c": part_c}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=[*PARTS, "all"], default="all")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--poses", type=int, default=2000, help="part a: poses")
    ap.add_argument("--landmarks", type=int, default=1000, help="part a: landmarks per pose")
    ap.add_argument("--ref-poses", type=int, default=20, help="part a: poses timed with GTSAM")
    ap.add_argument("--repeats", type=int, default=3, help="part a: timing repeats (best of)")
    ap.add_argument("--grid", type=int, default=36, help="part b: locations per side (x 8 yaws)")
    ap.add_argument("--candidates", type=int, default=500, help="part b: candidate markers")
    ap.add_argument("--k", type=int, default=20, help="parts b, c: markers to place")
    ap.add_argument("--scene", default="office", help="part c: scene to plan in (default office)")
    args = ap.parse_args(argv)
    for name, fn in PARTS.items():
        if args.part in (name, "all"):
            fn(args)


if __name__ == "__main__":
    main()
