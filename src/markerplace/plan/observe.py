"""Observation stage: at every feasible pose, render, extract SIFT (the scoring preset), lift
keypoints to 3D, and test which candidate markers are wholly visible.

Output: a :class:`~markerplace.imaging.features.FeatureSet` folder (``observations/``) with only
the keypoints that have a 3D point (within ``max_depth``), and the per-pose extra
``candidate_unoccluded`` (N, C) bool: the centre and corners of candidate c are not hidden at
pose i (tested only where the candidate is geometrically in view; see
:func:`markerplace.imaging.visibility.markers_unoccluded`).

With a :class:`MapOutput`, every render also gives the testbed's marker-free map image (its own
SIFT preset and the tags, 3D points only, and the (N, C) ``marker_in_view`` extra: which of the
candidates could change the image, :func:`markerplace.imaging.visibility.markers_in_view`), written
into a second feature folder: ``evaluate`` (and the calibration of a success model) then reuses
the render instead of rendering the pose again. The renders are deterministic, so those features
are the ones the testbed would make itself (tests/pipelines/test_map_from_observe.py compares them).

The work runs on an executor (:mod:`markerplace.runtime.executor`: in process, local processes
or a Dask cluster), one imaging engine per worker, results streamed to disk in parts (an
interrupted run resumes from them).
"""

from __future__ import annotations

import logging
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

from markerplace.imaging.config import ImagingConfig, renders_alike
from markerplace.imaging.engine import EngineSpec, imaging_job
from markerplace.imaging.features import FeatureSet, FeatureWriter, ImageFeatures
from markerplace.imaging.location_views import FaceLayout, crop, face_layout, location_groups, split_features, unoccluded_from_faces, warp_view
from markerplace.imaging.visibility import MARKER_SAMPLES, marker_points
from markerplace.progress import progress_bar
from markerplace.render.renderer import RenderResult
from markerplace.runtime import cache
from markerplace.runtime.atomic_io import write_npy
from markerplace.runtime.executor import RuntimeConfig, make_executor
from markerplace.runtime.stages import cached
from markerplace.tagfamily import DRAWING_VERSION

log = logging.getLogger(__name__)

__all__ = ["MapOutput", "observe", "run_observe"]


@dataclass(frozen=True)
class MapOutput:
    """Where and how observe also writes the testbed's marker-free map features.

    Attributes:
        folder: the map's feature folder (the testbed's ``map_base/features``).
        key: the cache key the testbed gives those features
            (:func:`markerplace.simulation.rendered_images.base_features_key`); the folder is marked done
            with it.
        config: the testbed's imaging settings: the same camera and depth settings as
            observe's, its own SIFT preset (refused otherwise: the render would differ).
    """

    folder: Path
    key: str
    config: ImagingConfig


def _observe_task(engine, item):
    """(world_from_cam, candidate mask, map SIFT preset or None, observations wanted) -> the
    pose's 3D features and candidate occlusion; with a preset, a pair: those (None when not
    wanted) and the map image's features (tags and the ``marker_in_view`` extra included)."""
    world_from_cam, candidate_mask, map_sift, with_obs = item
    res = engine.render(world_from_cam)
    obs = None
    if with_obs:
        feats = engine.features(res).with_3d_only()
        obs = ImageFeatures(feats.keypoints, feats.descriptors, feats.points_world,
                            extras={"candidate_unoccluded": engine.unoccluded(res, "candidates", candidate_mask)})
    if map_sift is None:
        return obs
    m = engine.features(res, tags=True, sift=map_sift).with_3d_only()
    return obs, ImageFeatures(m.keypoints, m.descriptors, m.points_world, m.tag_ids, m.tag_corners,
                              {"marker_in_view": engine.in_view(res, "quads")})


