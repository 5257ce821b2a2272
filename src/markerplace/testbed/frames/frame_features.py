"""Per-frame work of the real-photograph testbed, run on the executor
(:mod:`markerplace.runtime.executor`): one image's features for the localizer.

Two kinds of image stand at a frame's pose:

* ``real``: the frame's own photograph with the placement's tags composited in
  (:func:`markerplace.imaging.composite.composite_tags`: projected with the frame's pose and
  intrinsics, hidden where the frame's real depth is nearer, matched to the frame's blur,
  brightness and noise);
* ``render``: the fused surface rendered at the frame's pose with the frame's intrinsics, the
  tags drawn by the renderer (what a plan made from a scan assumes the camera sees).

Either way the features are the localizer's: SIFT (``ImagingConfig.sift``, OpenCV's defaults
for the testbed) lifted to 3D by the image's depth (the real depth for ``real``, the rendered
depth for ``render``) and the tag36h11 tags the real detector finds in the image. The
composite's random noise is seeded per (seed, frame, markers), so a rerun gives the same image.

A worker's state (:class:`FrameWorker`) holds the frame set, the intrinsics and, made on first
use, a renderer of the fused surface; its ``cache`` and ``K`` also serve
:func:`markerplace.simulation.maps.localize_task`.

Frames: world z up, metres; ``world_from_cam`` in OpenCV camera axes.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from markerplace.imaging.composite import CompositeConfig, composite_tags
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.engine import EngineSpec, ImagingEngine, marker_key
from markerplace.imaging.features import ImageFeatures
from markerplace.imaging.visibility import marker_points, markers_in_view
from markerplace.localization.sift import extract_sift, lift_to_3d
from markerplace.localization.tags import detect_tags
from markerplace.markers import Marker
from markerplace.runtime.cache import hash_of
from markerplace.runtime.executor import WorkerJob
from markerplace.scan.frame_images import load_frame
from markerplace.scan.frameset import FrameSet
from markerplace.scene.spec import SceneSpec

__all__ = ["FrameJobSpec", "FrameWorker", "frame_job", "image_task", "frame_in_view", "REAL", "RENDER"]

REAL = "real"
"""Image kind: the frame's photograph (tags composited in)."""
RENDER = "render"
"""Image kind: the fused surface rendered at the frame's pose (tags drawn)."""


@dataclass(frozen=True, eq=False)
class FrameJobSpec:
    """What a worker needs (picklable): the frames, the surface to render and the imaging.

    Attributes:
        frames: the frame set (paths and poses).
        surface: the fused surface as a scene recipe (for ``render`` images), or None.
        imaging: camera (the frames' intrinsics), SIFT preset and depth limit.
        composite: how tags are put into the photographs.
        seed: seed of the composite's noise.
    """

    frames: FrameSet
    surface: SceneSpec | None
    imaging: ImagingConfig
    composite: CompositeConfig
    seed: int


class FrameWorker:
    """A worker's state: the frame set, ``K`` (3, 3), a ``cache`` and a lazy renderer."""

    def __init__(self, spec: FrameJobSpec):
        self.spec = spec
        self.K = spec.imaging.camera.K
        self.cache: dict = {}
        self._engine: ImagingEngine | None = None

    @property
    def engine(self) -> ImagingEngine:
        """The renderer of the fused surface (made on first use)."""
        if self._engine is None:
            if self.spec.surface is None:
                raise RuntimeError("no surface to render: the job was made without one")
            self._engine = ImagingEngine(EngineSpec(self.spec.surface, self.spec.imaging))
        return self._engine

    def close(self) -> None:
        if self._engine is not None:
            self._engine.close()
        self.cache.clear()


def _build(spec: FrameJobSpec) -> FrameWorker:
    return FrameWorker(spec)


def _close(worker: FrameWorker) -> None:
    worker.close()


def frame_job(spec: FrameJobSpec) -> WorkerJob:
    """The executor job whose worker state is a :class:`FrameWorker` for ``spec``."""
    key = hash_of("frame-worker-v1", str(spec.frames.root), len(spec.frames.frames), repr(spec.surface),
                  spec.imaging, spec.composite, spec.seed)
    return WorkerJob(_build, spec, key, _close)


