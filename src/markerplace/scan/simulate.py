"""Simulated RGB-D scan of a built-in scene: the frame simulator and the whole scan (walk,
noisy frames, TSDF fusion). The result looks like a real scan: holes, noise, vertex colours, no
texture.

* the walk (positions, doorways, headings): :mod:`markerplace.scan.walk`;
* the depth-sensor noise model: :mod:`markerplace.scan.depth_noise`;
* here: :class:`ScanConfig` (camera, walk, noise, fusion), :class:`FrameSimulator` (renders one
  noisy RGB-D frame at a ``world_from_cam`` pose: colour (H, W, 3) uint8 and planar depth (H, W)
  uint16 millimetres), :func:`simulate_scan` (walk, frames, fusion into a mesh in the scene's
  world frame, z up, metres) and :func:`distance_to_scene` (metres, for checking a scan).

The colour image is the renderer's, registered to the depth. Frames can be kept on disk in the
markerplace layout (:mod:`markerplace.scan.frames`), so ``markerplace fuse`` reproduces the mesh.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.progress import track
from markerplace.render.renderer import Renderer
from markerplace.scan.depth_noise import DEPTH_SCALE, DepthNoiseConfig, camera_rays, noisy_depth, to_depth_png
from markerplace.scan.frames import FrameWriter
from markerplace.scan.fuse import FuseConfig, TSDFFusion
from markerplace.scan.walk import WalkConfig, plan_walk, seeded_rng
from markerplace.scene.types import Scene

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ScanConfig:
    """A simulated scan: camera, walk, noise and fusion.

    Attributes:
        width, height, fx, fy: rendered image size and focal lengths, pixels (default 320x240,
            262.5: a Kinect v1 at half resolution); the principal point is the image centre.
        walk: where the scanner goes.
        noise: the depth sensor model.
        fuse: TSDF settings (default 0.04 m voxels, truncation 2.5 voxels = 10 cm, depth up to
            4 m: about 0.6 million faces for the 112 m^2 office). A truncation wider than the
            0.1 m walls lets the two sides of a wall pull each other's surface off (4x gave
            10 % of the vertices more than 4 cm off; 2.5x gives 1.3 %).
    """

    width: int = 320
    height: int = 240
    fx: float = 262.5
    fy: float = 262.5
    walk: WalkConfig = WalkConfig()
    noise: DepthNoiseConfig = DepthNoiseConfig()
    fuse: FuseConfig = FuseConfig(voxel=0.04, trunc_voxels=2.5)

    @property
    def intrinsics(self) -> Intrinsics:
        """Camera model; pixel centres at integer coordinates, principal point at the centre."""
        return Intrinsics(self.width, self.height, self.fx, self.fy, (self.width - 1) / 2.0, (self.height - 1) / 2.0)



@dataclass(frozen=True)
class ScanResult:
    """Outcome of :func:`simulate_scan`.

    Attributes:
        mesh: legacy ``open3d.geometry.TriangleMesh`` (world frame, vertex colours, normals).
        world_from_cam: (N, 4, 4) poses of the frames, in walk order.
        positions: (P, 3) walk positions, metres.
        doorways: (D, 3) doorway centres found, metres.
        valid_fraction: mean fraction of pixels with a depth reading after the noise model.
        seconds: wall-clock time of the whole scan.
    """

    mesh: object
    world_from_cam: np.ndarray
    positions: np.ndarray
    doorways: np.ndarray
    valid_fraction: float
    seconds: float
    stats: dict = field(default_factory=dict)



def _glass_scene(scene: Scene) -> Scene | None:
    """The transparent parts alone, made opaque so they write depth (None when there are none)."""
    parts = tuple(dataclasses.replace(p, transparent=False) for p in scene.parts if p.transparent and len(p.faces))
    if not parts:
        return None
    return Scene(name=f"{scene.name}/glass", parts=parts, rooms=scene.rooms, floor_z=scene.floor_z, source=scene.source)



class FrameSimulator:
    """Renders noisy RGB-D frames of one scene (one GL context; two when the scene has glass).

    Use as a context manager or call :meth:`close`.

    Args:
        scene: the scene (world z up, metres).
        config: camera and noise settings (``config.walk`` and ``config.fuse`` are not used).
    """

    def __init__(self, scene: Scene, config: ScanConfig = ScanConfig()):
        self.config = config
        self.intrinsics = config.intrinsics
        self._rays = camera_rays(self.intrinsics)
        glass_scene = _glass_scene(scene) if config.noise.glass_dropout else None
        if glass_scene is not None:
            log.info("scan: %d transparent parts give no depth where they are the first surface", len(glass_scene.parts))
        self._renderer = Renderer(scene, self.intrinsics)
        self._glass = None
        try:
            self._glass = Renderer(glass_scene, self.intrinsics) if glass_scene is not None else None
        except Exception:
            self._renderer.close()
            raise

    def frame(self, world_from_cam: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One frame at a (4, 4) ``world_from_cam``.

        Returns:
            rgb (H, W, 3) uint8 and depth (H, W) uint16 millimetres (0 = no reading), planar.
        """
        # two GL contexts live in this process when there is glass: make each current before use
        # (a Renderer draws into whichever context is current)
        with self._renderer.ctx:
            res = self._renderer.render(world_from_cam)
        glass = None
        if self._glass is not None:
            # the renderer's depth is what lies behind glass; glass is the first surface where
            # the glass-only depth is nearer than that (or nothing lies behind it)
            with self._glass.ctx:
                dg = self._glass.render(world_from_cam, rgb=False, normal=False).depth
            glass = (dg > 0) & ((res.depth == 0) | (dg < res.depth + 1e-3))
        d = noisy_depth(res.depth, res.normal, self.intrinsics, world_from_cam, rng, self.config.noise, glass, self._rays)
        return res.rgb, to_depth_png(d, DEPTH_SCALE)

    def close(self) -> None:
        """Release the GL contexts."""
        self._renderer.close()
        if self._glass is not None:
            self._glass.close()

    def __enter__(self) -> "FrameSimulator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def simulate_scan(scene: Scene, config: ScanConfig = ScanConfig(), seed: int = 0,
                  keep_frames: str | Path | None = None, progress: bool = True) -> ScanResult:
    """Walk through ``scene``, render noisy RGB-D frames and fuse them into a mesh.

    Args:
        scene: a scene with rooms (built-in).
        config: camera, walk, noise and fusion settings.
        seed: seeds the walk and every frame's noise (frame i uses its own stream), so the
            result does not depend on anything else.
        keep_frames: folder to write the frames to in the markerplace layout, or None.
        progress: show a progress bar.

    Returns:
        :class:`ScanResult`.
    """
    t0 = time.perf_counter()
    config.fuse.validate()
    intr = config.intrinsics
    poses, positions, doorways = plan_walk(scene, config.walk, seed)
    fusion = TSDFFusion(intr, config.fuse)
    writer = FrameWriter(keep_frames, intr, DEPTH_SCALE) if keep_frames is not None else None
    valid_sum = 0.0
    try:
        with FrameSimulator(scene, config) as sim:
            for i, T in enumerate(track(poses, "scan", "frame", progress)):
                rgb, d16 = sim.frame(T, seeded_rng(seed, 2, i))
                valid_sum += float(np.count_nonzero(d16)) / d16.size
                fusion.integrate(rgb, d16, DEPTH_SCALE, T)
                if writer is not None:
                    writer.write(f"{i:06d}", rgb, d16, T)
    finally:
        if writer is not None:
            writer.close()
    mesh = fusion.extract_mesh()
    seconds = time.perf_counter() - t0
    stats = {"frames": len(poses), "positions": len(positions), "doorways": len(doorways),
             "faces": len(mesh.triangles), "vertices": len(mesh.vertices), "seconds": round(seconds, 2)}
    log.info("scan: %d frames fused at %.3f m voxels in %.1f s: %d vertices, %d faces; %.0f %% of pixels had depth",
             len(poses), config.fuse.voxel, seconds, len(mesh.vertices), len(mesh.triangles),
             100.0 * valid_sum / max(len(poses), 1))
    if len(mesh.triangles) == 0:
        raise UserError(f"scene {scene.name!r}: the simulated scan produced no surface")
    return ScanResult(mesh, poses, positions, doorways, valid_sum / max(len(poses), 1), seconds, stats)


def distance_to_scene(points: np.ndarray, scene: Scene) -> np.ndarray:
    """(N,) unsigned distance (metres) from each of (N, 3) points to the scene's triangles.

    Open3D's ``RaycastingScene.compute_distance`` on the mesh recentred in float64 first (the
    same float32 precaution as :class:`markerplace.scene.raycast.RayCaster`).
    """
    import open3d as o3d

    V, F = scene.geometry()
    centre = 0.5 * (V.min(axis=0) + V.max(axis=0))
    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(o3d.core.Tensor((V - centre).astype(np.float32)), o3d.core.Tensor(F.astype(np.uint32)))
    q = o3d.core.Tensor((np.asarray(points, dtype=np.float64).reshape(-1, 3) - centre).astype(np.float32))
    return rs.compute_distance(q).numpy().astype(np.float64)


__all__ = ["ScanConfig", "ScanResult", "FrameSimulator", "simulate_scan", "distance_to_scene"]
