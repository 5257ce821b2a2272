"""A scan-like scene for the render and report tests: a room whose walls, floor and ceiling are
fine triangle grids textured from several atlases, as a real scan's glTF is (many primitives
sharing a few texture atlases), with more than
:data:`~markerplace.render.culling.MIN_TRIANGLES` triangles in each of its two big atlases, so the
renderer sorts both into spatial chunks and draws them through occlusion queries, plus a table
with an atlas of its own, drawn whole.

Every texel is a :data:`PALETTE` colour. Each has G == B and R >= G >= R / 4, and so does every
colour the renderer can make of them (a colour times a light factor, texture filtering's mixtures
of texels, the tags' greys, the black where nothing is hit): :func:`foreign_colours` finds the
pixels that are none of these.

Frame: world z up, metres; the room is [0, 6] x [0, 5] x [0, 2.7].
"""

from __future__ import annotations

import numpy as np

from markerplace.scene.types import MeshPart, Scene

ROOM = (6.0, 5.0, 2.7)
CELLS = 112
"""Grid cells per side of each room face: 6 faces x 2 x 112^2 = 150,528 triangles, 75,264 per big atlas."""
BLOCK = 8
"""Cells per side of a checker block: the blocks alternate between the two big atlases."""

PALETTE = np.array([[225, 225, 225], [130, 130, 130], [60, 60, 60], [205, 75, 75], [150, 40, 40]], np.uint8)
"""The texels' colours (RGB): greys and reds, each with G == B and R >= G >= R / 4."""


def foreign_colours(rgb: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of an (H, W, 3) uint8 image that no render of the scene can hold
    (G != B, or G outside [R / 4, R], one grey level of rounding allowed)."""
    r, g, b = (rgb[..., i].astype(np.int32) for i in range(3))
    return (np.abs(g - b) > 1) | (g > r + 1) | (4 * g < r - 4)


def _grid(origin, u, v, n):
    """(n+1)^2 vertices, 2 n^2 faces (cell-major: faces 2k, 2k+1 are cell k) and the grid
    coordinates (s, t) in [0, 1] of each vertex, of the parallelogram origin + s u + t v."""
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    verts = np.asarray(origin) + s.reshape(-1, 1) * np.asarray(u) + t.reshape(-1, 1) * np.asarray(v)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.stack([np.column_stack([a, b, c]), np.column_stack([a, c, d])], axis=1).reshape(-1, 3)
    return verts, faces, np.column_stack([s.ravel(), t.ravel()])


def _atlas(rng: np.random.Generator, size: int = 128, block: int = 16) -> np.ndarray:
    """(size, size, 3) uint8: blocks of random :data:`PALETTE` colours."""
    k = size // block
    pick = rng.integers(0, len(PALETTE), (k, k))
    return np.ascontiguousarray(np.repeat(np.repeat(PALETTE[pick], block, axis=0), block, axis=1))


def _room_faces():
    x, y, z = ROOM
    return [((0, 0, 0), (x, 0, 0), (0, y, 0)), ((0, 0, z), (x, 0, 0), (0, y, 0)),
            ((0, 0, 0), (x, 0, 0), (0, 0, z)), ((0, y, 0), (x, 0, 0), (0, 0, z)),
            ((0, 0, 0), (0, y, 0), (0, 0, z)), ((x, 0, 0), (0, y, 0), (0, 0, z))]


def multi_atlas_room(seed: int = 0) -> Scene:
    """The room (see the module docstring): per face, two parts (the checker blocks of atlas 0,
    with per-vertex normals, drawn indexed; and those of atlas 1, without, drawn de-indexed),
    and a table (0.8 m high, x in [2, 3.2], y in [3.5, 4.3]) textured from atlas 2."""
    rng = np.random.default_rng(seed)
    atlases = [_atlas(rng) for _ in range(3)]
    parts = []
    cell = np.arange(CELLS * CELLS)
    checker = ((cell // CELLS) // BLOCK + (cell % CELLS) // BLOCK) % 2
    for i, (origin, u, v) in enumerate(_room_faces()):
        verts, faces, st = _grid(origin, u, v, CELLS)
        normal = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
        uv = (st * np.array([np.linalg.norm(u), np.linalg.norm(v)]) / 2.0).astype(np.float32)  # an atlas per 2 m
        for k in (0, 1):
            f = faces.reshape(-1, 2, 3)[checker == k].reshape(-1, 3).astype(np.int32)
            normals = np.tile(normal, (len(verts), 1)).astype(np.float32) if k == 0 else None
            parts.append(MeshPart(f"face{i}/atlas{k}", verts.astype(np.float32), f, uv=uv, texture=atlases[k],
                                  normals=normals))
    x0, y0, x1, y1, top = 2.0, 3.5, 3.2, 4.3, 0.8
    for j, (origin, u, v) in enumerate([((x0, y0, top), (x1 - x0, 0, 0), (0, y1 - y0, 0)),
                                        ((x0, y0, 0), (x1 - x0, 0, 0), (0, 0, top)),
                                        ((x0, y1, 0), (x1 - x0, 0, 0), (0, 0, top)),
                                        ((x0, y0, 0), (0, y1 - y0, 0), (0, 0, top)),
                                        ((x1, y0, 0), (0, y1 - y0, 0), (0, 0, top))]):
        verts, faces, st = _grid(origin, u, v, 4)
        parts.append(MeshPart(f"table{j}", verts.astype(np.float32), faces.astype(np.int32),
                              uv=st.astype(np.float32), texture=atlases[2]))
    return Scene("multi-atlas-room", tuple(parts), (), 0.0)
