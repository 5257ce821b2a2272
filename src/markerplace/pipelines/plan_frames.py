"""``markerplace plan --frames DIR``: plan at a real RGB-D sequence's own 6-DoF camera poses,
from its own images (the paper: with good RGB-D data at feasible poses the textured mesh is not
needed).

:func:`prepare_frames` is :func:`markerplace.pipelines.plan.prepare` for frames:

1. poses: the chosen frames' ``world_from_cam`` (:mod:`markerplace.plan.frames.poses`);
2. surface: fused from the same frames (``fused.ply``, cached) or ``--mesh``
   (:mod:`markerplace.plan.frames.surface`);
3. candidates on that surface and the top-down grid, saved as ``discretization.npz``
   (:mod:`markerplace.plan.frames.candidates`, :mod:`markerplace.plan.frames.top_view`);
4. observations from the real images, ``observations/`` (:mod:`markerplace.plan.frames.observations`);
   then look-alikes and scores exactly as the mesh plan (with the frames' K).

:func:`run_plan_frames` adds placement and the mesh plan's deliverables; the scene of the
installer views is the loaded surface. ``expected-recall``, ``--target-recall`` and
``--recall-curve`` are refused: their success model is calibrated by rendering the scene.

Frames: everything runs in the surface's internal frame (the poses are shifted by its
:func:`~markerplace.scene.worldframe.world_offset`, zero unless the model lies far from the
origin); outputs are moved back to the frames' world frame.
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.pipelines.plan import PlanResult
from markerplace.plan.config import PlanConfig, validate
from markerplace.plan.discretize.artifact import load as load_discretization
from markerplace.plan.discretize.artifact import save as save_discretization
from markerplace.plan.discretize.exclusion import apply_exclusion, load_exclusion
from markerplace.plan.folder import FRAMES_SCENE_PREFIX
from markerplace.plan.frames.candidates import frame_candidates
from markerplace.plan.frames.observations import run_frame_observe
from markerplace.plan.frames.poses import plan_intrinsics
from markerplace.plan.frames.surface import FUSE, frames_key, surface_path
from markerplace.plan.frames.top_view import floor_height, frames_discretization
from markerplace.plan.place.greedy import check_k
from markerplace.plan.place.predicted_recall import predicted_recall, score_bound, wants_success_model
from markerplace.plan.place.stage import first_pick_gain, place
from markerplace.plan.score.stage import geometric_visibility, score_poses
from markerplace.plan.similarity.stage import run_similarity
from markerplace.plan.types import PlanData
from markerplace.report.frames_map import camera_path_map
from markerplace.report.plan_outputs import write_plan_outputs
from markerplace.report.plan_report import write_plan_report
from markerplace.runtime import cache, run_folder
from markerplace.runtime.stages import cached
from markerplace.scan.frameset import FrameSet
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster
from markerplace.scene.worldframe import world_offset

log = logging.getLogger(__name__)

__all__ = ["FramesInputs", "frames_config", "prepare_frames", "run_plan_frames", "check_frames_method"]


def frames_config(config: PlanConfig, fs: FrameSet, frame_indices: np.ndarray) -> PlanConfig:
    """``config`` with the frames' camera model as ``imaging.camera`` (scoring's K)."""
    return replace(config, imaging=replace(config.imaging, camera=plan_intrinsics(fs, frame_indices)))


def check_frames_method(config: PlanConfig) -> None:
    """:class:`UserError` for settings that need a renderer: a calibrated method
    (``expected-recall``), ``--target-recall``, ``--recall-curve``."""
    p = config.placement
    if wants_success_model(p):
        what = f"--method {p.method}" if p.method == "expected-recall" else \
            ("--target-recall" if p.target_recall is not None else
             ("--recall-curve" if p.recall_curve else f"--method {p.method}"))
        raise UserError(f"{what} cannot plan from --frames: its success model is calibrated by rendering the "
                        "scene at the camera poses; use omp, random, uniform or human")


def _indices(fs: FrameSet, frame_indices) -> np.ndarray:
    idx = np.asarray(frame_indices, dtype=np.int64).reshape(-1)
    if len(idx) == 0:
        raise UserError(f"{fs.root}: no frames chosen to plan at")
    if idx.min() < 0 or idx.max() >= len(fs.frames):
        raise UserError(f"{fs.root}: frame index out of range 0..{len(fs.frames) - 1}")
    return idx


@contextmanager
def _quiet_up_axis_check():
    """Drop the loader's "its floor seems to face another way" warning while this runs."""
    logger = logging.getLogger("markerplace.scene.loader")

    def keep(record: logging.LogRecord) -> bool:
        return "seems to face another way" not in record.getMessage()

    logger.addFilter(keep)
    try:
        yield
    finally:
        logger.removeFilter(keep)


