"""Where ``plan``'s time goes: plan a scan-like model as a user runs it and time every stage,
then time the observe stage's steps per pose.

Prints ``name: value`` lines.

* the model: ``--frames DIR`` profiles ``plan --frames DIR`` instead (a real RGB-D sequence: the
  surface fused from the frames, the frames' own images looked at, no rendering; e.g. the
  7-Scenes kitchen of ``scripts/prepare_kitchen.sh``, ``--plan-args`` for its tag size); its
  stage windows are ``setup``, ``fuse``, ``discretize``, ``observe``, ``similarity``,
  ``score_place`` and ``deliverables``, and per frame: reading the images, SIFT, lifting, the
  candidate occlusion test, transfer and bookkeeping.
* else the model: ``--scene house-scan`` (default) is ``scene export house --as-scan`` (a fused
  simulated scan of the built-in two-storey house, cached in ``--work`` as
  benchmarks/run_estimate.py does), planned with ``--up z``; ``--scene campus`` is the built-in
  2,064 m^2 campus, planned with ``--level 0`` (extra ``plan`` arguments: ``--plan-args``, e.g.
  ``--plan-args="--start 10,5"``) to keep the run short. The floor area comes from the
  discretize log lines (``open floor`` and ``free region`` summed over storeys) and
  ``area_reaches_200m2`` says whether it reaches 200 m^2.
* per stage: ``markerplace plan SCENE -k K --out DIR --workers W`` runs in a subprocess into a
  fresh ``DIR``; its process tree (plan process, pool workers and their children) is sampled
  every ``--period`` s with psutil (resident memory summed over the tree; CPU seconds of the
  tree, reaped children included) while its log lines are time-stamped as they arrive. Stage
  windows: ``setup`` (start-up, scene load, the first-guess size check) up to the discretize
  stage, ``discretize`` (its logged seconds, ending at its ``... yaws = N poses`` line),
  ``size_check`` (the run-size sample renders), ``observe`` (from ``observe: rendering`` to
  ``observe: N features``), ``similarity`` (to its summary line), ``score`` (its logged seconds,
  then the placement calibration), ``place`` (to ``...: placed N markers``) and
  ``deliverables`` (files, report.html, process exit). Per window: wall s, CPU s (and its system,
  i.e. kernel, part) and peak RSS MiB of the tree.
* per pose of the observe stage, on ``--sample`` of the run's own poses (spread evenly; the
  discretization is read from ``DIR``), in this process: render (RGB and depth), SIFT (the
  scoring preset), lifting keypoints to 3D (and dropping those without), the candidate
  occlusion test, the transfer of a result from a worker (pickled through a pipe, as the
  process pool returns it; plus its size) and bookkeeping (the ImageFeatures and the
  FeatureWriter that streams parts to disk). Median and mean ms each, and their share of the
  per-pose total; also a depth-only render of the same pose (not part of observe: what the RGB
  pass costs) and the scene's triangle count. ``DIR.log`` keeps the plan log (seconds since
  start per line).

    .venv/bin/python benchmarks/plan_profile.py [--scene house-scan|campus] [--work out/bench_plan_profile]
        [--sample 60] [--workers 2] [-k 10]
    .venv/bin/python benchmarks/plan_profile.py --frames runs/kitchen/frames -k 4 \
        --plan-args="--tag-size 0.16 --marker-spacing 0.5"
"""

from __future__ import annotations

import argparse
import os
import pickle
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from multiprocessing import Pipe
from pathlib import Path

import numpy as np
import psutil
from run_estimate import house_scan, markerplace_exe  # benchmarks/ is on sys.path when run as a script
from scan_plan import emit

AREA_GOAL = 200.0
STAGES = ("setup", "discretize", "size_check", "observe", "similarity", "score", "place", "deliverables")
FRAMES_WINDOWS = (("setup", r"plan --frames: \d+ of \d+ frames"), ("fuse", r"fused \d+ frames|fuse: reusing"),
                  ("discretize", r"frames: \d+ of \d+ frames .* candidate tag spots"),
                  ("observe", r"observe: \d+ features with 3D points"), ("similarity", r"similarity \(\w+\): \d+ points"),
                  ("score_place", r": placed \d+ markers \("), ("deliverables", None))
"""Stage windows of a frames plan: (name, the log line that ends it; None: the process exit)."""


