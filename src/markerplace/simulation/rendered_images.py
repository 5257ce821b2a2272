"""Map and test images of the testbed: rendered by the imaging engine, features re-used across
placements.

Renders are deterministic, so an image whose view holds no marker of a placement equals the
marker-free image: its features come from the marker-free set, computed once per image set
(:class:`BaseImages`). More generally an image only depends on the markers in its view, so
features are keyed by ``(image, markers in view)`` and shared between placements with the same
markers in that view (e.g. the nested OMP prefixes). "In view" is decided conservatively on the
marker-free depth (:func:`markerplace.imaging.visibility.markers_in_view`, union of every
evaluated marker).
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from markerplace.imaging.engine import EngineSpec, ImagingEngine, imaging_job, marker_key
from markerplace.imaging.features import FeatureSet, FeatureWriter, ImageFeatures
from markerplace.imaging.visibility import MARKER_SAMPLES, marker_points, select_in_view
from markerplace.markers import Marker
from markerplace.progress import progress_bar
from markerplace.runtime import cache, run_folder
from markerplace.runtime.atomic_io import write_npy
from markerplace.simulation.conditions import QueryCondition, render_query

log = logging.getLogger(__name__)

__all__ = ["TestbedImaging", "BaseImages", "base_features_key"]


def _render_task(engine: ImagingEngine, item) -> ImageFeatures:
    """(world_from_cam, markers, map_only[, image condition]) -> features of the render with
    those markers, degraded by the query condition when one is given
    (:func:`~markerplace.simulation.conditions.render_query`); a marker-free render also carries
    ``extras['in_view']``, the (U,) union-marker in-view mask (of the clean depth)."""
    world_from_cam, markers, map_only = item[:3]
    res = render_query(engine, world_from_cam, markers, item[3] if len(item) > 3 else None)
    feats = engine.features(res, tags=True)
    if map_only:
        feats = feats.with_3d_only()
    if not markers:
        feats = ImageFeatures(feats.keypoints, feats.descriptors, feats.points_world, feats.tag_ids,
                              feats.tag_corners, {"in_view": engine.in_view(res, "union")})
    return feats


def _in_view_task(engine: ImagingEngine, world_from_cam) -> np.ndarray:
    """(U,) union-marker in-view mask from a marker-free depth render."""
    return engine.in_view(engine.render(world_from_cam, (), rgb=False), "union")


def _geometry_key(marker: Marker) -> tuple:
    """Where a marker is drawn (size and pose, as :func:`~markerplace.imaging.engine.marker_key`
    without the tag id): whether it is in view does not depend on its id."""
    return marker_key(marker)[1:]


class TestbedImaging:
    """Renders testbed images on an executor: every worker keeps one imaging engine whose
    ``union`` sample set holds every marker pose any evaluated placement uses (one entry per
    pose and size, whatever the tag id).

    Args:
        scene_spec: how workers rebuild the scene.
        config: the testbed's :class:`~markerplace.imaging.config.ImagingConfig`.
        union_markers: every marker of every evaluated placement.
        executor: where the work runs.
        progress: progress bars.
    """

    __test__ = False

    def __init__(self, scene_spec, config, union_markers: Sequence[Marker], executor, progress: bool = True):
        self.config = config
        self.union = list({_geometry_key(m): m for m in union_markers}.values())
        self.union_index = {_geometry_key(m): i for i, m in enumerate(self.union)}
        T = np.array([m.world_from_marker for m in self.union]).reshape(-1, 4, 4)
        self.samples = marker_points(T, [m.size for m in self.union], grid=config.visibility_grid) \
            if self.union else np.zeros((0, config.visibility_grid ** 2, 3))
        self.spec = EngineSpec(scene_spec, config, {"union": self.samples})
        self.job = imaging_job(self.spec)
        self.executor = executor
        self.progress = progress

    def run(self, task, items: list, desc: str, initial: int = 0):
        """``(index, task(engine, items[index]))`` for every item, with a progress bar that
        starts at ``initial`` (images an interrupted run already finished)."""
        with progress_bar(len(items) + initial, desc, "img", self.progress, initial=initial) as bar:
            for i, r in self.executor.map(task, items, self.job):
                bar.update()
                yield i, r

    def render_iter(self, world_from_cam: np.ndarray, indices: Sequence[int], markers: Sequence[Marker],
                    map_only: bool, desc: str,
                    condition: QueryCondition | None = None) -> Iterator[tuple[int, ImageFeatures]]:
        """``(i, features)`` of images ``indices`` of (N, 4, 4) ``world_from_cam`` rendered with
        ``markers`` (under the query ``condition``, None: clean), as the executor finishes them
        (in any order)."""
        indices = [int(i) for i in indices]
        items = [_item(world_from_cam[i], list(markers), map_only, condition, i) for i in indices]
        for j, f in self.run(_render_task, items, desc):
            yield indices[j], f

    def render(self, world_from_cam: np.ndarray, indices: Sequence[int], markers: Sequence[Marker],
               map_only: bool, desc: str, condition: QueryCondition | None = None) -> dict[int, ImageFeatures]:
        """Features of images ``indices`` of (N, 4, 4) ``world_from_cam`` rendered with ``markers``."""
        return dict(self.render_iter(world_from_cam, indices, markers, map_only, desc, condition))

    def columns(self, markers: Sequence[Marker]) -> np.ndarray:
        """(M,) union indices of ``markers`` (the columns of a base in-view mask)."""
        return np.array([self.union_index[_geometry_key(m)] for m in markers], dtype=np.int64)

    def view_digest(self, in_view: np.ndarray, markers: Sequence[Marker]) -> str:
        """Digest of the (N, M) in-view columns of ``markers`` in the (N, U) base mask, in the
        markers' order: what a prediction with these markers reads of the mask, the same
        whatever other placements the run evaluates (a key never holds the whole union)."""
        return cache.hash_of(np.asarray(in_view, bool)[:, self.columns(markers)])

    def view_keys(self, in_view: np.ndarray, markers: Sequence[Marker]) -> list[tuple]:
        """Per image: the ``markers`` in view as sorted (union index, tag id) pairs, from the
        (N, U) base mask (empty: the image equals its marker-free render)."""
        idx = self.columns(markers)
        if len(idx) == 0:
            return [()] * len(in_view)
        ids = [int(m.tag_id) for m in markers]
        sub = np.asarray(in_view)[:, idx]
        return [tuple(sorted((int(idx[j]), ids[j]) for j in np.flatnonzero(row))) for row in sub]

    def appearance(self, key: tuple) -> tuple:
        """What a :meth:`view_keys` entry draws, independent of this run's union order: per
        marker in view, its tag id, size and pose (as :func:`marker_key`)."""
        return tuple(sorted((tag_id,) + _geometry_key(self.union[u]) for u, tag_id in key))


def _item(world_from_cam: np.ndarray, markers: list, map_only: bool, condition: QueryCondition | None,
          index: int) -> tuple:
    """A :func:`_render_task` item of image ``index`` (clean: no fourth element)."""
    base = (world_from_cam, markers, map_only)
    return base if condition is None else base + (condition.image(index),)


def base_features_key(key: str, map_only: bool, config) -> str:
    """Cache key of the marker-free features of the image set named by ``key`` (scene, poses),
    3D points only or not, made with the :class:`~markerplace.imaging.config.ImagingConfig`
    ``config``: the one :class:`BaseImages` checks, and the one ``observe`` marks the map
    features it writes with (:class:`markerplace.plan.observe.MapOutput`)."""
    return cache.hash_of("base-features-v2", key, map_only, config)


PART_SIZE = 64
"""Images per part file of a marker-free stage: an interrupted stage loses at most this many."""


class BaseImages:
    """Marker-free features (``features/``) and the (N, U) union-marker in-view mask
    (``in_view.npy``) of one image set, cached in ``folder``: features are keyed without
    markers, the mask with the union (a new placement only costs depth renders). ``key`` is
    the features' cache key: it names the set's images (scene, poses, imaging settings).

    Both stages commit their work as it arrives: every ``part_size`` images go to a part file
    (:class:`~markerplace.imaging.features.FeatureWriter`: ``features/parts/`` and
    ``in_view_parts/parts/``), so an interrupted stage loses at most one part and the next run
    renders only the images no part holds. The assembled result does not depend on where a run
    stopped (images are put back in index order).

    ``condition``: the query condition its images are rendered under (None: clean; the map
    images are always clean); part of ``key``.
    """

    def __init__(self, imaging: TestbedImaging, world_from_cam: np.ndarray, folder: Path, key: str, map_only: bool,
                 name: str, part_size: int = PART_SIZE, condition: QueryCondition | None = None):
        self.folder = Path(folder)
        self.world_from_cam = np.asarray(world_from_cam, float)
        self.part_size = int(part_size)
        N = len(world_from_cam)
        self.condition = condition
        feat_key = base_features_key(key, map_only, imaging.config)
        mask_key = cache.hash_of(feat_key, imaging.samples, imaging.config.visibility_margin_px,
                                 imaging.config.occlusion_tolerance)
        feat_dir, mask_path = self.folder / "features", self.folder / "in_view.npy"
        mask = None
        feats = cache.load_fresh(feat_dir, feat_key, FeatureSet.load) if FeatureSet.exists(feat_dir) else None
        if feats is not None:
            log.info("%s: reusing marker-free features in %s", name, feat_dir)
        else:
            writer = FeatureWriter(feat_dir, N, feat_key + mask_key, self.part_size)
            todo = _resume(writer, N, f"{name} (no markers)")
            items = [_item(self.world_from_cam[i], [], map_only, condition, i) for i in todo]
            for j, f in imaging.run(_render_task, items, f"{name} (no markers)", initial=N - len(todo)):
                writer.add(todo[j], f)
            feats = writer.finish()
            mask = np.asarray(feats.extras.pop("in_view")).reshape(N, -1)
            run_folder.remove(feat_dir / "extra_in_view.npy")
            cache.mark_done(feat_dir, feat_key)
        if mask is None:
            mask = cache.load_fresh(mask_path, mask_key, lambda p: np.load(p, allow_pickle=False))
        observed = feats.extras.pop("marker_in_view", None)  # features made by observe (plan/observe.py)
        if mask is None and observed is not None:
            mask = _observed_mask(observed, feat_dir, imaging.samples, name)
        if mask is None:  # features cached, markers changed: depth-only renders
            mask = self._depth_mask(imaging, mask_key, name)
        if not cache.is_fresh(mask_path, mask_key):
            write_npy(mask_path, mask)
            cache.mark_done(mask_path, mask_key)
        self.features = feats
        self.in_view = mask.reshape(N, len(imaging.union))
        self.key = feat_key
        # the features' bytes only: the mask's columns depend on which placements this run
        # evaluates, so each prediction keys the columns of its own markers (view_digest)
        self.digest = cache.content_digest(feat_dir)

    def _depth_mask(self, imaging: TestbedImaging, mask_key: str, name: str) -> np.ndarray:
        """(N, U) in-view mask from depth-only renders, streamed to ``in_view_parts/`` (resumed
        from there after an interruption, removed once assembled)."""
        N = len(self.world_from_cam)
        if N == 0:
            return np.zeros((0, len(imaging.union)), bool)
        work = self.folder / "in_view_parts"
        writer = FeatureWriter(work, N, mask_key, self.part_size)
        todo = _resume(writer, N, f"{name} (marker visibility)")
        for j, m in imaging.run(_in_view_task, [self.world_from_cam[i] for i in todo], f"{name} (marker visibility)",
                                initial=N - len(todo)):
            writer.add(todo[j], ImageFeatures(np.zeros((0, 2), np.float32), np.zeros((0, 128), np.uint8),
                                              np.zeros((0, 3), np.float32), extras={"in_view": m}))
        mask = np.array(writer.finish().extras["in_view"]).reshape(N, -1)
        run_folder.remove_tree(work)
        return mask


def _observed_mask(stored: np.ndarray, feat_dir: Path, samples: np.ndarray, name: str) -> np.ndarray | None:
    """The (N, U) in-view mask of the union markers sampled by ``samples``, from the (N, C)
    ``marker_in_view`` extra that ``observe`` stores with the map features it writes, or None
    when it does not cover every union marker."""
    if not (feat_dir / MARKER_SAMPLES).exists():
        return None
    mask = select_in_view(stored, np.load(feat_dir / MARKER_SAMPLES, allow_pickle=False), samples)
    if mask is None:
        log.info("%s: a marker is not among the candidates observe tested: marker visibility from depth renders", name)
    return mask


def _resume(writer: FeatureWriter, n: int, desc: str) -> list[int]:
    """The images of ``writer``'s ``n`` that no part of an earlier run holds, saying so when
    some do."""
    done = writer.done()
    if done:
        log.info("%s: resuming, %d of %d images already done", desc, len(done), n)
    return [i for i in range(n) if i not in done]