def _noise_seed(seed: int, frame: int, markers: Sequence[Marker]) -> int:
    text = repr((int(seed), int(frame), [marker_key(m) for m in markers])).encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:8], "little")


def _features(worker: FrameWorker, rgb: np.ndarray, depth_m: np.ndarray, world_from_cam: np.ndarray,
              extras: dict) -> ImageFeatures:
    """SIFT lifted by ``depth_m`` (metres, 0 = none) and the detected tags of one image."""
    imaging = worker.spec.imaging
    kp, desc = extract_sift(rgb, imaging.sift)
    pts, valid = lift_to_3d(kp, depth_m, worker.K, world_from_cam, max_depth=imaging.max_depth,
                            image_size=(rgb.shape[1], rgb.shape[0]))
    pts = np.where(valid[:, None], pts, np.nan)
    dets = detect_tags(rgb)
    ids = np.array([d.tag_id for d in dets], dtype=np.int32)
    corners = np.array([np.asarray(d.corners, np.float32).reshape(4, 2) for d in dets], np.float32).reshape(-1, 4, 2)
    return ImageFeatures(kp.astype(np.float32), np.clip(np.rint(desc), 0, 255).astype(np.uint8),
                         pts.astype(np.float32), ids, corners, extras)


def real_image(worker: FrameWorker, frame: int, markers: Sequence[Marker]) -> tuple[np.ndarray, np.ndarray, list]:
    """The photograph of frame ``frame`` with ``markers`` composited in: (rgb (H, W, 3) uint8,
    depth (H, W) metres, per-marker :class:`~markerplace.imaging.composite.CompositeStats`)."""
    fs = worker.spec.frames
    rec = fs.frames[frame]
    rgb, depth = load_frame(fs, rec)
    depth_m = depth.astype(np.float64) / fs.depth_scale
    stats: list = []
    if markers:
        rng = np.random.default_rng(_noise_seed(worker.spec.seed, frame, markers))
        rgb, stats = composite_tags(rgb, depth_m, worker.K, rec.world_from_cam, list(markers),
                                    worker.spec.composite, rng)
    return rgb, depth_m, stats


def image_task(worker: FrameWorker, item) -> ImageFeatures:
    """(kind, frame index, markers) -> the image's features (:func:`_features`); a ``real``
    image's ``extras`` hold ``visible_px`` (M,), the tag pixels left visible per marker, and
    ``hidden_px`` / ``hole_px``, those hidden by nearer depth / over depth holes."""
    kind, frame, markers = item
    world_from_cam = worker.spec.frames.frames[frame].world_from_cam
    if kind == RENDER:
        res = worker.engine.render(world_from_cam, list(markers))
        return _features(worker, res.rgb, res.depth, world_from_cam, {})
    rgb, depth_m, stats = real_image(worker, frame, markers)
    extras = {"visible_px": np.array([s.covered_px - s.hidden_px for s in stats], np.int64).reshape(-1),
              "hidden_px": np.array([s.hidden_px for s in stats], np.int64).reshape(-1),
              "hole_px": np.array([s.hole_px for s in stats], np.int64).reshape(-1)}
    return _features(worker, rgb, depth_m, world_from_cam, extras)


def frame_in_view(world_from_cam: np.ndarray, K: np.ndarray, size: tuple[int, int], markers: Sequence[Marker],
                  margin_px: float = 16.0) -> np.ndarray:
    """(M,) bool: some point of a marker's drawn quad (quiet zone included) projects in front
    of the camera within ``margin_px`` of the (width, height) image: the marker may change the
    image (conservative: occlusion is not tested, so a hidden tag still counts)."""
    if not markers:
        return np.zeros(0, bool)
    samples = marker_points(np.array([m.world_from_marker for m in markers]), [m.size for m in markers], grid=7)
    no_depth = np.zeros((int(size[1]), int(size[0])))
    return markers_in_view(no_depth, world_from_cam, K, samples, margin_px, 0.0)
