"""View-frustum culling of large vertex buffers: triangles in spatial chunks, the ranges a view draws.

Why: Mesa's llvmpipe (the software GL this project renders with) transforms, clips and bins
every triangle it is given, so a view of a million-triangle scan costs the same whether it
sees a corner or the whole building (about 130 ms a view at 600x450 on one core, proportional
to the triangles submitted). Drawing only the chunks whose bounding box meets the view frustum
does the same work for the triangles that can appear and skips the rest. GL has no
frustum-culling of its own for a single draw call and moderngl exposes none, and ray-casting
libraries (Embree, Open3D) answer a different question, so this small module does it: sort the
triangles of a buffer along a Morton (z-order) curve of their centroids (stable, so triangles
in one cell keep their order), cut them into chunks of :data:`CHUNK_TRIANGLES`, keep each
chunk's axis-aligned box, and per view test the boxes against the frustum's six planes
(conservative: a box is dropped only when it lies wholly outside one plane, widened by
:data:`MARGIN_PX` pixels), merging consecutive visible chunks into one draw range.

What a view shows is unchanged: a dropped triangle lies outside the frustum, so it could not
produce a fragment. The order of the triangles changes, which matters only where two surfaces
have exactly the same depth at a pixel centre (depth test ``LESS``: the first drawn wins);
buffers with fewer than :data:`MIN_TRIANGLES` triangles (every built-in scene's) are left in
their order and drawn whole.

Frames: positions in the world frame (metres); ``cam_from_world`` 4x4 maps world points to the
OpenCV camera frame (x right, y down, z forward); planes are ``(n, d)`` with ``n . p + d >= 0``
inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplace.geometry import Intrinsics

__all__ = ["CHUNK_TRIANGLES", "MIN_TRIANGLES", "MARGIN_PX", "ChunkedTriangles", "chunk_triangles", "chunk_ranges",
           "frustum_planes", "visible_chunks", "visible_ranges"]

CHUNK_TRIANGLES = 1024
"""Triangles per chunk: about 1,100 chunks for a million-triangle scan (the per-view box test
is a few hundred microseconds; smaller chunks cull tighter but cost more draw calls)."""

MIN_TRIANGLES = 65536
"""Buffers with fewer triangles are drawn whole, in their order (culling would save little)."""

MARGIN_PX = 2.0
"""The frustum's side planes are widened by this many pixels (rounding safety)."""

_MORTON_BITS = 10


@dataclass(frozen=True, eq=False)
class ChunkedTriangles:
    """A triangle buffer in spatial order, cut into chunks.

    Attributes:
        order: (T,) int64, original triangle index of each triangle in the new order.
        first_vertex: (C,) int64, first corner (3 per triangle: a vertex of a de-indexed buffer or
            an entry of an index buffer) of each chunk in the new order.
        n_vertices: (C,) int64, corners of each chunk.
        box_min, box_max: (C, 3) float64 world-frame corners of each chunk's bounding box.
    """

    order: np.ndarray
    first_vertex: np.ndarray
    n_vertices: np.ndarray
    box_min: np.ndarray
    box_max: np.ndarray


def _spread_bits(v: np.ndarray) -> np.ndarray:
    """Insert two zero bits between the low 10 bits of each value (for 3-D Morton codes)."""
    v = v.astype(np.uint64) & np.uint64(0x3FF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x030000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x0300F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x030C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x09249249)
    return v


