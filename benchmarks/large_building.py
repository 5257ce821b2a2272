"""Large building: plan the built-in ``campus`` (2,064 m^2, two storeys) end to end on a Dask
cluster and project the observe stage onto bigger clusters.

Prints ``name: value`` lines.

* end to end: ``prepare`` + ``place`` (OMP, ``--k`` markers) with ``PlanConfig.runtime =
  RuntimeConfig(cluster=--cluster)`` (default ``local:2``, a Dask ``LocalCluster`` of 2
  single-threaded workers started by the observe stage) in a fresh run folder. Per stage (load,
  discretize, observe, similarity, score, place): seconds and peak resident memory of the main
  process, of all workers together and of the largest worker (sampled every 0.5 s); the time
  between the timed stages (geometric marker visibility) is ``other``. Also: poses, candidates,
  features, and the observe stage's cost per pose (wall seconds, worker seconds, main-process
  CPU seconds).
* calibration, after the plan, on ``--calibration-poses`` poses spread evenly over the same
  discretization: the observe stage's own function on an in-process executor (warm: the per-pose
  cost on one core, no executor) and on a fresh cluster of the same kind (its start-up, the
  worker warm-up, then the steady cost per pose). Both in wall seconds and in CPU seconds (this
  process; the workers): on a shared machine wall time includes waiting for a core
  (``calib_wait_factor`` = worker wall seconds / worker CPU seconds). The workers' extra CPU per
  pose over the in-process run is the executor's overhead on the workers; with the main
  process's CPU per pose (results, scheduler) times the batch size (poses per task) it is the
  per-task overhead.
* projection of the observe stage on 16 and 64 workers (``--project``), assuming linear
  scaling: ``T(W) = start + warm-up + N * c / W``, c the measured worker CPU seconds per pose on
  the cluster (compute plus per-task overhead), one free core per worker, start-up and warm-up
  as measured here, and never faster than the main process takes results (``N * m``, m its
  measured CPU seconds per pose; ``projection_main_limited_above_workers`` = c / m). At this
  run's worker count the model is given twice, with c and with the measured wall cost, to set
  against ``stage_observe_s``. The other stages run in the main process and do not scale with
  workers; ``projection_total_s_wW`` adds them as measured. ``--project-spacing 0.5``
  discretizes at 0.5 m too (timed) and projects its observe stage the same way.

    .venv/bin/python benchmarks/large_building.py [--grid-spacing 0.5] [--cluster local:2] [--k 20]

The full run at the default 0.5 m renders ~44k poses (well over an hour on 2 shared cores);
``--grid-spacing 1.0 --project-spacing 0.5`` renders ~12.5k and projects the 0.5 m observe stage.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil
from scan_plan import MemorySampler, emit  # benchmarks/ is on sys.path when run as a script

STAGES = ("load", "discretize", "observe", "similarity", "score")


class StageSampler(MemorySampler):
    """:class:`MemorySampler` that also records, per sample, the resident memory of the largest
    child process (one worker) and the main process's CPU seconds."""

    def __init__(self, period: float = 0.5):
        super().__init__(period)
        self.extra: list[tuple[float, float, float]] = []  # (t, largest child MB, main CPU s)

    def _run(self) -> None:
        while not self._stop.is_set():
            main = self.proc.memory_info().rss
            cpu = self.proc.cpu_times()
            kids = []
            for c in self.proc.children(recursive=True):
                try:
                    kids.append(c.memory_info().rss)
                except psutil.Error:
                    pass
            t = time.perf_counter()
            self.samples.append((t, main / 2**20, sum(kids) / 2**20))
            self.extra.append((t, max(kids, default=0) / 2**20, cpu.user + cpu.system))
            self._stop.wait(self.period)

    def largest_child(self, t0: float, t1: float) -> float:
        """Peak MB of the largest single child between two perf_counter times."""
        s = [m for t, m, _ in self.extra if t0 <= t <= t1]
        return max(s) if s else float("nan")

    def cpu_seconds(self, t0: float, t1: float) -> float:
        """Main-process CPU seconds between the samples nearest to t0 and t1."""
        if not self.extra:
            return float("nan")
        a = min(self.extra, key=lambda x: abs(x[0] - t0))
        b = min(self.extra, key=lambda x: abs(x[0] - t1))
        return b[2] - a[2]


