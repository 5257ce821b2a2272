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
from pathlib import Path

import numpy as np

from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.engine import EngineSpec, imaging_job
from markerplace.imaging.features import FeatureSet, FeatureWriter, ImageFeatures
from markerplace.imaging.visibility import marker_points
from markerplace.progress import progress_bar

log = logging.getLogger(__name__)

__all__ = ["observe"]


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
