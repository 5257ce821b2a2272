"""The surface a frames plan puts tags on: fused from the chosen frames (TSDF,
:func:`markerplace.scan.fuse.fuse_frameset`), cached in the run folder as ``fused.ply`` under
the hash of the frames (names, image paths, poses, camera, depth scale) and the fusion
settings; or the mesh the user gives (``--mesh``).

Fusion uses :data:`FUSE` (2.5 cm voxels, truncation 3 voxels, depth up to 4 m): fine enough that
a tag's 7 x 7 flatness samples (:func:`~markerplace.plan.discretize.candidate_rules.tag_fits`)
see a wall's own surface, coarse enough to fuse a few hundred frames in seconds.
"""

from __future__ import annotations

import logging
from dataclasses import replace
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.runtime import cache
from markerplace.runtime.stages import cached
from markerplace.scan.fuse import FuseConfig, fuse_frameset, write_mesh_ply

log = logging.getLogger(__name__)

__all__ = ["FUSE", "FUSED_NAME", "frames_key", "surface_path"]

FUSE = FuseConfig(voxel=0.025, trunc_voxels=3.0, depth_max=4.0)
"""TSDF settings of the fused surface."""

FUSED_NAME = "fused.ply"


def frames_key(fs, indices: np.ndarray) -> str:
    """Hash of what the chosen frames are: layout, camera, depth scale and each frame's name,
    image paths and pose."""
    recs = [fs.frames[int(i)] for i in indices]
    return cache.hash_of("frames-v1", fs.format, fs.intrinsics, float(fs.depth_scale),
                         [(r.name, str(r.color_path), str(r.depth_path)) for r in recs],
                         np.array([r.world_from_cam for r in recs], float))


def surface_path(fs, indices: np.ndarray, run_dir: Path, mesh: str | Path | None, timings: dict,
                 progress: bool = True) -> Path:
    """The surface's mesh file: ``mesh`` when given (checked to exist), else ``run_dir/fused.ply``
    fused from the frames ``indices`` (reused while the frames and :data:`FUSE` are unchanged)."""
    if mesh is not None:
        path = Path(mesh)
        if not path.is_file():
            raise UserError(f"--mesh {mesh}: file not found")
        return path
    key = cache.hash_of("fused-v1", frames_key(fs, indices), FUSE)
    path = Path(run_dir) / FUSED_NAME

    def compute() -> Path:
        chosen = replace(fs, frames=tuple(fs.frames[int(i)] for i in indices))
        mesh_ = fuse_frameset(chosen, FUSE, progress)
        write_mesh_ply(mesh_, path)
        return path

    return cached("fuse", path, key, compute, None, lambda p: Path(p), timings)