def scene_args(args, work: Path) -> tuple[list[str], str, str | None]:
    """(``plan`` scene arguments, the scene spec, its up axis); exports the scan when missing."""
    if args.scene == "house-scan":
        scan = house_scan(work)
        return [str(scan), "--up", "z"], str(scan), "z"
    if args.scene == "campus":
        return ["campus", "--level", "0"], "campus", None
    return [args.scene], args.scene, None


class TreeSampler:
    """Samples the process tree of ``pid`` every ``period`` s: (t, RSS MiB summed, CPU s summed,
    reaped children included)."""

    def __init__(self, pid: int, period: float):
        self.proc = psutil.Process(pid)
        self.period = period
        self.samples: list[tuple[float, float, float]] = []
        self.system: list[float] = []  # system CPU s of the tree at each sample
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            rss = cpu = sys_s = 0.0
            try:
                procs = [self.proc, *self.proc.children(recursive=True)]
            except psutil.Error:
                break
            for p in procs:
                try:
                    rss += p.memory_info().rss
                    c = p.cpu_times()
                    cpu += c.user + c.system + c.children_user + c.children_system
                    sys_s += c.system + c.children_system
                except psutil.Error:
                    pass
            self.samples.append((time.perf_counter(), rss / 2**20, cpu))
            self.system.append(sys_s)
            self._stop.wait(self.period)

    def start(self) -> "TreeSampler":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join()

    def system_window(self, t0: float, t1: float) -> float:
        """System (kernel) CPU s of the tree between two perf_counter times (nearest samples)."""
        if not self.samples:
            return float("nan")
        times = np.array([s[0] for s in self.samples])
        return self.system[int(np.argmin(np.abs(times - t1)))] - self.system[int(np.argmin(np.abs(times - t0)))]

    def window(self, t0: float, t1: float, end_cpu: float | None = None) -> tuple[float, float]:
        """(CPU s, peak RSS MiB) between two perf_counter times (nearest samples); ``end_cpu``:
        the tree's CPU total at t1 when the process has exited by then."""
        if not self.samples:
            return float("nan"), float("nan")
        a = min(self.samples, key=lambda s: abs(s[0] - t0))
        b = min(self.samples, key=lambda s: abs(s[0] - t1))
        inside = [m for t, m, _ in self.samples if t0 <= t <= t1] or [b[1]]
        return (b[2] if end_cpu is None else end_cpu) - a[2], max(inside)


def children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def first(lines: list[tuple[float, str]], pattern: str, after: float = 0.0) -> tuple[float, re.Match] | None:
    rx = re.compile(pattern)
    for t, line in lines:
        if t >= after:
            m = rx.search(line)
            if m:
                return t, m
    return None


def run_plan(args, plan_scene: list[str], out: Path):
    """Run ``plan`` into ``out`` with its process tree sampled: (log lines, sampler, t0, t_end, CPU s)."""
    exe = markerplace_exe()
    shutil.rmtree(out, ignore_errors=True)
    cmd = [exe, "plan", *plan_scene, *args.plan_args.split(), "-k", str(args.k), "--out", str(out),
           "--workers", str(args.workers)]
    emit("plan_command", " ".join(cmd))
    cpu0 = children_cpu()
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, bufsize=1)
    sampler = TreeSampler(proc.pid, args.period).start()
    lines: list[tuple[float, str]] = []
    with open(out.with_suffix(".log"), "w") as log:
        for line in proc.stderr:
            lines.append((time.perf_counter(), line.rstrip("\n")))
            log.write(f"{lines[-1][0] - t0:9.2f} {line}")
    emit("plan_log", out.with_suffix(".log"))
    proc.wait()
    t_end = time.perf_counter()
    sampler.stop()
    cpu_total = children_cpu() - cpu0
    if proc.returncode != 0:
        print("\n".join(s for _, s in lines[-30:]), file=sys.stderr)
        raise SystemExit(f"plan failed ({proc.returncode})")
    return lines, sampler, t0, t_end, cpu_total