def stage_windows(timings: dict, t0: float, t1: float) -> dict[str, tuple[float, float]]:
    """(start, end) perf_counter times of each timed stage of ``prepare`` that ran from t0 to t1.

    ``load`` and ``discretize`` run back to back from t0; ``observe``, ``similarity`` and
    ``score`` back to back up to t1; what lies between (the geometric visibility of the
    candidates) is ``other``.
    """
    win, t = {}, t0
    for name in ("load", "discretize"):
        win[name] = (t, t + timings.get(name, 0.0))
        t = win[name][1]
    end = t1
    for name in ("score", "similarity", "observe"):
        win[name] = (end - timings.get(name, 0.0), end)
        end = win[name][0]
    win["other"] = (t, end)
    return win


def plan_end_to_end(args, run_dir: Path):
    """Plan ``args.scene`` in ``run_dir``; returns (data, placement, sampler, windows, config)."""
    from markerplace.pipelines.plan import prepare
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import DiscretizeConfig
    from markerplace.plan.place.config import PlacementConfig
    from markerplace.plan.place.stage import place
    from markerplace.runtime.executor import RuntimeConfig
    from markerplace.scene.spec import SceneSpec

    config = PlanConfig(discretize=DiscretizeConfig(grid_spacing=args.grid_spacing),
                        placement=PlacementConfig(k=args.k), runtime=RuntimeConfig(cluster=args.cluster))
    with StageSampler() as mem:
        t0 = time.perf_counter()
        data = prepare(SceneSpec(args.scene), config, run_dir, progress=False)
        t1 = time.perf_counter()
        placement = place(data, config.placement, progress=False)
        t2 = time.perf_counter()
    windows = stage_windows(data.timings, t0, t1)
    windows["place"] = (t1, t2)
    windows["total"] = (t0, t2)
    return data, placement, mem, windows, config


def _cpu_seconds(procs) -> float:
    """User + system CPU seconds of ``procs`` (processes that are gone count 0)."""
    total = 0.0
    for p in procs:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.Error:
            pass
    return total


def calibrate(args, data, config, scratch: Path) -> dict:
    """Per-pose observe cost in process and on a fresh cluster (see the module docstring):
    wall seconds and CPU seconds (of this process, and of the workers), so that waiting for a
    core on a shared machine can be told apart from work."""
    from markerplace.plan.observe import observe
    from markerplace.plan.score.stage import geometric_visibility
    from markerplace.runtime.executor import RuntimeConfig, make_executor
    from markerplace.scene.spec import SceneSpec

    disc = data.disc
    T = disc.candidate_world_from_marker
    sizes = np.full(len(T), config.placement.tag_size)
    N = len(disc.world_from_cam)
    spec = SceneSpec(args.scene)
    me = psutil.Process()

    def run(executor, idx: np.ndarray, name: str, workers=()) -> tuple[float, float, float]:
        """(wall s, main CPU s, workers' CPU s) of the observe function on poses ``idx``."""
        poses = disc.world_from_cam[idx]
        in_view = geometric_visibility(poses, T, config.imaging.camera, config.noise.max_range)
        c0, w0, t = _cpu_seconds([me]), _cpu_seconds(workers), time.perf_counter()
        observe(spec, poses, in_view, T, sizes, config.imaging, executor, scratch / name, key=name, progress=False)
        return time.perf_counter() - t, _cpu_seconds([me]) - c0, _cpu_seconds(workers) - w0

    m = min(args.calibration_poses, N)
    idx = np.unique(np.linspace(0, N - 1, m).round().astype(np.int64))
    m = len(idx)
    warm = np.unique(np.linspace(0, N - 1, 16).round().astype(np.int64))
    out = {"poses": m}

    ex = make_executor(RuntimeConfig(workers=1))  # in this process
    try:
        run(ex, warm[:2], "inproc_warm")
        sub = idx[::2]
        wall, cpu, _ = run(ex, sub, "inproc")
        out["inprocess_wall_s_per_pose"], out["inprocess_cpu_s_per_pose"] = wall / len(sub), cpu / len(sub)
    finally:
        ex.close()

    t = time.perf_counter()
    ex = make_executor(RuntimeConfig(cluster=args.cluster))
    out["start_s"] = time.perf_counter() - t
    try:
        out["workers"] = ex.workers
        out["warmup_s"] = run(ex, warm, "dask_warm")[0]  # 16 poses in small tasks: every worker builds its state
        run(ex, idx[1::8], "dask_settle")  # 48 more poses in small tasks, so no state is built in the measured run
        out["batch"] = ex.batch_size(N)  # poses per task in the full run
        workers = [p for p in me.children(recursive=True)]
        wall, main_cpu, worker_cpu = run(ex, idx, "dask", workers)
    finally:
        ex.close()
    out["wall_s_per_pose"] = wall / m
    out["worker_s_per_pose"] = wall * out["workers"] / m
    out["worker_cpu_s_per_pose"] = worker_cpu / m
    out["main_cpu_s_per_pose"] = main_cpu / m
    return out


