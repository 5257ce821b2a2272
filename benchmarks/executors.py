"""Executor scaling: the observe stage (render + SIFT + 3D + occlusion) on each backend.

Prints ``name: value`` lines. For ``--poses`` feasible poses of ``--scene``, the observe stage
runs in this process (1 worker), on a local process pool of 2 workers and on a 2-worker Dask
``LocalCluster``; reported per backend: seconds, poses per second, scaling efficiency against
the in-process run (speed-up / workers) and the start-up cost (pool spawn or cluster start,
first GL context). The per-task overhead is measured apart with a task that does nothing
(same batches): seconds per task and its share of the observe run (goal: under 5 %).

    .venv/bin/python benchmarks/executors.py [--scene office] [--poses 400]
"""

from __future__ import annotations

import argparse
import logging
import tempfile
import time

GOAL_OVERHEAD = 0.05


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = f"{value:.6g}"
    print(f"{name}: {value}", flush=True)


def _noop(state, item):
    return item


def _build(spec):
    return None


def main(argv=None) -> None:
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
    from markerplace.plan.observe import observe
    from markerplace.plan.score.stage import geometric_visibility
    from markerplace.runtime.executor import RuntimeConfig, WorkerJob, make_executor
    from markerplace.scene.spec import SceneSpec

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="office")
    ap.add_argument("--poses", type=int, default=400, help="poses observed per backend (the first N)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)

    spec = SceneSpec(args.scene)
    disc = discretize(spec.load(), DiscretizeConfig())
    poses = disc.world_from_cam[: args.poses]
    T = disc.candidate_world_from_marker
    config = PlanConfig()
    in_view = geometric_visibility(poses, T, config.imaging.camera, config.noise.max_range)
    emit("scene", args.scene)
    emit("poses", len(poses))
    backends = {"inprocess": RuntimeConfig(workers=1), "pool2": RuntimeConfig(workers=2),
                "dask2": RuntimeConfig(cluster="local:2")}
    seconds = {}
    for name, rc in backends.items():
        t0 = time.perf_counter()
        with make_executor(rc) as ex, tempfile.TemporaryDirectory() as tmp:
            t_start = time.perf_counter() - t0
            t1 = time.perf_counter()
            fs = observe(spec, poses, in_view, T, 0.4, config.imaging, ex, tmp + "/obs", key=name, progress=False)
            seconds[name] = time.perf_counter() - t1
            workers = ex.workers
            tasks = len(range(0, len(poses), ex.batch_size(len(poses))))
            # per-task overhead: the same batches with a task that does nothing
            job = WorkerJob(_build, None, "noop")
            list(ex.map(_noop, list(range(len(poses))), job))  # warm the workers' state
            t2 = time.perf_counter()
            list(ex.map(_noop, list(range(len(poses))), job))
            per_task = (time.perf_counter() - t2) / tasks
        emit(f"{name}_workers", workers)
        emit(f"{name}_startup_s", round(t_start, 2))
        emit(f"{name}_observe_s", round(seconds[name], 2))
        emit(f"{name}_poses_per_s", round(len(poses) / seconds[name], 2))
        emit(f"{name}_features", int(fs.offsets[-1]))
        emit(f"{name}_tasks", tasks)
        emit(f"{name}_overhead_per_task_ms", round(1000 * per_task, 2))
        emit(f"{name}_overhead_share", round(per_task * tasks / seconds[name], 4))
        if name != "inprocess":
            speedup = seconds["inprocess"] / seconds[name]
            emit(f"{name}_speedup", round(speedup, 3))
            emit(f"{name}_efficiency", round(speedup / workers, 3))
    emit("goal_overhead_share", GOAL_OVERHEAD)


if __name__ == "__main__":
    main()