def _observe_location_task(engine, item):
    """(the location's (n, 4, 4) poses, (n, C) candidate masks, (n,) observations wanted, the
    :class:`FaceLayout`, whether the odd poses share the faces' features) -> per pose its 3D
    features and candidate occlusion, None where not wanted. The even poses are rendered as
    faces; an odd pose takes its neighbours' features (``share_features``) or SIFT of the image
    resampled from them (:mod:`markerplace.imaging.location_views`)."""
    poses, masks, wanted, layout, share_features = item
    n, K = len(poses), layout.camera.K
    need = {j for j in range(0, n, 2) if wanted[j]}
    need |= {k % n for j in range(1, n, 2) if wanted[j] for k in (j - 1, j + 1)}
    faces = {j: engine.render(poses[j]) for j in sorted(need)}
    face_feats = {j: engine.features(r).with_3d_only() for j, r in faces.items()} if share_features else {}
    samples = engine.spec.samples["candidates"]
    tolerance = engine.config.occlusion_tolerance
    out = []
    for j in range(n):
        if not wanted[j]:
            out.append(None)
            continue
        used = [j] if j % 2 == 0 else [j - 1, (j + 1) % n]
        if share_features:
            feats = split_features(layout, poses[j], [(poses[u], face_feats[u]) for u in used])
        else:
            if j % 2 == 0:
                rgb, depth = crop(layout, faces[j].rgb), crop(layout, faces[j].depth)
            else:
                rgb, depth = warp_view(layout, poses[j], [(poses[u], faces[u].rgb, faces[u].depth) for u in used])
            feats = engine.features(RenderResult(rgb, depth, None, poses[j]), K=K).with_3d_only()
        unoccluded = np.zeros(len(samples), bool)
        sel = np.flatnonzero(masks[j])
        if len(sel):
            unoccluded[sel] = unoccluded_from_faces(layout, poses[j], [(poses[u], faces[u].depth) for u in used],
                                                    samples[sel], tolerance)
        out.append(ImageFeatures(feats.keypoints, feats.descriptors, feats.points_world,
                                 extras={"candidate_unoccluded": unoccluded}))
    return out


def _location_layout(world_from_cam: np.ndarray, config: ImagingConfig, allowed: bool) -> FaceLayout | None:
    """The face layout when ``config.observe_views`` is not ``pose`` and it can serve these poses
    (and only observations are made: the map images must be real renders), else None."""
    if config.observe_views == "pose" or not allowed or len(world_from_cam) == 0:
        return None
    layout = face_layout(world_from_cam, location_groups(world_from_cam), config.camera)
    if layout is None:
        log.info("observe: the poses of a location cannot share renders (too few yaws for the camera's field of "
                 "view); rendering every pose")
    else:
        log.info("observe: one %dx%d face per two poses of a location (--observe-views %s)",
                 layout.face.width, layout.face.height, config.observe_views)
    return layout


def _check_map_output(map_output: MapOutput, config: ImagingConfig) -> None:
    if not renders_alike(map_output.config, config):
        raise ValueError("observe: the map's imaging settings differ from observe's beyond the SIFT preset")


