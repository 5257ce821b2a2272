"""Observation stage: at every feasible pose, render, extract SIFT (the scoring preset), lift
keypoints to 3D, and test which candidate markers are wholly visible.

Output: a :class:`~markerplace.imaging.features.FeatureSet` folder (``observations/``) with only
the keypoints that have a 3D point (within ``max_depth``), and the per-pose extra
``candidate_unoccluded`` (N, C) bool: the centre and corners of candidate c are not hidden at
pose i (tested only where the candidate is geometrically in view; see
:func:`markerplace.imaging.visibility.markers_unoccluded`).

The work runs on an executor (:mod:`markerplace.runtime.executor`: in process, local processes
or a Dask cluster), one imaging engine per worker, results streamed to disk in parts (an
interrupted run resumes from them).
"""

from __future__ import annotations

import logging
from contextlib import nullcontext
from pathlib import Path
from typing import Callable

import numpy as np

from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.engine import EngineSpec, imaging_job
from markerplace.imaging.features import FeatureSet, FeatureWriter, ImageFeatures
from markerplace.imaging.visibility import marker_points
from markerplace.progress import progress_bar
from markerplace.runtime import cache
from markerplace.runtime.executor import RuntimeConfig, make_executor
from markerplace.runtime.stages import cached
from markerplace.tagfamily import DRAWING_VERSION

log = logging.getLogger(__name__)

__all__ = ["observe", "run_observe"]


def _observe_task(engine, item) -> ImageFeatures:
    """(world_from_cam, candidate mask) -> the pose's 3D features and candidate occlusion."""
    world_from_cam, candidate_mask = item
    res = engine.render(world_from_cam)
    feats = engine.features(res).with_3d_only()
    unoccluded = engine.unoccluded(res, "candidates", candidate_mask)
    return ImageFeatures(feats.keypoints, feats.descriptors, feats.points_world,
                         extras={"candidate_unoccluded": unoccluded})


def observe(scene_spec, world_from_cam: np.ndarray, candidate_in_view: np.ndarray,
            candidate_world_from_marker: np.ndarray, tag_sizes, config: ImagingConfig, executor,
            folder: str | Path, key: str = "", progress: bool = True) -> FeatureSet:
    """Render and extract features at every pose into the FeatureSet folder ``folder``.

    Args:
        scene_spec: how each worker (re)loads the scene (:class:`~markerplace.scene.spec.SceneSpec`).
        world_from_cam: (N, 4, 4) feasible camera poses.
        candidate_in_view: (N, C) bool, candidates geometrically visible from each pose (range,
            field of view, viewing angle); only those are tested for occlusion.
        candidate_world_from_marker: (C, 4, 4) candidate marker poses.
        tag_sizes: black-square edge in metres, (C,) or one for all.
        config: camera, feature preset, occlusion tolerance.
        executor: where the work runs.
        folder: output folder; its ``parts/`` from an interrupted run with the same ``key`` are
            reused.
        key: identity of these inputs (parts written for other inputs are dropped).
        progress: a progress bar.
    """
    N, C = len(world_from_cam), len(candidate_world_from_marker)
    samples = marker_points(candidate_world_from_marker, tag_sizes) if C else np.zeros((0, 5, 3))
    job = imaging_job(EngineSpec(scene_spec, config, {"candidates": samples}))
    writer = FeatureWriter(folder, N, key)
    done = writer.done()
    todo = [i for i in range(N) if i not in done]
    if done:
        log.info("observe: resuming, %d of %d poses already done", len(done), N)
    mask = candidate_in_view if C else np.zeros((N, 0), bool)
    items = [(world_from_cam[i], mask[i]) for i in todo]
    with progress_bar(N, "observe", "pose", progress, initial=len(done)) as bar:
        for j, feats in executor.map(_observe_task, items, job):
            writer.add(todo[j], feats)
            bar.update()
    return writer.finish()


def run_observe(scene_spec, world_from_cam: np.ndarray, disc_key: str, marker_poses: np.ndarray, sizes: list,
                in_view: np.ndarray, config: ImagingConfig, run_dir: Path, executor, runtime: RuntimeConfig,
                timings: dict, progress: bool = True, before: Callable[[], None] | None = None) -> tuple[FeatureSet, str]:
    """The observe stage of a run folder: ``run_dir/observations/``, reused while the
    discretization (its key and file digest), the imaging settings, the tag drawing and the
    marker poses and sizes are unchanged; an interrupted stage resumes from its parts.

    Args:
        world_from_cam: (N, 4, 4) the discretization's camera poses.
        marker_poses: (M, 4, 4) candidates then existing markers; ``sizes`` (M,) metres.
        in_view: (N, M) bool geometric visibility (only those are tested for occlusion).
        executor: where the work runs; None: one made from ``runtime`` when the stage runs.
        before: called when the stage must run, before anything renders (the run-size check).

    Returns:
        (the features, the stage's cache key).
    """
    key = cache.hash_of("observe-v3", DRAWING_VERSION, disc_key, cache.content_digest(run_dir / "discretization.npz"),
                        config, marker_poses, sizes)

    def compute() -> FeatureSet:
        log.info("observe: rendering and extracting SIFT at %d poses", len(world_from_cam))
        with make_executor(runtime) if executor is None else nullcontext(executor) as ex:
            return observe(scene_spec, world_from_cam, in_view, marker_poses, np.asarray(sizes, float), config, ex,
                           run_dir / "observations", key, progress=progress)

    if before is not None and not cache.is_fresh(run_dir / "observations", key):
        before()
    obs = cached("observe", run_dir / "observations", key, compute, None, FeatureSet.load, timings)
    log.info("observe: %d features with 3D points (%.0f per pose)", len(obs.image_index),
             len(obs.image_index) / max(len(world_from_cam), 1))
    return obs, key

