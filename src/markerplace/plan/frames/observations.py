"""Observations of a frames plan from the real images (no rendering): per chosen frame, SIFT
with the plan's preset (``imaging.sift``), each keypoint lifted to 3D by the frame's own depth
(:func:`~markerplace.localization.sift.lift_to_3d`: keypoints without a depth reading, at a
depth edge or beyond ``imaging.max_depth`` are dropped), and ``candidate_unoccluded`` (N, C):
the candidate's centre and four corners project inside the image in front of the camera and the
frame's depth there is not nearer than the tag by more than ``imaging.occlusion_tolerance``
(:func:`~markerplace.imaging.visibility.markers_unoccluded`; a depth hole (0) counts as not
hiding it: sensors lose dark, shiny and far surfaces, and a hole is rarely something in front).

Written as a :class:`~markerplace.imaging.features.FeatureSet` folder ``observations/`` in the
run folder, frame by frame in parts (an interrupted run resumes), cached under the hash of the
frames, the candidates and the imaging settings. The frames are read and looked at on the
executor (:mod:`markerplace.runtime.executor`), one task per frame; the result of a frame does
not depend on where it ran (the kitchen's 334 frames on idle cores: observe 19.8 s in this
process, 15.3 s on 2 workers).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import FeatureSet, FeatureWriter, ImageFeatures
from markerplace.imaging.visibility import marker_points, markers_unoccluded
from markerplace.localization.sift import extract_sift, lift_to_3d
from markerplace.progress import progress_bar
from markerplace.runtime import cache
from markerplace.runtime.executor import RuntimeConfig, WorkerJob, make_executor
from markerplace.runtime.stages import cached
from markerplace.scan.frame_images import load_frame

log = logging.getLogger(__name__)

__all__ = ["frame_features", "run_frame_observe"]


def frame_features(rgb: np.ndarray, depth_m: np.ndarray, world_from_cam: np.ndarray, samples: np.ndarray,
                   config: ImagingConfig) -> ImageFeatures:
    """One frame's observation: its 3D SIFT features and (C,) ``candidate_unoccluded`` of the
    candidates sampled by ``samples`` (C, 5, 3) (module docstring); ``depth_m`` planar, metres."""
    K = config.camera.K
    kp, desc = extract_sift(rgb, config.sift)
    pts, valid = lift_to_3d(kp, depth_m, K, world_from_cam, max_depth=config.max_depth,
                            image_size=(rgb.shape[1], rgb.shape[0]))  # a real principal point is off-centre
    unocc = markers_unoccluded(depth_m, world_from_cam, K, samples, config.occlusion_tolerance) if len(samples) \
        else np.zeros(0, bool)
    return ImageFeatures(kp[valid].astype(np.float32), np.clip(np.rint(desc[valid]), 0, 255).astype(np.uint8),
                         pts[valid].astype(np.float32), extras={"candidate_unoccluded": unocc})


def _frame_state(spec: tuple):
    """A worker's state: (the frame set, (C, 5, 3) candidate samples, ImagingConfig), as given
    (the executor has already made the worker keep freed memory: :mod:`markerplace.runtime.heap`)."""
    return spec


def _frame_task(state: tuple, item: tuple) -> ImageFeatures:
    """One frame's observation on a worker: ``item`` = (frame index, (4, 4) world_from_cam)."""
    fs, samples, config = state
    index, world_from_cam = item
    rgb, depth = load_frame(fs, fs.frames[int(index)])
    return frame_features(rgb, depth.astype(np.float32) / float(fs.depth_scale), world_from_cam, samples, config)


def run_frame_observe(fs, indices: np.ndarray, world_from_cam: np.ndarray, frames_key: str, marker_poses: np.ndarray,
                      sizes, config: ImagingConfig, run_dir: Path, timings: dict,
                      progress: bool = True, runtime: RuntimeConfig = RuntimeConfig()) -> tuple[FeatureSet, str]:
    """The observe stage of a frames plan: ``run_dir/observations/`` (module docstring).

    Args:
        fs: the frame set; ``indices`` (N,) the chosen frames, ``world_from_cam`` (N, 4, 4) their
            poses in the surface's internal frame; ``frames_key`` their identity
            (:func:`~markerplace.plan.frames.surface.frames_key`).
        marker_poses: (C, 4, 4) candidates; ``sizes`` (C,) or one black-square edge, metres.
        runtime: where the frames are looked at (never changes the result).

    Returns:
        (the features, the stage's cache key).
    """
    folder = Path(run_dir) / "observations"
    key = cache.hash_of("frames-observe-v1", frames_key, np.asarray(world_from_cam, float), config,
                        np.asarray(marker_poses, float), np.asarray(sizes, float))
    samples = marker_points(marker_poses, sizes) if len(marker_poses) else np.zeros((0, 5, 3))
    N = len(indices)

    def compute() -> FeatureSet:
        writer = FeatureWriter(folder, N, key)
        done = writer.done()
        if done:
            log.info("observe: resuming, %d of %d frames already done", len(done), N)
        todo = [j for j in range(N) if j not in done]
        job = WorkerJob(_frame_state, (fs, samples, config), cache.hash_of("frames-observe-worker", key))
        items = [(int(indices[j]), np.asarray(world_from_cam[j], float)) for j in todo]
        with make_executor(runtime) as executor, \
                progress_bar(N, "observe (frames)", "frame", progress, initial=len(done)) as bar:
            for t, feats in executor.map(_frame_task, items, job):
                writer.add(todo[t], feats)
                bar.update()
        return writer.finish()

    obs = cached("observe", folder, key, compute, None, FeatureSet.load, timings)
    log.info("observe: %d features with 3D points from %d frames (%.0f per frame)", len(obs.image_index), N,
             len(obs.image_index) / max(N, 1))
    return obs, key