def emit_windows(win: dict, sampler: TreeSampler, cpu_total: float, lines, t0: float, t_end: float) -> None:
    """Per stage window (name -> (t0, t1)): wall, CPU, system and peak RSS; then the totals."""
    cpu_before_end = sampler.samples[-1][2] if sampler.samples else 0.0
    for name, (a, b) in win.items():
        cpu, rss = sampler.window(a, b, end_cpu=cpu_total if name == "deliverables" else None)
        emit(f"stage.{name}.wall_s", b - a)
        emit(f"stage.{name}.cpu_s", cpu)
        emit(f"stage.{name}.system_s", sampler.system_window(a, b))
        emit(f"stage.{name}.peak_rss_mib", rss)
    emit("stage.logged_seconds", first(lines, r"stage seconds:")[1].string.split("stage seconds: ")[-1])
    emit("plan.wall_s", t_end - t0)
    emit("plan.cpu_s", cpu_total)
    emit("plan.system_s", sampler.system[-1] if sampler.system else float("nan"))
    emit("plan.cpu_s_sampled_before_exit", cpu_before_end)
    emit("plan.peak_rss_mib", max((m for _, m, _ in sampler.samples), default=float("nan")))


def plan_stages(args, plan_scene: list[str], out: Path) -> list[tuple[float, str]]:
    """Run ``plan`` into ``out`` and print per stage wall s, CPU s and peak RSS; returns the log lines."""
    lines, sampler, t0, t_end, cpu_total = run_plan(args, plan_scene, out)
    stage_s = dict((k, float(v)) for k, v in re.findall(r"(\w+) (\d+\.\d+)", first(lines, r"stage seconds:")[1].string))
    t_disc_end = first(lines, r"discretize: .* yaws = \d+ poses")[0]
    t_obs0 = first(lines, r"observe: rendering")[0]
    t_obs1 = first(lines, r"observe: \d+ features", t_obs0)[0]
    t_sim1 = first(lines, r"similarity \(\w+\): \d+ points", t_obs1)[0]
    t_score1 = t_sim1 + stage_s.get("score", 0.0)
    t_place1 = first(lines, r": placed \d+ markers \(", t_sim1)[0]
    t_disc0 = t_disc_end - stage_s.get("discretize", 0.0)
    win = {"setup": (t0, t_disc0), "discretize": (t_disc0, t_disc_end), "size_check": (t_disc_end, t_obs0),
           "observe": (t_obs0, t_obs1), "similarity": (t_obs1, t_sim1), "score": (t_sim1, t_score1),
           "place": (t_score1, t_place1), "deliverables": (t_place1, t_end)}
    emit_windows(win, sampler, cpu_total, lines, t0, t_end)
    return lines


def frames_stages(args, out: Path) -> list[tuple[float, str]]:
    """``plan --frames`` into ``out``: the :data:`FRAMES_WINDOWS` per stage; returns the log lines."""
    lines, sampler, t0, t_end, cpu_total = run_plan(args, ["--frames", args.frames], out)
    win, start = {}, t0
    for name, pattern in FRAMES_WINDOWS:
        hit = first(lines, pattern, start) if pattern else None
        if pattern and hit is None:
            raise SystemExit(f"no log line matches {pattern!r} (stage {name}); see {out.with_suffix('.log')}")
        end = hit[0] if hit else t_end
        win[name] = (start, end)
        start = end
    emit_windows(win, sampler, cpu_total, lines, t0, t_end)
    poses = first(lines, r"frames: (\d+) of \d+ frames .* (\d+) candidate tag spots")
    emit("poses", int(poses[1].group(1)))
    emit("candidates", int(poses[1].group(2)))
    return lines


def area(lines: list[tuple[float, str]], out: Path) -> None:
    """Floor area of the planned storeys (the discretization's summary), poses and candidates."""
    from markerplace.plan.discretize.artifact import load as load_discretization

    summary = load_discretization(out / "discretization.npz").summary
    storeys = summary.get("per_storey", [])
    open_floor = sum(s["open_floor_m2"] for s in storeys)
    emit("storeys_planned", len(storeys))
    emit("area.open_floor_m2", float(open_floor))
    emit("area.free_region_m2", float(sum(s["free_m2"] for s in storeys)))
    emit("area.covered_m2", float(sum(s["covered_m2"] for s in storeys)))
    emit("area_reaches_200m2", bool(open_floor >= AREA_GOAL))
    poses = first(lines, r"= (\d+) poses, (\d+) candidate")
    if poses:
        emit("poses", int(poses[1].group(1)))
        emit("candidates", int(poses[1].group(2)))


def emit_steps(prefix: str, t: dict, steps: tuple) -> float:
    """Median and mean ms of each step's timings ``t[step]`` (ms per item), their total, and each
    step's share of the mean total; returns the mean total ms."""
    total = np.sum([t[s] for s in steps], axis=0)
    for s in steps + ("total",):
        v = np.asarray(total if s == "total" else t[s])
        emit(f"{prefix}.{s}.median_ms", float(np.median(v)))
        emit(f"{prefix}.{s}.mean_ms", float(np.mean(v)))
        if s != "total":
            emit(f"{prefix}.{s}.share_of_mean", float(np.mean(v) / np.mean(total)))
    return float(np.mean(total))


