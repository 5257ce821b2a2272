"""The imaging engine: render a pose, extract features, lift them to 3D, detect tags and tell
which markers are in view. Planning (``observe``) and the testbed (map and query images) use it
alike, in whatever worker the executor runs it (:mod:`markerplace.runtime.executor`).

An :class:`ImagingEngine` is a worker's state: the scene loaded once, one renderer (GL context),
the marker sample points of the tests, and a small cache for task-specific objects (e.g. the
localizer of the map database a worker is using). Tasks are module-level functions
``task(engine, item)``; :func:`imaging_job` wraps an :class:`EngineSpec` as the executor's
:class:`~markerplace.runtime.executor.WorkerJob`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import ImageFeatures
from markerplace.imaging.visibility import markers_in_view, markers_unoccluded
from markerplace.localization.sift import SiftConfig, extract_sift, lift_to_3d
from markerplace.localization.tags import detect_tags
from markerplace.markers import Marker
from markerplace.render.renderer import Renderer
from markerplace.runtime.cache import hash_of
from markerplace.runtime.executor import WorkerJob

__all__ = ["EngineSpec", "ImagingEngine", "imaging_job", "marker_key"]


def marker_key(marker: Marker) -> tuple:
    """Hashable identity of a marker's appearance: id, size and pose (rounded to 0.1 mm)."""
    return (int(marker.tag_id), round(float(marker.size), 6),
            tuple(np.round(np.asarray(marker.world_from_marker, float)[:3].ravel(), 4)))


@dataclass(frozen=True, eq=False)
class EngineSpec:
    """What a worker needs to build its engine (picklable).

    Attributes:
        scene: a :class:`~markerplace.plan.observe.SceneSpec` (``load()`` rebuilds the scene).
        config: camera, feature preset and visibility settings.
        samples: named (M, S, 3) world sample sets of markers (see
            :func:`markerplace.imaging.visibility.marker_points`), e.g. ``candidates`` (centre
            and corners, for occlusion) or ``union`` (drawn quads, for "in view").
    """

    scene: object
    config: ImagingConfig
    samples: dict = field(default_factory=dict)


class ImagingEngine:
    """A worker's imaging state (see the module docstring)."""

    def __init__(self, spec: EngineSpec):
        self.spec = spec
        self.config = spec.config
        self.K = spec.config.camera.K
        self.renderer = Renderer(spec.scene.load(), spec.config.camera)
        self._markers: tuple = ()
        self.cache: dict = {}

    def close(self) -> None:
        self.renderer.close()
        self.cache.clear()

    def render(self, world_from_cam: np.ndarray, markers: Sequence[Marker] = (), rgb: bool = True):
        """Render (RGB unless ``rgb`` is False, and planar depth) with ``markers`` drawn."""
        key = tuple(marker_key(m) for m in markers)
        if key != self._markers:
            self.renderer.set_markers(list(markers))
            self._markers = key
        return self.renderer.render(world_from_cam, rgb=rgb, depth=True, normal=False)

    def features(self, result, tags: bool = False, sift: SiftConfig | None = None,
                 K: np.ndarray | None = None) -> ImageFeatures:
        """SIFT of a render (the engine's preset, or ``sift``), each keypoint lifted to 3D by the
        rendered depth (NaN beyond ``max_depth`` or at depth edges); with ``tags``, the detected
        tag36h11 tags too. ``K``: the (3, 3) camera of ``result`` when not the engine's (an
        image made from a render, :mod:`markerplace.imaging.location_views`)."""
        kp, desc = extract_sift(result.rgb, self.config.sift if sift is None else sift)
        pts, valid = lift_to_3d(kp, result.depth, self.K if K is None else K, result.world_from_cam,
                                max_depth=self.config.max_depth,
                                image_size=(result.rgb.shape[1], result.rgb.shape[0]))
        pts = np.where(valid[:, None], pts, np.nan)
        ids = np.zeros(0, np.int32)
        corners = np.zeros((0, 4, 2), np.float32)
        if tags:
            dets = detect_tags(result.rgb)
            ids = np.array([d.tag_id for d in dets], dtype=np.int32)
            corners = np.array([np.asarray(d.corners, np.float32).reshape(4, 2) for d in dets],
                               dtype=np.float32).reshape(-1, 4, 2)
        return ImageFeatures(kp.astype(np.float32), np.clip(np.rint(desc), 0, 255).astype(np.uint8),
                             pts.astype(np.float32), ids, corners)

    def unoccluded(self, result, name: str, mask: np.ndarray | None = None) -> np.ndarray:
        """(M,) bool per marker of sample set ``name``: wholly visible in this (marker-free)
        render; only markers where ``mask`` is true are tested (others False)."""
        samples = self.spec.samples[name]
        out = np.zeros(len(samples), bool)
        sel = np.arange(len(samples)) if mask is None else np.flatnonzero(mask)
        if len(sel):
            out[sel] = markers_unoccluded(result.depth, result.world_from_cam, self.K, samples[sel],
                                          self.config.occlusion_tolerance)
        return out

    def in_view(self, result, name: str) -> np.ndarray:
        """(M,) bool per marker of sample set ``name``: may change this (marker-free) render."""
        return markers_in_view(result.depth, result.world_from_cam, self.K, self.spec.samples[name],
                               self.config.visibility_margin_px, self.config.occlusion_tolerance)


def _build(spec: EngineSpec) -> ImagingEngine:
    return ImagingEngine(spec)


def _close(engine: ImagingEngine) -> None:
    engine.close()


def imaging_job(spec: EngineSpec):
    """The executor job whose worker state is an :class:`ImagingEngine` for ``spec``."""
    key = hash_of("imaging-engine", repr(spec.scene), spec.config, sorted(spec.samples.items()))
    return WorkerJob(_build, spec, key, _close)