def load_surface(fs: FrameSet, idx: np.ndarray, run_dir: Path, mesh, timings: dict, progress: bool):
    """(surface file, the loaded scene, its world offset)."""
    path = surface_path(fs, idx, run_dir, mesh, timings, progress)
    if mesh is None:  # z up by the frames' contract: a scan of walls only is no reason to suggest --up
        with _quiet_up_axis_check():
            scene = load_scene(str(path), up="z")
    else:
        scene = load_scene(str(path))
    return path, scene, world_offset(scene)


def prepare_frames(fs: FrameSet, frame_indices: np.ndarray, config: PlanConfig, run_dir: Path,
                   mesh: str | Path | None = None, progress: bool = True, k: int | None = None) -> PlanData:
    """Poses, surface, candidates, observations, look-alikes and scores of a frames plan (module
    docstring), each cached in ``run_dir``.

    Args:
        fs: the frame set (:func:`markerplace.scan.frames.open_frameset`).
        frame_indices: (N,) indices into ``fs.frames`` of the poses to serve.
        config: all settings; ``imaging.camera`` is replaced by the frames' intrinsics.
        run_dir: the run folder (created): ``fused.ply`` (without ``mesh``),
            ``discretization.npz``, ``observations/``, ``similarity.npz``.
        mesh: a mesh file in the frames' world frame (z up, metres) to put tags on instead of
            the fused surface.
        k: the most markers the caller will place: refused right after the candidates when
            they are fewer (None: not checked).
    """
    run_dir = Path(run_dir)
    run_folder.make_dirs(run_dir)
    idx = _indices(fs, frame_indices)
    config = frames_config(config, fs, idx)
    timings: dict[str, float] = {}
    path, scene, offset = load_surface(fs, idx, run_dir, mesh, timings, progress)
    world_from_cam = np.array([fs.frames[int(i)].world_from_cam for i in idx], float)
    world_from_cam[:, :3, 3] -= offset
    fkey = frames_key(fs, idx)
    tag_size = config.placement.tag_size
    info = {"count": int(len(idx)), "total": int(len(fs.frames)), "layout": fs.format, "root": str(fs.root),
            "step": int(np.median(np.diff(idx))) if len(idx) > 1 else 1,
            "surface": "fused" if mesh is None else str(mesh), "voxel_m": FUSE.voxel if mesh is None else None}
    key = cache.hash_of("frames-discretize-v1", fkey, cache.content_digest(path), offset,
                        config.discretize.cache_view(tag_size), config.imaging.camera)

    def compute():
        V, F = scene.geometry()
        rc = RayCaster(V, F)
        floor = floor_height(rc, world_from_cam[:, 2, 3], config.discretize.height)
        cand = frame_candidates(rc, world_from_cam, config.imaging.camera, config.discretize.candidates, tag_size,
                                floor[0])
        if len(cand.position) == 0:
            raise UserError(f"no candidate tag spots: no flat near-vertical surface seen by the frames holds a "
                            f"{tag_size:g} m tag with open space in front; check --tag-size or the frames")
        return frames_discretization(rc, world_from_cam, cand, floor,
                                     config.discretize.resolution, info)

    disc = cached("discretize", run_dir / "discretization.npz", key, compute, save_discretization,
                  load_discretization, timings)
    C = len(disc.candidate_world_from_marker)
    log.info("frames: %d of %d frames (%s layout) as camera poses, %d candidate tag spots on the %s surface",
             len(idx), len(fs.frames), fs.format, C, "fused" if mesh is None else "given")
    if k is not None:
        check_k(k, C)
    marker_poses = disc.candidate_world_from_marker
    sizes = [tag_size] * C
    in_view = geometric_visibility(disc.world_from_cam, marker_poses, config.imaging.camera, config.noise.max_range)
    obs, obs_key = run_frame_observe(fs, idx, disc.world_from_cam, fkey, marker_poses, sizes, config.imaging,
                                     run_dir, timings, progress, config.runtime)
    n_similar = run_similarity(obs.descriptors, obs.points_world, obs_key, run_dir, config.similarity,
                               config.placement.similarity, timings, progress)
    return score_poses(disc, obs, n_similar, marker_poses, sizes, in_view, 0, config.placement.marker_model,
                       config.noise, config.imaging.camera.K, timings)