def _send(conn, obj) -> None:
    conn.send(obj)


def per_pose(args, spec, up, out: Path) -> None:
    """Time the observe stage's steps per pose on ``args.sample`` of the run's poses."""
    from markerplace.imaging.engine import EngineSpec, ImagingEngine
    from markerplace.imaging.features import FeatureWriter, ImageFeatures
    from markerplace.imaging.visibility import marker_points
    from markerplace.localization.sift import extract_sift, lift_to_3d
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.artifact import load as load_discretization
    from markerplace.plan.score.stage import geometric_visibility
    from markerplace.scene.spec import SceneSpec

    config = PlanConfig()
    scene_spec = SceneSpec(spec, up=up)
    disc = load_discretization(out / "discretization.npz")  # the plan run's own poses and candidates
    poses = np.asarray(disc.world_from_cam, float)
    cands = np.asarray(disc.candidate_world_from_marker, float)
    pick = np.unique(np.linspace(0, len(poses) - 1, min(args.sample, len(poses))).astype(int))
    in_view = geometric_visibility(poses[pick], cands, config.imaging.camera, config.noise.max_range)
    samples = marker_points(cands, config.placement.tag_size)
    engine = ImagingEngine(EngineSpec(scene_spec, config.imaging, {"candidates": samples}))
    emit("per_pose.scene_triangles", int(engine.renderer.scene.num_faces))
    K, cfg = engine.K, config.imaging
    engine.render(poses[pick[0]])  # warm-up: GL context, scene upload
    steps = ("render", "sift", "lift", "occlusion", "transfer", "bookkeeping")
    t = {s: [] for s in steps}
    nbytes, nfeat, depth_only = [], [], []
    recv, send = Pipe(duplex=False)
    with tempfile.TemporaryDirectory() as tmp:
        writer = FeatureWriter(Path(tmp) / "obs", len(pick), "bench")
        for j, i in enumerate(pick):
            c0 = time.perf_counter()
            res = engine.render(poses[i])
            c1 = time.perf_counter()
            kp, desc = extract_sift(res.rgb, cfg.sift)
            c2 = time.perf_counter()
            pts, valid = lift_to_3d(kp, res.depth, K, res.world_from_cam, max_depth=cfg.max_depth)
            pts = np.where(valid[:, None], pts, np.nan)
            feats = ImageFeatures(kp.astype(np.float32), np.clip(np.rint(desc), 0, 255).astype(np.uint8),
                                  pts.astype(np.float32)).with_3d_only()
            c3 = time.perf_counter()
            unocc = engine.unoccluded(res, "candidates", in_view[j])
            c4 = time.perf_counter()
            result = [(j, ImageFeatures(feats.keypoints, feats.descriptors, feats.points_world,
                                        extras={"candidate_unoccluded": unocc}))]
            c5 = time.perf_counter()
            nbytes.append(len(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)))
            c6 = time.perf_counter()
            th = threading.Thread(target=_send, args=(send, result))
            th.start()
            got = recv.recv()
            th.join()
            c7 = time.perf_counter()
            writer.add(got[0][0], got[0][1])
            c8 = time.perf_counter()
            engine.render(poses[i], rgb=False)  # not part of observe: how much of the render is the RGB pass
            depth_only.append(1000 * (time.perf_counter() - c8))
            nfeat.append(len(feats.keypoints))
            for s, dt in zip(steps, (c1 - c0, c2 - c1, c3 - c2, c4 - c3, c7 - c6, (c5 - c4) + (c8 - c7))):
                t[s].append(1000 * dt)
        c0 = time.perf_counter()
        writer.finish()
        finish_ms = 1000 * (time.perf_counter() - c0) / len(pick)
    engine.close()
    t["bookkeeping"] = [x + finish_ms for x in t["bookkeeping"]]
    emit("per_pose.poses_timed", len(pick))
    emit("per_pose.features_with_3d_mean", float(np.mean(nfeat)))
    emit("per_pose.result_bytes_mean", float(np.mean(nbytes)))
    mean_ms = emit_steps("per_pose", t, steps)
    emit("per_pose.render_depth_only.median_ms", float(np.median(depth_only)))
    emit("per_pose.render_depth_only.mean_ms", float(np.mean(depth_only)))
    emit("per_pose.observe_one_core_s_all_poses", mean_ms / 1000 * len(poses))


