"""Real-scan readiness: plan on fused, scan-like versions of built-in scenes.

Prints ``name: value`` lines.

* part a, discretization on scans: for each of ``--scenes`` (default office, house) the scene
  is scanned (``scene export NAME --as-scan``: a walk of RGB-D frames with depth noise and
  dropouts, fused with a TSDF) and both the procedural original and the fused scan are
  discretized with the same settings. Reported: faces, storeys found, camera locations of
  each and the share of the original's locations the scan finds (goal >= 90 %), candidates,
  and the discretization time of the scan.
* part b, end to end: ``plan SCAN -k 20`` on a fused scan of about ``--faces`` faces (the
  office at a finer voxel): seconds and peak resident memory (main process and all workers
  together) per stage, and the candidates no camera pose sees (goal: none in the plan).
  Goal: discretization of the ~1M-face mesh well under a minute.

    .venv/bin/python benchmarks/scan_plan.py [--part a|b|all] [--cache out/bench_scans]

Scans are cached in ``--cache`` (reused when present; delete to rebuild).
"""

from __future__ import annotations

import argparse
import logging
import threading
import time
from pathlib import Path
from typing import Callable

import numpy as np

GOAL_SHARE = 0.90
GOAL_DISCRETIZE_S = 60.0


def emit(name: str, value) -> None:
    """One ``name: value`` benchmark line."""
    if isinstance(value, float):
        value = f"{value:.6g}"
    print(f"{name}: {value}", flush=True)


def scan_of(name: str, voxel: float, cache: Path) -> tuple[Path, float]:
    """Path of the fused scan of built-in ``name`` at ``voxel`` (built when missing) and the seconds it took."""
    from markerplace.cli.main import main

    path = cache / f"{name}_scan_{voxel:g}.ply"
    if path.exists():
        return path, float("nan")
    cache.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    code = main(["--quiet", "scene", "export", name, str(path), "--as-scan", "--voxel", str(voxel)])
    if code != 0:
        raise SystemExit(f"scene export {name} --as-scan failed ({code})")
    return path, time.perf_counter() - t0


class MemorySampler:
    """Samples resident memory of this process and of all its children every ``period`` s."""

    def __init__(self, period: float = 0.2):
        import psutil

        self.proc = psutil.Process()
        self.period = period
        self.samples: list[tuple[float, float, float]] = []  # (t, main MB, children MB)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        import psutil

        while not self._stop.is_set():
            main = self.proc.memory_info().rss
            kids = 0
            for c in self.proc.children(recursive=True):
                try:
                    kids += c.memory_info().rss
                except psutil.Error:
                    pass
            self.samples.append((time.perf_counter(), main / 2**20, kids / 2**20))
            self._stop.wait(self.period)

    def __enter__(self) -> "MemorySampler":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def peak(self, t0: float, t1: float) -> tuple[float, float]:
        """Peak (main MB, children MB) between two perf_counter times (the nearest sample for
        a stage shorter than the sampling period)."""
        s = [(m, k) for t, m, k in self.samples if t0 <= t <= t1]
        if not s and self.samples:
            t, m, k = min(self.samples, key=lambda x: abs(x[0] - 0.5 * (t0 + t1)))
            s = [(m, k)]
        if not s:
            return float("nan"), float("nan")
        return max(m for m, _ in s), max(k for _, k in s)


def part_a(args) -> None:
    from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
    from markerplace.scene import load_scene

    for name in args.scenes.split(","):
        path, t_scan = scan_of(name, args.voxel, Path(args.cache))
        scan = load_scene(str(path), up="z")
        original = discretize(load_scene(name), DiscretizeConfig())
        t0 = time.perf_counter()
        d = discretize(scan, DiscretizeConfig())
        t_disc = time.perf_counter() - t0
        ours = {(s, *np.round(p, 3)) for s, p in zip(d.location_storey, d.locations)}
        theirs = [(s, *np.round(p, 3)) for s, p in zip(original.location_storey, original.locations)]
        share = sum(t in ours for t in theirs) / max(len(theirs), 1)
        emit(f"{name}_scan_faces", scan.num_faces)
        emit(f"{name}_scan_export_s", round(t_scan, 1))
        emit(f"{name}_storeys_original", " ".join(f"{z:.2f}" for z in original.storeys))
        emit(f"{name}_storeys_scan", " ".join(f"{z:.2f}" for z in d.storeys))
        emit(f"{name}_locations_original", len(original.locations))
        emit(f"{name}_locations_scan", len(d.locations))
        emit(f"{name}_locations_found_share", round(share, 4))
        emit(f"{name}_goal_share", GOAL_SHARE)
        emit(f"{name}_candidates_original", len(original.candidate_position))
        emit(f"{name}_candidates_scan", len(d.candidate_position))
        emit(f"{name}_scan_discretize_s", round(t_disc, 2))


def part_b(args) -> None:
    import tempfile

    from markerplace.pipelines.plan import prepare
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.place.config import PlacementConfig
    from markerplace.plan.place.stage import place
    from markerplace.scene import load_scene
    from markerplace.scene.spec import SceneSpec

    path, t_scan = scan_of(args.big_scene, args.big_voxel, Path(args.cache))
    faces = load_scene(str(path), up="z").num_faces
    config = PlanConfig(placement=PlacementConfig(k=args.k))
    with tempfile.TemporaryDirectory() as run_dir, MemorySampler() as mem:
        t0 = time.perf_counter()
        data = prepare(SceneSpec(str(path), up="z"), config, run_dir, progress=False)
        t1 = time.perf_counter()
        result = place(data, config.placement, progress=False)
        t2 = time.perf_counter()
    emit("e2e_mesh", path.name)
    emit("e2e_faces", faces)
    emit("e2e_scan_export_s", round(t_scan, 1))
    emit("e2e_poses", len(data.disc.world_from_cam))
    emit("e2e_candidates", data.num_candidates)
    emit("e2e_candidates_not_seen_removed", data.disc.summary["candidates_removed"].get("not seen", 0))
    start = t0
    for stage, seconds in list(data.timings.items()) + [("place", t2 - t1)]:
        end = start + seconds if stage != "place" else t2
        if stage == "place":
            start = t1
        main_mb, kids_mb = mem.peak(start, end)
        emit(f"e2e_{stage}_s", round(seconds, 2))
        emit(f"e2e_{stage}_peak_main_mb", round(main_mb, 1))
        emit(f"e2e_{stage}_peak_workers_mb", round(kids_mb, 1))
        start = end
    emit("e2e_total_s", round(t2 - t0, 2))
    emit("e2e_markers", len(result.markers))
    emit("e2e_goal_discretize_s", GOAL_DISCRETIZE_S)


PARTS: dict[str, Callable] = {"a": part_a, "b": part_b}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=[*PARTS, "all"], default="all")
    ap.add_argument("--scenes", default="office,house", help="part a: built-in scenes to scan")
    ap.add_argument("--voxel", type=float, default=0.04, help="part a: TSDF voxel of the scans, metres")
    ap.add_argument("--big-scene", default="office", help="part b: scene of the ~1M-face scan")
    ap.add_argument("--big-voxel", type=float, default=0.035, help="part b: TSDF voxel, metres (0.035: ~1.2M faces)")
    ap.add_argument("--k", type=int, default=20, help="part b: markers")
    ap.add_argument("--cache", default="out/bench_scans", help="folder of cached scans")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    for name, fn in PARTS.items():
        if args.part in (name, "all"):
            fn(args)


if __name__ == "__main__":
    main()