@dataclass(frozen=True)
class FramesInputs:
    """What a frames plan reads besides its settings: the frames (``fs``, ``frame_indices``),
    ``mesh`` (``--mesh``), ``exclude`` (``--exclude`` file), ``paper``, ``adopt``, ``progress``."""

    fs: FrameSet
    frame_indices: np.ndarray
    mesh: str | None = None
    exclude: str | None = None
    paper: str = "a4"
    adopt: bool = False
    progress: bool = True


def run_plan_frames(config: PlanConfig, inputs: FramesInputs, out: str | Path) -> PlanResult:
    """Plan ``config.placement.k`` tags at the frames' poses and write every deliverable of
    :func:`markerplace.pipelines.plan.run_plan` into ``out``, plus ``camera_path.png``."""
    out, k, fs = Path(out), config.placement.k, inputs.fs
    validate(config)
    check_frames_method(config)
    idx = _indices(fs, inputs.frame_indices)
    config = frames_config(config, fs, idx)
    exclusion = load_exclusion(inputs.exclude) if inputs.exclude else None
    run_folder.open_run_folder(out, "plan", adopt=inputs.adopt)
    data = prepare_frames(fs, idx, config, out, inputs.mesh, inputs.progress, k)
    _, scene, offset = load_surface(fs, idx, out, inputs.mesh, {}, inputs.progress)
    check_k(k, data.num_candidates)
    if exclusion is not None:
        data = apply_exclusion(data, exclusion, offset, k)
    placement = place(data, config.placement, progress=inputs.progress)
    t0 = time.perf_counter()
    predicted = {"predicted_recall": predicted_recall(data, placement, config.placement),
                 "score_bound": score_bound(data, placement)}
    data.timings["predicted recall and bounds"] = time.perf_counter() - t0
    source = f"{FRAMES_SCENE_PREFIX}{fs.root}"
    summary = write_plan_outputs(out, data=data, placement=placement, first_gain=first_pick_gain(data, placement),
                                 config=config, method=config.placement.method, scene_source=source, scene=scene,
                                 world_offset=offset, paper=inputs.paper,
                                 scene_options={"frames": str(fs.root), "format": fs.format,
                                                "frame_indices": [int(i) for i in idx], "mesh": inputs.mesh},
                                 exclusion=exclusion, predicted=predicted)
    camera_path_map(out / "camera_path.png", data.disc, placement.markers, offset,
                    f"{len(idx)} of {len(fs.frames)} frames ({fs.format} layout): camera path and {len(placement.markers)} tags")
    log.info("placed %d markers with %s at %d frame poses; mean score %.2f -> %.2f; 10th percentile %.2f -> %.2f",
             len(placement.markers), config.placement.method, len(idx), summary["mean_score_before"],
             summary["mean_score_after"], summary["p10_score_before"], summary["p10_score_after"])
    log.info("stage seconds: %s", ", ".join(f"{name} {s:.1f}" for name, s in data.timings.items()))
    report = write_plan_report(out, scene, data.disc, config.discretize.height, world_offset=offset)
    return PlanResult(out, Path(report), ())