def per_frame(args, out: Path) -> None:
    """Time a frames plan's observe steps per frame on ``args.sample`` of the run's frames."""
    import json

    from markerplace.imaging.features import FeatureWriter, ImageFeatures
    from markerplace.imaging.visibility import marker_points, markers_unoccluded
    from markerplace.localization.sift import extract_sift, lift_to_3d
    from markerplace.pipelines.plan_frames import frames_config
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.artifact import load as load_discretization
    from markerplace.scan.frame_images import load_frame
    from markerplace.scan.frames import open_frameset

    written = json.loads((out / "config.json").read_text())
    options = written["scene_options"]
    fs = open_frameset(options["frames"], options["format"])
    indices = np.asarray(options["frame_indices"], int)
    disc = load_discretization(out / "discretization.npz")
    pick = np.unique(np.linspace(0, len(indices) - 1, min(args.sample, len(indices))).astype(int))
    cfg = frames_config(PlanConfig(), fs, indices).imaging
    samples = marker_points(disc.candidate_world_from_marker, written["placement"]["tag_size"])
    steps = ("read", "sift", "lift", "occlusion", "transfer", "bookkeeping")
    t = {s: [] for s in steps}
    recv, send = Pipe(duplex=False)
    with tempfile.TemporaryDirectory() as tmp:
        writer = FeatureWriter(Path(tmp) / "obs", len(pick), "bench")
        for j, i in enumerate(pick):
            c0 = time.perf_counter()
            rgb, depth = load_frame(fs, fs.frames[int(indices[i])])
            depth_m = depth.astype(np.float32) / float(fs.depth_scale)
            c1 = time.perf_counter()
            kp, desc = extract_sift(rgb, cfg.sift)
            c2 = time.perf_counter()
            pts, valid = lift_to_3d(kp, depth_m, cfg.camera.K, disc.world_from_cam[i], max_depth=cfg.max_depth,
                                    image_size=(rgb.shape[1], rgb.shape[0]))
            c3 = time.perf_counter()
            unocc = markers_unoccluded(depth_m, disc.world_from_cam[i], cfg.camera.K, samples, cfg.occlusion_tolerance)
            c4 = time.perf_counter()
            feats = ImageFeatures(kp[valid].astype(np.float32), np.clip(np.rint(desc[valid]), 0, 255).astype(np.uint8),
                                  pts[valid].astype(np.float32), extras={"candidate_unoccluded": unocc})
            c5 = time.perf_counter()
            th = threading.Thread(target=_send, args=(send, [(j, feats)]))
            th.start()
            got = recv.recv()
            th.join()
            c6 = time.perf_counter()
            writer.add(got[0][0], got[0][1])
            c7 = time.perf_counter()
            for s, dt in zip(steps, (c1 - c0, c2 - c1, c3 - c2, c4 - c3, c6 - c5, (c5 - c4) + (c7 - c6))):
                t[s].append(1000 * dt)
        writer.finish()
    emit("per_frame.frames_timed", len(pick))
    mean_ms = emit_steps("per_frame", t, steps)
    emit("per_frame.observe_one_core_s_all_frames", mean_ms / 1000 * len(indices))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="house-scan", help="house-scan (default), campus (--level 0) or a built-in name")
    ap.add_argument("--work", default="out/bench_plan_profile")
    ap.add_argument("--sample", type=int, default=60, help="poses timed per step (spread evenly over the run's poses)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("-k", type=int, default=10)
    ap.add_argument("--period", type=float, default=0.25, help="process-tree sampling period, s")
    ap.add_argument("--frames", default=None, help="profile plan --frames DIR (a real RGB-D sequence) instead")
    ap.add_argument("--plan-args", default="", help="extra plan arguments, e.g. --plan-args='--start 10,5'")
    args = ap.parse_args()
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    emit("cpus", os.cpu_count())
    if args.frames:
        emit("frames", args.frames)
        out = work / "plan_frames"
        frames_stages(args, out)
        per_frame(args, out)
        return 0
    plan_scene, spec, up = scene_args(args, work)
    emit("scene", args.scene)
    out = work / f"plan_{args.scene}"
    lines = plan_stages(args, plan_scene, out)
    area(lines, out)
    per_pose(args, spec, up, out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