def project_spacing(args) -> dict:
    """Discretize ``args.scene`` at ``args.project_spacing`` (timed): how many poses a finer
    lattice has, to project its observe stage from the measured per-pose cost."""
    from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
    from markerplace.scene import load_scene

    t = time.perf_counter()
    d = discretize(load_scene(args.scene), DiscretizeConfig(grid_spacing=args.project_spacing))
    return {"s": time.perf_counter() - t, "poses": len(d.world_from_cam), "candidates": len(d.candidate_world_from_marker)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="campus", help="built-in scene (default campus)")
    ap.add_argument("--grid-spacing", type=float, default=0.5, help="camera lattice spacing, metres (paper: 0.5)")
    ap.add_argument("--cluster", default="local:2", help="Dask cluster: local:N or a scheduler address")
    ap.add_argument("--k", type=int, default=20, help="markers to place")
    ap.add_argument("--calibration-poses", type=int, default=384, help="poses of the calibration runs")
    ap.add_argument("--project", default="16,64", help="worker counts to project the observe stage onto")
    ap.add_argument("--project-spacing", type=float, default=None,
                    help="also discretize at this spacing and project its observe stage (e.g. 0.5 after a 1.0 run)")
    ap.add_argument("--run-dir", default=None, help="keep the run folder here (must not exist); default: a temporary one")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    import distributed  # noqa: F401  (configures its loggers on import; quiet them afterwards)

    for name in ("distributed", "bokeh", "tornado"):
        logging.getLogger(name).setLevel(logging.WARNING)

    from markerplace.scene import load_scene
    from markerplace.scene.builtin.catalogue import get_layout

    scene = load_scene(args.scene)
    emit("scene", args.scene)
    emit("floor_area_m2", round(get_layout(args.scene).floor_area, 1))
    emit("faces", scene.num_faces)
    emit("grid_spacing_m", args.grid_spacing)
    emit("cluster", args.cluster)
    emit("cpu_count", os.cpu_count())
    emit("load_average_1min_before", round(os.getloadavg()[0], 2))

    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(args.run_dir) if args.run_dir else Path(tmp) / "run"
        if run_dir.exists():
            raise SystemExit(f"--run-dir {run_dir} exists: cached stages would be reused; give a new folder")
        data, placement, mem, win, config = plan_end_to_end(args, run_dir)
        disc = data.disc
        N = len(disc.world_from_cam)
        from markerplace.imaging.features import FeatureSet

        features = int(FeatureSet.load(run_dir / "observations", mmap=True).offsets[-1])
        emit("storeys", " ".join(f"{z:.2f}" for z in disc.storeys))
        emit("locations", len(disc.locations))
        emit("poses", N)
        emit("candidates", data.num_candidates + disc.summary["candidates_removed"].get("not seen", 0))
        emit("candidates_offered", data.num_candidates)
        emit("features", features)
        emit("features_per_pose", round(features / max(N, 1), 1))
        for stage in (*STAGES, "other", "place", "total"):
            t0, t1 = win[stage]
            main_mb, workers_mb = mem.peak(t0, t1)
            emit(f"stage_{stage}_s", round(t1 - t0, 2))
            emit(f"stage_{stage}_peak_main_mb", round(main_mb, 1))
            emit(f"stage_{stage}_peak_workers_mb", round(workers_mb, 1))
            emit(f"stage_{stage}_peak_largest_worker_mb", round(mem.largest_child(t0, t1), 1))
        emit("markers", len(placement.markers))
        t_obs = win["observe"][1] - win["observe"][0]
        main_cpu = mem.cpu_seconds(*win["observe"])
        emit("observe_wall_s_per_pose", round(t_obs / N, 5))
        emit("observe_main_cpu_s_per_pose", round(main_cpu / N, 5))

        cal = calibrate(args, data, config, Path(tmp) / "calibration")
        W = cal["workers"]
        emit("observe_worker_s_per_pose", round(t_obs * W / N, 5))
        emit("calib_poses", cal["poses"])
        emit("calib_inprocess_wall_s_per_pose", round(cal["inprocess_wall_s_per_pose"], 5))
        emit("calib_inprocess_cpu_s_per_pose", round(cal["inprocess_cpu_s_per_pose"], 5))
        emit("calib_cluster_start_s", round(cal["start_s"], 2))
        emit("calib_warmup_s", round(cal["warmup_s"], 2))
        emit("calib_workers", W)
        emit("calib_wall_s_per_pose", round(cal["wall_s_per_pose"], 5))
        emit("calib_worker_s_per_pose", round(cal["worker_s_per_pose"], 5))
        emit("calib_worker_cpu_s_per_pose", round(cal["worker_cpu_s_per_pose"], 5))
        emit("calib_main_cpu_s_per_pose", round(cal["main_cpu_s_per_pose"], 5))
        emit("calib_wait_factor", round(cal["worker_s_per_pose"] / cal["worker_cpu_s_per_pose"], 2))
        overhead = cal["worker_cpu_s_per_pose"] - cal["inprocess_cpu_s_per_pose"]
        emit("calib_worker_overhead_cpu_s_per_pose", round(overhead, 5))
        emit("calib_worker_overhead_pct", round(100 * overhead / cal["inprocess_cpu_s_per_pose"], 1))
        emit("calib_batch_poses_per_task", cal["batch"])
        emit("calib_per_task_overhead_cpu_s", round((overhead + cal["main_cpu_s_per_pose"]) * cal["batch"], 4))

        c = cal["worker_cpu_s_per_pose"]
        m = max(cal["main_cpu_s_per_pose"], main_cpu / N)
        setup = cal["start_s"] + cal["warmup_s"]
        serial = sum(win[s][1] - win[s][0] for s in ("load", "discretize", "other", "similarity", "score", "place"))

        def projected(n: int, workers: int, cost: float) -> float:
            return setup + n * max(cost / workers, m)

        emit(f"projection_observe_s_w{W}_measured_wall_cost", round(projected(N, W, cal["worker_s_per_pose"]), 1))
        emit(f"projection_observe_s_w{W}", round(projected(N, W, c), 1))
        for w in (int(v) for v in args.project.split(",")):
            emit(f"projection_observe_s_w{w}", round(projected(N, w, c), 1))
            emit(f"projection_total_s_w{w}", round(projected(N, w, c) + serial, 1))
        emit("projection_main_limited_above_workers", math.floor(c / m) if m > 0 else "inf")
        emit("projection_assumption", "linear scaling: T(W) = cluster start + warm-up + N * c / W, c = measured worker "
             "CPU s per pose on the cluster (compute + per-task overhead), one free core per worker, never below "
             "N * main-process CPU s per pose (results and scheduler); other stages serial as measured")
        if args.project_spacing:
            ps = project_spacing(args)
            tag = f"{args.project_spacing:g}".replace(".", "p")
            emit(f"spacing_{tag}_discretize_s", round(ps["s"], 2))
            emit(f"spacing_{tag}_poses", ps["poses"])
            emit(f"spacing_{tag}_candidates", ps["candidates"])
            for w in (W, *(int(v) for v in args.project.split(","))):
                emit(f"spacing_{tag}_projection_observe_s_w{w}", round(projected(ps["poses"], w, c), 1))
    emit("load_average_1min_after", round(os.getloadavg()[0], 2))


if __name__ == "__main__":
    main()