def observe(scene_spec, world_from_cam: np.ndarray, candidate_in_view: np.ndarray,
            candidate_world_from_marker: np.ndarray, tag_sizes, config: ImagingConfig, executor,
            folder: str | Path, key: str = "", progress: bool = True,
            map_output: MapOutput | None = None, observations: bool = True) -> FeatureSet | None:
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
        map_output: also write the testbed's map features there (None: not); its
            ``marker_in_view`` extra is over the same C markers, drawn as their whole quads
            (``config.visibility_grid``). Skipped when that folder is already fresh.
        observations: False: only the map features (``folder`` untouched; returns None), for
            a plan whose observations are cached.
    """
    N, C = len(world_from_cam), len(candidate_world_from_marker)
    samples = {"candidates": marker_points(candidate_world_from_marker, tag_sizes) if C else np.zeros((0, 5, 3))}
    if map_output is not None and cache.is_fresh(map_output.folder, map_output.key):
        map_output = None
    if map_output is not None:
        _check_map_output(map_output, config)
        grid = map_output.config.visibility_grid
        samples["quads"] = marker_points(candidate_world_from_marker, tag_sizes, grid=grid) if C \
            else np.zeros((0, grid * grid, 3))
    layout = _location_layout(world_from_cam, config, map_output is None and observations)
    job = imaging_job(EngineSpec(scene_spec, config if layout is None else layout.face_config(config), samples))
    writers = [FeatureWriter(folder, N, key) if observations else None]
    if map_output is not None:
        writers.append(FeatureWriter(map_output.folder, N, map_output.key))
    done = [set(range(N)) if w is None else w.done() for w in writers]
    todo = [i for i in range(N) if not all(i in d for d in done)]
    if N - len(todo):
        log.info("observe: resuming, %d of %d poses already done", N - len(todo), N)
    mask = candidate_in_view if C else np.zeros((N, 0), bool)
    map_sift = None if map_output is None else map_output.config.sift
    with progress_bar(N, "observe" if observations else "map (no markers)", "pose", progress,
                      initial=N - len(todo)) as bar:
        if layout is not None:
            groups = [g for g in location_groups(world_from_cam) if any(i not in done[0] for i in g)]
            share = config.observe_views == "location-features"
            items = [(world_from_cam[g], mask[g], np.array([i not in done[0] for i in g]), layout, share)
                     for g in groups]
            for j, results in executor.map(_observe_location_task, items, job):
                for i, feats in zip(groups[j], results):
                    if feats is not None:
                        writers[0].add(int(i), feats)
                        bar.update()
        else:
            items = [(world_from_cam[i], mask[i], map_sift, i not in done[0]) for i in todo]
            for j, result in executor.map(_observe_task, items, job):
                for writer, d, feats in zip(writers, done, result if map_output is not None else (result,)):
                    if todo[j] not in d:
                        writer.add(todo[j], feats)
                bar.update()
    if map_output is not None:
        writers[1].finish()
        write_npy(map_output.folder / MARKER_SAMPLES, samples["quads"])
        cache.mark_done(map_output.folder, map_output.key)
        log.info("observe: the testbed's marker-free map features written to %s", map_output.folder)
    return None if writers[0] is None else writers[0].finish()


def run_observe(scene_spec, world_from_cam: np.ndarray, disc_key: str, marker_poses: np.ndarray, sizes: list,
                in_view: np.ndarray, config: ImagingConfig, run_dir: Path, executor, runtime: RuntimeConfig,
                timings: dict, progress: bool = True, before: Callable[[], None] | None = None,
                map_output: MapOutput | None = None) -> tuple[FeatureSet, str]:
    """The observe stage of a run folder: ``run_dir/observations/``, reused while the
    discretization (its key and file digest), the imaging settings, the tag drawing and the
    marker poses and sizes are unchanged; an interrupted stage resumes from its parts. When it
    must run and also write the map features, it observes per pose (``observe_views`` ``pose``,
    and so keyed): those renders serve both; and observations made so (``plan --with-map``) are
    reused by a later run with the map (``evaluate --plan``).

    Args:
        world_from_cam: (N, 4, 4) the discretization's camera poses.
        marker_poses: (M, 4, 4) candidates then existing markers; ``sizes`` (M,) metres.
        in_view: (N, M) bool geometric visibility (only those are tested for occlusion).
        executor: where the work runs; None: one made from ``runtime`` when the stage runs.
        before: called when the stage must run, before anything renders (the run-size check).
        map_output: the testbed's map features written from the same renders when the stage
            runs (:func:`observe`), or rendered for alone when the stage is cached and they are
            not; not part of the stage's key.

    Returns:
        (the features, the stage's cache key).
    """
    def key_of(config: ImagingConfig) -> str:
        return cache.hash_of("observe-v3", DRAWING_VERSION, disc_key, cache.content_digest(run_dir / "discretization.npz"),
                             config, marker_poses, sizes)

    key = key_of(config)
    if map_output is not None and config.observe_views != "pose" and not cache.is_fresh(run_dir / "observations", key):
        # one render per pose gives both the observations and the map images (which must be
        # the renders of their poses): cheaper than faces plus a second pass for the map; and
        # observations a run with the map made per pose (plan --with-map) are the ones to reuse
        per_pose = replace(config, observe_views="pose")
        if cache.is_fresh(run_dir / "observations", key_of(per_pose)) or not cache.is_fresh(map_output.folder,
                                                                                              map_output.key):
            config, key = per_pose, key_of(per_pose)

    def compute() -> FeatureSet:
        log.info("observe: rendering and extracting SIFT at %d poses", len(world_from_cam))
        with make_executor(runtime) if executor is None else nullcontext(executor) as ex:
            return observe(scene_spec, world_from_cam, in_view, marker_poses, np.asarray(sizes, float), config, ex,
                           run_dir / "observations", key, progress=progress, map_output=map_output)

    if before is not None and not cache.is_fresh(run_dir / "observations", key):
        before()
    obs = cached("observe", run_dir / "observations", key, compute, None, FeatureSet.load, timings)
    if map_output is not None and not cache.is_fresh(map_output.folder, map_output.key):
        log.info("observe: cached; rendering the %d poses again for the map features", len(world_from_cam))
        with make_executor(runtime) if executor is None else nullcontext(executor) as ex:
            observe(scene_spec, world_from_cam, in_view, marker_poses, np.asarray(sizes, float), config, ex,
                    run_dir / "observations", key, progress=progress, map_output=map_output, observations=False)
    log.info("observe: %d features with 3D points (%.0f per pose)", len(obs.image_index),
             len(obs.image_index) / max(len(world_from_cam), 1))
    return obs, key

