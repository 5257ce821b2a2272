"""TSDF fusion of posed RGB-D frames into a vertex-coloured triangle mesh (marching cubes).

The method is the paper's (they fused their room with Open3D's scalable TSDF volume): a truncated
signed distance function on a sparse grid of voxel blocks allocated around the observed surface,
each frame averaged in with weight 1 (Curless & Levoy 1996; voxel hashing, Niessner et al. 2013),
RGB8 colour averaged the same way, and the zero level set extracted by marching cubes.

Implementation note: Open3D's legacy ``open3d.pipelines.integration.ScalableTSDFVolume`` integrates
nothing in the installed open3d-cpu 0.20.0 (every frame leaves the volume empty; 0.19.0 works on
the same input), so this module uses its successor in the same library,
``open3d.t.geometry.VoxelBlockGrid`` (hashed 8^3 voxel blocks, the same TSDF update and marching
cubes), which gives the same kind of mesh on 0.18-0.20.

Frames: poses are ``world_from_cam`` (OpenCV camera x right, y down, z forward); the mesh is in
the poses' world frame, metres. Depth images are planar, uint16 in ``depth_scale`` units per metre.
Each frame may have its own pinhole camera (``TSDFFusion.integrate(..., intrinsics=)``).

:func:`refine_up`: when the frame set's up axis was only estimated from the cameras, the fused
mesh's floors and table tops (:func:`~markerplace.scan.up.estimate_up_from_mesh`) refine it.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics, invert
from markerplace.progress import track
from markerplace.runtime.atomic_io import atomic_path
from markerplace.runtime.heap import keep_freed_memory
from markerplace.scan.frame_images import load_frame
from markerplace.scan.frameset import FrameSet, frame_intrinsics
from markerplace.scan.up import MESH_REFINE_DEG, UP_SOURCE_CAMERAS, angle_deg, estimate_up_from_mesh, world_from_input

log = logging.getLogger(__name__)

READ_AHEAD = 4
"""Frames :func:`read_ahead` decodes ahead of the one being integrated."""


@dataclass(frozen=True)
class FuseConfig:
    """TSDF fusion settings.

    Attributes:
        voxel: voxel edge, metres (default 0.02).
        trunc_voxels: truncation distance of the TSDF as a multiple of ``voxel`` (default 4,
            i.e. 8 cm at the default voxel); used when ``trunc_m`` is None.
        trunc_m: truncation distance in metres (overrides ``trunc_voxels``).
        depth_max: depth readings beyond this (metres) are ignored (default 4.0; the noise of
            structured-light and time-of-flight sensors grows with the square of depth).
        every: use every N-th frame (default 1 = all).
        min_observations: marching cubes only where at least this many frames observed the
            voxel (default 1: everything observed; Open3D's own default, for 30 Hz video, is
            more than 3).
        block_resolution: voxels per block edge of the sparse grid (default 8).
    """

    voxel: float = 0.02
    trunc_voxels: float = 4.0
    trunc_m: float | None = None
    depth_max: float = 4.0
    every: int = 1
    min_observations: int = 1
    block_resolution: int = 8

    @property
    def trunc_multiplier(self) -> float:
        """Truncation distance in voxels."""
        return float(self.trunc_m / self.voxel) if self.trunc_m is not None else float(self.trunc_voxels)

    def validate(self) -> None:
        """Raise :class:`UserError` for settings that cannot work."""
        if not (np.isfinite(self.voxel) and 0.001 <= self.voxel <= 1.0):
            raise UserError(f"--voxel {self.voxel:g} must be between 0.001 and 1 metre")
        t = self.trunc_multiplier
        if not (np.isfinite(t) and 1.0 <= t <= 100.0):
            raise UserError(f"--trunc gives {t:g} voxels; it must be 1 to 100 voxels (e.g. 4x, or metres >= --voxel)")
        if not (np.isfinite(self.depth_max) and self.depth_max > 0):
            raise UserError(f"--depth-max {self.depth_max:g} must be a positive number of metres")
        if int(self.every) != self.every or self.every < 1:
            raise UserError(f"--every {self.every} must be a positive integer")
        if int(self.min_observations) != self.min_observations or self.min_observations < 1:
            raise UserError(f"minimum observations {self.min_observations} must be a positive integer")


def parse_trunc(text: str) -> tuple[float | None, float]:
    """``--trunc`` value -> (``trunc_m``, ``trunc_voxels``).

    ``"0.08"`` is metres; ``"4x"`` (or ``"4vox"``) is 4 voxels.
    """
    s = str(text).strip().lower()
    try:
        for suffix in ("voxels", "voxel", "vox", "x"):
            if s.endswith(suffix):
                v = float(s[: -len(suffix)])
                if not (np.isfinite(v) and v > 0):
                    raise ValueError
                return None, v
        v = float(s)
        if not (np.isfinite(v) and v > 0):
            raise ValueError
        return v, FuseConfig.trunc_voxels
    except ValueError:
        raise UserError(f"--trunc {text!r}: give metres (e.g. 0.08) or a multiple of the voxel (e.g. 4x)") from None


class TSDFFusion:
    """A sparse TSDF volume with RGB colour, fed one frame at a time.

    Args:
        intrinsics: camera model of every frame (pixels).
        config: fusion settings.
    """

    def __init__(self, intrinsics: Intrinsics, config: FuseConfig = FuseConfig()):
        import open3d as o3d

        config.validate()
        self._o3d = o3d
        self.config = config
        self.intrinsics = intrinsics
        self._K = self._o3d_K(intrinsics)
        self._grid = o3d.t.geometry.VoxelBlockGrid(
            attr_names=("tsdf", "weight", "color"),
            attr_dtypes=(o3d.core.float32, o3d.core.float32, o3d.core.float32),
            attr_channels=((1), (1), (3)),
            voxel_size=float(config.voxel),
            block_resolution=int(config.block_resolution),
            block_count=4096,
            device=o3d.core.Device("CPU:0"),
        )
        self.frames = 0

    def _o3d_K(self, intrinsics: Intrinsics):
        # Open3D reads the depth pixel int(u) of a voxel's projection u (pixel i spans [i, i + 1));
        # ours has pixel centres at integers (OpenCV). Shifting the principal point by half a
        # pixel makes int(u + 0.5) the nearest pixel; without it, slanted surfaces move by half
        # a pixel's depth change (about 9 mm on a 45 deg wall 2 m away at 100 px focal length).
        K = np.asarray(intrinsics.K, dtype=np.float64).copy()
        K[0, 2] += 0.5
        K[1, 2] += 0.5
        return self._o3d.core.Tensor(K)

    def integrate(self, rgb: np.ndarray, depth: np.ndarray, depth_scale: float, world_from_cam: np.ndarray,
                  intrinsics: Intrinsics | None = None) -> bool:
        """Fuse one frame.

        Args:
            rgb: (H, W, 3) uint8 colour registered to the depth image.
            depth: (H, W) uint16 planar depth, ``depth_scale`` units per metre, 0 = no reading.
            depth_scale: depth units per metre (1000 for millimetres).
            world_from_cam: (4, 4) camera pose.
            intrinsics: this frame's pinhole camera; None = the one given to the constructor.

        Returns:
            False when the frame has no depth reading within ``depth_max`` (nothing fused).
        """
        o3d = self._o3d
        if intrinsics is None or intrinsics == self.intrinsics:
            intrinsics, K = self.intrinsics, self._K
        else:
            K = self._o3d_K(intrinsics)
        H, W = intrinsics.height, intrinsics.width
        if depth.shape != (H, W) or rgb.shape[:2] != (H, W):
            raise ValueError(f"frame of {depth.shape} / {rgb.shape} does not match the intrinsics {W}x{H}")
        limit = self.config.depth_max * depth_scale
        if not np.any((depth > 0) & (depth <= limit)):
            return False
        dep = o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(depth, dtype=np.uint16)))
        col = o3d.t.geometry.Image(o3d.core.Tensor(np.ascontiguousarray(rgb, dtype=np.uint8)))
        ext = o3d.core.Tensor(invert(np.asarray(world_from_cam, dtype=np.float64)))
        mult = self.config.trunc_multiplier
        try:
            blocks = self._grid.compute_unique_block_coordinates(dep, K, ext, float(depth_scale),
                                                                 float(self.config.depth_max), mult)
        except RuntimeError as err:  # Open3D samples the depth image: a few far readings may touch no block
            if "No block is touched" not in str(err):
                raise
            return False
        self._grid.integrate(blocks, dep, col, K, ext, float(depth_scale), float(self.config.depth_max), mult)
        self.frames += 1
        return True

    def extract_mesh(self):
        """Marching cubes on the fused volume.

        Returns:
            an ``open3d.geometry.TriangleMesh`` (legacy) with vertex colours in [0, 1] and vertex
            normals, in canonical order (vertices sorted by position, faces sorted), so equal
            inputs give byte-identical files whatever the thread scheduling.
        """
        o3d = self._o3d
        if self.frames == 0:
            return o3d.geometry.TriangleMesh()
        # Open3D keeps voxels with weight > threshold; each frame adds weight 1
        threshold = float(self.config.min_observations) - 0.5
        mesh = self._grid.extract_triangle_mesh(weight_threshold=threshold).to_legacy()
        return canonical_mesh(mesh)


def canonical_mesh(mesh):
    """The same legacy Open3D mesh with vertices sorted by (x, y, z) and faces sorted (deterministic output)."""
    import open3d as o3d

    V = np.asarray(mesh.vertices)
    F = np.asarray(mesh.triangles)
    if len(V) == 0 or len(F) == 0:
        return o3d.geometry.TriangleMesh()
    order = np.lexsort((V[:, 2], V[:, 1], V[:, 0]))
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    F2 = rank[F]
    # rotate each face so its smallest index comes first (keeps the winding), then sort faces
    k = np.argmin(F2, axis=1)
    idx = (k[:, None] + np.arange(3)[None, :]) % 3
    F2 = np.take_along_axis(F2, idx, axis=1)
    F2 = F2[np.lexsort((F2[:, 2], F2[:, 1], F2[:, 0]))]
    out = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(V[order]), o3d.utility.Vector3iVector(F2.astype(np.int32)))
    if mesh.has_vertex_colors():
        out.vertex_colors = o3d.utility.Vector3dVector(np.asarray(mesh.vertex_colors)[order])
    if mesh.has_vertex_normals():
        out.vertex_normals = o3d.utility.Vector3dVector(np.asarray(mesh.vertex_normals)[order])
    return out


def read_ahead(fs, records, ahead: int = READ_AHEAD):
    """Yield :func:`~markerplace.scan.frames.load_frame` of each record in order, reading up to
    ``ahead`` frames ahead on one thread (decoding releases the GIL, so reading overlaps the
    integration; the frames and their order are those of a plain loop)."""
    records = list(records)
    with ThreadPoolExecutor(1) as pool:
        pending = deque(pool.submit(load_frame, fs, rec) for rec in records[:ahead])
        for nxt in records[ahead:] + [None] * min(ahead, len(records)):
            frame = pending.popleft().result()
            if nxt is not None:
                pending.append(pool.submit(load_frame, fs, nxt))
            yield frame


def fuse_frameset(fs, config: FuseConfig = FuseConfig(), progress: bool = True):
    """Fuse every ``config.every``-th frame of a :class:`~markerplace.scan.frameset.FrameSet`.

    Returns:
        the legacy Open3D mesh of :meth:`TSDFFusion.extract_mesh`.

    Raises:
        UserError: a bad image (see :func:`~markerplace.scan.frame_images.load_frame`), or no surface.
    """
    config.validate()
    frames = fs.frames[:: int(config.every)]
    no_depth = sum(rec.depth_path is None for rec in frames)
    if no_depth == len(frames):
        raise UserError(f"{fs.root}: no depth images ({fs.format} layout{': no frame has a depth_file_path' if fs.format == 'nerfstudio' else ''}); "
                        "fusion needs depth")
    if no_depth:
        log.warning("%d of %d frames have no depth image and are skipped", no_depth, len(frames))
    keep_freed_memory()  # decoded frames reuse the heap (markerplace.runtime.heap)
    fusion = TSDFFusion(fs.intrinsics, config)
    t0 = time.perf_counter()
    empty = 0
    with_depth = [rec for rec in frames if rec.depth_path is not None]
    for rec, (rgb, depth) in zip(track(with_depth, "fuse", "frame", progress), read_ahead(fs, with_depth)):
        if not fusion.integrate(rgb, depth, fs.depth_scale, rec.world_from_cam, frame_intrinsics(fs, rec)):
            empty += 1
    if empty == len(frames) - no_depth:
        raise UserError(f"{fs.root}: no frame has a depth reading within --depth-max {config.depth_max:g} m; "
                        f"check the depth scale ({fs.depth_scale:g} units per metre)")
    if empty:
        log.warning("%d of %d frames have no depth reading within %.2f m", empty, len(frames), config.depth_max)
    mesh = fusion.extract_mesh()
    log.info("fused %d frames (%s layout, every %d) at %.3f m voxels, truncation %.3f m in %.1f s: %d vertices, %d faces",
             fusion.frames, fs.format, config.every, config.voxel, config.trunc_multiplier * config.voxel,
             time.perf_counter() - t0, len(mesh.vertices), len(mesh.triangles))
    if len(mesh.triangles) == 0:
        raise UserError(f"{fs.root}: fusion produced no surface; check the depth scale "
                        f"({fs.depth_scale:g} units per metre), --depth-max and the poses")
    return mesh


def refine_up(fs: FrameSet, mesh):
    """Refine an up axis estimated from the cameras with the fused mesh's floors and table tops.

    Only when ``fs.up_source`` is the camera estimate, and only when the mesh estimate
    (:func:`~markerplace.scan.up.estimate_up_from_mesh` around +z) is within
    :data:`~markerplace.scan.up.MESH_REFINE_DEG` of it; logged either way.

    Returns:
        (frame set, mesh): both turned by the minimal rotation taking the mesh's up to +z
        (``world_from_input`` and ``up_source`` updated), or the inputs unchanged.
    """
    import open3d as o3d

    if fs.up_source != UP_SOURCE_CAMERAS or len(mesh.triangles) == 0:
        return fs, mesh
    if not mesh.has_vertex_normals():
        mesh.compute_vertex_normals()
    up = estimate_up_from_mesh(np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals))
    if up is None:
        log.info("up axis: too few upward-facing surfaces in the mesh to refine the cameras' estimate")
        return fs, mesh
    tilt = angle_deg(up, [0.0, 0.0, 1.0])
    if tilt > MESH_REFINE_DEG:
        log.warning("up axis: the mesh's floors/table tops are %.1f deg from the cameras' estimate (over %.0f deg): "
                    "estimate kept; give --up if the floor is not level", tilt, MESH_REFINE_DEG)
        return fs, mesh
    T = world_from_input(up)
    out = o3d.geometry.TriangleMesh(mesh)
    out.rotate(T[:3, :3], center=(0.0, 0.0, 0.0))
    frames = tuple(replace(r, world_from_cam=T @ r.world_from_cam) for r in fs.frames)
    source = f"{UP_SOURCE_CAMERAS}, refined by the mesh's horizontal surfaces"
    log.info("up axis refined by the mesh's floors/table tops: turned %.2f deg", tilt)
    return replace(fs, frames=frames, up_source=source, world_from_input=T @ fs.world_from_input), canonical_mesh(out)


def write_mesh_ply(mesh, path: str | Path) -> None:
    """Write a legacy Open3D mesh as binary PLY with vertex colours (uchar) and normals, atomically."""
    import open3d as o3d

    path = Path(path)
    with atomic_path(path) as tmp:
        ok = o3d.io.write_triangle_mesh(str(tmp), mesh, write_ascii=False, compressed=False,
                                        write_vertex_normals=mesh.has_vertex_normals(),
                                        write_vertex_colors=mesh.has_vertex_colors(), write_triangle_uvs=False)
        if not ok or tmp.stat().st_size == 0:
            raise UserError(f"cannot write {path}")
