"""Vertex records the renderer uploads: the interleaved layout, scene parts de-indexed, marker quads.

CPU side only (numpy, no GL). World frame: z up, metres. One record per triangle corner
(:data:`VERTEX_DTYPE`): ``pos`` 3 x float32 world metres, ``normal`` 3 x float32 unit world
normal, ``uv`` 2 x float32 GL texture coordinates (t = 0 is image row 0, the top), ``color``
4 x uint8 (base colour times vertex colour; alpha is the opacity, glass about 0.3).

Parts are de-indexed so parts without normals get exact flat face normals. A marker is a quad
of two triangles carrying its tag image with the white quiet zone (marker frame: x to a facing
viewer's right, y up, z out of the wall), lifted :data:`MARKER_OFFSET` metres off the wall
along its normal. :data:`VERTEX_ATTRS` names the shader inputs of the layout
(:mod:`markerplace.render.shaders`).
"""

from __future__ import annotations

import numpy as np

from markerplace.markers import Marker
from markerplace.scene.transparency import OPAQUE_ALPHA, drawn_alpha
from markerplace.scene.types import MeshPart
from markerplace.tagfamily import outer_size

__all__ = ["MARKER_OFFSET", "VERTEX_DTYPE", "VERTEX_ATTRS", "part_vertices", "indexed_part_vertices", "marker_vertices"]

MARKER_OFFSET = 0.004
"""Distance (metres) a marker quad floats in front of its wall, along the marker normal."""

# Interleaved vertex layout: pos 3f, normal 3f, uv 2f, colour 4 x u8 (normalized).
VERTEX_DTYPE = np.dtype(
    [("pos", "<f4", 3), ("normal", "<f4", 3), ("uv", "<f4", 2), ("color", "u1", 4)]
)
VERTEX_ATTRS = (("in_pos", "3f", 12), ("in_normal", "3f", 12), ("in_uv", "2f", 8), ("in_color", "4f1", 4))
"""(shader input, moderngl format, bytes) of each field of :data:`VERTEX_DTYPE`, in order."""


def part_vertices(part: MeshPart) -> np.ndarray:
    """De-indexed (3 M,) vertex records of one part (see ``VERTEX_DTYPE``)."""
    faces = np.asarray(part.faces, dtype=np.int64)
    return _records(part, faces.reshape(-1), faces)


def indexed_part_vertices(part: MeshPart) -> tuple[np.ndarray, np.ndarray]:
    """(V,) vertex records, one per mesh vertex, and the (M, 3) int64 faces indexing them: the
    same corners as :func:`part_vertices` draws, for a part whose attributes are all per vertex
    (it must have normals; flat face normals need the de-indexed records)."""
    if part.normals is None:
        raise ValueError("indexed vertex records need per-vertex normals")
    faces = np.asarray(part.faces, dtype=np.int64)
    return _records(part, np.arange(len(part.vertices)), faces), faces


def _records(part: MeshPart, corner: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Vertex records of ``part`` at the mesh vertices ``corner`` (one per record); ``faces``
    (M, 3) give flat normals when the part has none (then ``corner`` is ``faces`` flattened)."""
    verts = np.asarray(part.vertices, dtype=np.float64)
    out = np.zeros(len(corner), dtype=VERTEX_DTYPE)
    out["pos"] = verts[corner]
    if part.normals is not None:
        out["normal"] = np.asarray(part.normals, dtype=np.float32)[corner]
    else:
        tri = verts[faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-300), np.array([0.0, 0.0, 1.0]))
        out["normal"] = np.repeat(n, 3, axis=0)
    if part.uv is not None and part.texture is not None:
        uv = np.asarray(part.uv, dtype=np.float32)[corner]
        # Scene uv: (0, 0) = bottom-left of the image as displayed; GL t = 0 is image row 0 (top).
        out["uv"][:, 0] = uv[:, 0]
        out["uv"][:, 1] = 1.0 - uv[:, 1]
    base = np.clip(np.asarray(part.base_color, dtype=np.float64), 0.0, 1.0)
    if part.colors is not None:
        col = np.asarray(part.colors, dtype=np.float64)[corner] / 255.0 * base
    else:
        col = np.broadcast_to(base, (len(corner), 4))
    if part.transparent:  # glass: its opacity, at most about 0.3 unless its colour says less
        col = np.array(col)
        col[:, 3] = np.where((col[:, 3] > 0) & (col[:, 3] < OPAQUE_ALPHA), col[:, 3], drawn_alpha(1.0))
    out["color"] = np.round(col * 255.0).astype(np.uint8)
    return out


def marker_vertices(marker: Marker) -> np.ndarray:
    """(6,) vertex records of a marker quad (two triangles) in the world frame."""
    h = outer_size(marker.size) / 2.0
    # Marker frame: x viewer's right, y up, z out of the wall. Image row 0 (GL t = 0) at +y.
    local = np.array([[-h, h], [h, h], [h, -h], [-h, -h]])
    st = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    T = np.asarray(marker.world_from_marker, dtype=np.float64)
    pts = np.column_stack([local, np.full(4, MARKER_OFFSET)]) @ T[:3, :3].T + T[:3, 3]
    idx = [0, 3, 2, 0, 2, 1]  # counter-clockwise seen from +z
    out = np.zeros(6, dtype=VERTEX_DTYPE)
    out["pos"] = pts[idx]
    out["normal"] = T[:3, 2]
    out["uv"] = st[idx]
    out["color"] = 255
    return out
