"""Observation stage: render RGB-D at every feasible pose, extract SIFT, lift keypoints to 3D.

Output (one HDF5 file, concatenated arrays with per-pose offsets):

* ``keypoints`` (P, 2) float32 pixel xy; ``descriptors`` (P, 128) uint8 (OpenCV SIFT values are
  integers in 0..255); ``points_world`` (P, 3) float32 world metres; ``pose_index`` (P,) int32.
* ``offsets`` (N + 1,) int64: features of pose i are rows ``offsets[i]:offsets[i+1]``.
* ``candidate_unoccluded`` (N, C) bool: the centre and corners of candidate marker c are not
  hidden behind other geometry in the depth rendered at pose i (only meaningful where the
  marker is in the field of view; see :func:`marker_occlusion_free`).

Rendering and feature extraction are spread over a process pool, one GL context per worker.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from ..geometry import Intrinsics, project_with_depth_lookup
from ..io_utils import atomic_path
from ..localization.features import SIFT_SCORING, SiftConfig, extract_sift, lift_to_3d
from ..runtime.workers import default_workers, single_threaded_libraries, spawn_pool

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SceneSpec:
    """How a worker process rebuilds the scene: ``load_scene(spec, up, unit_scale, seed)``."""

    spec: str
    up: str | None = None
    unit_scale: float | None = None
    seed: int = 0

    def load(self):
        from ..scene import load_scene

        return load_scene(self.spec, up=self.up, unit_scale=self.unit_scale, seed=self.seed)


@dataclass(frozen=True)
class ObserveConfig:
    """Observation settings.

    Attributes:
        intrinsics: camera model of the renders (paper: 600x450, 90 deg HFOV).
        sift: SIFT parameters (paper's scoring preset: 1000 features, contrast 0.1, edge 5).
        max_depth: features farther than this (metres) are dropped.
        occlusion_tolerance: a marker sample point counts as visible when the rendered depth
            there is at least (marker depth - tolerance), metres.
        workers: processes for rendering + SIFT (0 = number of CPUs, capped at 4).
    """

    intrinsics: Intrinsics = field(default_factory=Intrinsics)
    sift: SiftConfig = SIFT_SCORING
    max_depth: float = 10.0
    occlusion_tolerance: float = 0.10
    workers: int = 0


@dataclass(frozen=True, eq=False)
class Observations:
    """Features of all poses; see the module docstring for shapes."""

    keypoints: np.ndarray
    descriptors: np.ndarray
    points_world: np.ndarray
    pose_index: np.ndarray
    offsets: np.ndarray
    candidate_unoccluded: np.ndarray

    @property
    def num_poses(self) -> int:
        return len(self.offsets) - 1

    def save(self, path: str | Path) -> None:
        """Write to HDF5 atomically."""
        with atomic_path(path) as tmp:
            with h5py.File(tmp, "w") as f:
                for name in ("keypoints", "descriptors", "points_world", "pose_index", "offsets", "candidate_unoccluded"):
                    arr = getattr(self, name)
                    f.create_dataset(name, data=arr, compression="lzf" if arr.size > 4096 else None)

    @classmethod
    def load(cls, path: str | Path) -> "Observations":
        with h5py.File(path, "r") as f:
            return cls(**{k: f[k][()] for k in ("keypoints", "descriptors", "points_world", "pose_index", "offsets", "candidate_unoccluded")})


def marker_sample_points(candidate_world_from_marker: np.ndarray, sizes) -> np.ndarray:
    """(C, 5, 3) world points per candidate: tag centre and the 4 black-square corners.

    ``sizes``: black-square edge in metres, one per candidate (C,) or one for all.
    """
    C = len(candidate_world_from_marker)
    h = np.broadcast_to(np.asarray(sizes, dtype=float), (C,)) / 2.0
    unit = np.array([[0, 0, 0], [-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]], dtype=float)
    local = unit[None, :, :] * h[:, None, None]
    R = candidate_world_from_marker[:, :3, :3]
    t = candidate_world_from_marker[:, :3, 3]
    return np.einsum("cij,ckj->cki", R, local) + t[:, None, :]


def marker_occlusion_free(depth: np.ndarray, world_from_cam: np.ndarray, K: np.ndarray,
                          samples_world: np.ndarray, tolerance: float) -> np.ndarray:
    """Which candidates are not hidden at this pose.

    Args:
        depth: (H, W) planar depth rendered WITHOUT markers, metres.
        world_from_cam: (4, 4) pose of the render.
        K: (3, 3) intrinsics.
        samples_world: (C, S, 3) sample points per candidate (centre + corners).
        tolerance: metres of slack between rendered depth and the sample's depth.

    Returns:
        (C,) bool: True when every sample projects inside the image, in front of the camera,
        and the rendered surface there is not closer than the sample (minus ``tolerance``).
    """
    H, W = depth.shape
    C, S, _ = samples_world.shape
    uv, z, surface = project_with_depth_lookup(depth, world_from_cam, K, samples_world.reshape(-1, 3))
    ui, vi = np.round(uv[:, 0]), np.round(uv[:, 1])
    inside = (z > 1e-3) & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
    ok = inside & ((surface == 0) | (surface >= z - tolerance))
    return ok.reshape(C, S).all(axis=1)


# --- worker side -------------------------------------------------------------------------------

_WORKER: dict = {}


def _worker_init(scene_spec: SceneSpec, config: ObserveConfig, samples_world: np.ndarray) -> None:
    from ..render.renderer import Renderer

    scene = scene_spec.load()
    _WORKER["renderer"] = Renderer(scene, config.intrinsics)
    _WORKER["config"] = config
    _WORKER["samples"] = samples_world


def _pool_worker_init(*args) -> None:
    single_threaded_libraries()
    _worker_init(*args)


def _observe_one(args: tuple[int, np.ndarray, np.ndarray]):
    index, world_from_cam, candidate_mask = args
    renderer = _WORKER["renderer"]
    config: ObserveConfig = _WORKER["config"]
    K = config.intrinsics.K
    result = renderer.render(world_from_cam, rgb=True, depth=True, normal=False)
    kp, desc = extract_sift(result.rgb, config.sift)
    pts, valid = lift_to_3d(kp, result.depth, K, world_from_cam, max_depth=config.max_depth)
    unoccluded = np.zeros(len(candidate_mask), dtype=bool)
    if candidate_mask.any():
        samples = _WORKER["samples"][candidate_mask]
        unoccluded[candidate_mask] = marker_occlusion_free(result.depth, world_from_cam, K, samples, config.occlusion_tolerance)
    return (index, kp[valid].astype(np.float32), np.clip(np.rint(desc[valid]), 0, 255).astype(np.uint8),
            pts[valid].astype(np.float32), unoccluded)


def observe(scene_spec: SceneSpec, world_from_cam: np.ndarray, candidate_in_view: np.ndarray,
            candidate_world_from_marker: np.ndarray, tag_sizes, config: ObserveConfig,
            progress: bool = True) -> Observations:
    """Render and extract features at every pose.

    Args:
        scene_spec: how to (re)load the scene in each worker.
        world_from_cam: (N, 4, 4) feasible camera poses.
        candidate_in_view: (N, C) bool, candidates geometrically visible from each pose
            (range, FOV, viewing angle); only those are checked for occlusion.
        candidate_world_from_marker: (C, 4, 4) candidate marker poses.
        tag_sizes: black-square edge in metres, (C,) or one for all (for the corner samples).
        config: observation settings.
        progress: show a progress bar.
    """
    from tqdm import tqdm

    N = len(world_from_cam)
    C = len(candidate_world_from_marker)
    samples = marker_sample_points(candidate_world_from_marker, tag_sizes) if C else np.zeros((0, 5, 3))
    workers = default_workers(config.workers)
    jobs = [(i, world_from_cam[i], candidate_in_view[i] if C else np.zeros(0, bool)) for i in range(N)]
    results: list = [None] * N
    bar = tqdm(total=N, desc="observe", unit="pose", disable=not progress, leave=False)
    if workers <= 1:
        _worker_init(scene_spec, config, samples)
        try:
            for job in jobs:
                r = _observe_one(job)
                results[r[0]] = r
                bar.update()
        finally:
            _WORKER.pop("renderer").close()
    else:
        with spawn_pool(workers, _pool_worker_init, (scene_spec, config, samples)) as pool:
            for r in pool.imap_unordered(_observe_one, jobs, chunksize=8):
                results[r[0]] = r
                bar.update()
    bar.close()
    counts = np.array([len(r[1]) for r in results], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    return Observations(
        keypoints=np.concatenate([r[1] for r in results]) if N else np.zeros((0, 2), np.float32),
        descriptors=np.concatenate([r[2] for r in results]) if N else np.zeros((0, 128), np.uint8),
        points_world=np.concatenate([r[3] for r in results]) if N else np.zeros((0, 3), np.float32),
        pose_index=np.repeat(np.arange(N, dtype=np.int32), counts),
        offsets=offsets,
        candidate_unoccluded=np.stack([r[4] for r in results]) if N else np.zeros((0, C), bool),
    )