def chunk_triangles(triangles: np.ndarray, chunk: int = CHUNK_TRIANGLES) -> ChunkedTriangles:
    """Spatial order and chunk boxes of the triangles of a draw.

    Args:
        triangles: (T, 3, 3) world-frame corner positions of each triangle, in draw order.
        chunk: triangles per chunk.

    Returns:
        :class:`ChunkedTriangles`; reorder the draw's corners (a de-indexed vertex buffer, or
        an index buffer's faces) with ``corners.reshape(T, 3, ...)[order]``.
    """
    tri = np.asarray(triangles, dtype=np.float64).reshape(-1, 3, 3)
    T = len(tri)
    centroid = tri.mean(axis=1)
    lo, hi = centroid.min(axis=0), centroid.max(axis=0)
    scale = (2 ** _MORTON_BITS - 1) / np.maximum(hi - lo, 1e-9)
    cell = np.clip(((centroid - lo) * scale).astype(np.int64), 0, 2 ** _MORTON_BITS - 1)
    code = _spread_bits(cell[:, 0]) | (_spread_bits(cell[:, 1]) << np.uint64(1)) | (_spread_bits(cell[:, 2]) << np.uint64(2))
    order = np.argsort(code, kind="stable")
    starts = np.arange(0, T, chunk)
    counts = np.minimum(chunk, T - starts)
    sorted_tri = tri[order]
    box_min = np.minimum.reduceat(sorted_tri.min(axis=1), starts, axis=0)
    box_max = np.maximum.reduceat(sorted_tri.max(axis=1), starts, axis=0)
    return ChunkedTriangles(order, starts * 3, counts * 3, box_min, box_max)


def frustum_planes(intrinsics: Intrinsics, near: float, far: float, margin_px: float = MARGIN_PX) -> np.ndarray:
    """(6, 4) camera-frame planes ``(n, d)`` of the view frustum, ``n . p + d >= 0`` inside.

    The side planes pass through the camera centre and the image edges (pixel boundaries at
    -0.5 and width - 0.5, widened by ``margin_px``); near and far are z = near, z = far.
    """
    K = intrinsics
    left = (-0.5 - margin_px - K.cx) / K.fx
    right = (K.width - 0.5 + margin_px - K.cx) / K.fx
    top = (-0.5 - margin_px - K.cy) / K.fy
    bottom = (K.height - 0.5 + margin_px - K.cy) / K.fy
    return np.array([
        [1.0, 0.0, -left, 0.0],     # x >= left z
        [-1.0, 0.0, right, 0.0],    # x <= right z
        [0.0, 1.0, -top, 0.0],      # y >= top z
        [0.0, -1.0, bottom, 0.0],   # y <= bottom z
        [0.0, 0.0, 1.0, -near],     # z >= near
        [0.0, 0.0, -1.0, far],      # z <= far
    ])


def visible_chunks(chunks: ChunkedTriangles, cam_from_world: np.ndarray, planes_cam: np.ndarray) -> np.ndarray:
    """(V,) int64 indices, ascending, of the chunks whose box is not wholly outside a frustum plane.

    Args:
        chunks: from :func:`chunk_triangles`.
        cam_from_world: (4, 4) world -> OpenCV camera.
        planes_cam: (6, 4) from :func:`frustum_planes`.
    """
    planes_world = planes_cam @ np.asarray(cam_from_world, dtype=np.float64)  # (n_c, d_c) . (R p + t)
    n, d = planes_world[:, :3], planes_world[:, 3]
    centre = (chunks.box_min + chunks.box_max) / 2.0
    half = (chunks.box_max - chunks.box_min) / 2.0
    reach = centre @ n.T + half @ np.abs(n).T + d  # (C, 6): the box's farthest point along each normal
    return np.flatnonzero((reach >= 0.0).all(axis=1))


def chunk_ranges(chunks: ChunkedTriangles, indices: np.ndarray) -> list[tuple[int, int]]:
    """Draw ranges ``(first, count)`` of the chunks ``indices`` (ascending), consecutive chunks
    merged into one range."""
    indices = np.asarray(indices, dtype=np.int64)
    if len(indices) == 0:
        return []
    breaks = np.flatnonzero(np.diff(indices) > 1)
    run_start = np.concatenate([[indices[0]], indices[breaks + 1]])
    run_end = np.concatenate([indices[breaks], [indices[-1]]])
    first = chunks.first_vertex[run_start]
    last = chunks.first_vertex[run_end] + chunks.n_vertices[run_end]
    return [(int(f), int(e - f)) for f, e in zip(first, last)]


def visible_ranges(chunks: ChunkedTriangles, cam_from_world: np.ndarray, planes_cam: np.ndarray) -> list[tuple[int, int]]:
    """Vertex ranges ``(first, count)`` to draw for one view: :func:`visible_chunks`, merged by
    :func:`chunk_ranges`."""
    return chunk_ranges(chunks, visible_chunks(chunks, cam_from_world, planes_cam))
