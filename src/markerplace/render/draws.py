"""The renderer's draws: GL buffers of the scene's parts, and the chunks of a large draw that a view
needs (inside the frustum, and not hidden behind what is already drawn).

A large draw (a scan: at least :data:`~markerplace.render.culling.MIN_TRIANGLES` triangles) is
split into spatial chunks (:mod:`markerplace.render.culling`). A view draws the chunks that meet
its frustum in rounds, nearest first (:data:`ROUNDS`): the first round (and every chunk whose
box comes within :data:`NEAR_SAFE` metres of the eye) untested, then in each later round only
the chunks whose box is not hidden by the depth drawn so far: one GL occlusion query per box
(the box drawn with colour and depth writes off, counting the samples that pass the depth test).

Why the image stays the same: a chunk's triangles lie inside its box, enlarged by
:data:`BOX_MARGIN`, so along every pixel ray they lie behind the box's front faces; when no
sample of the box passes the depth test (``LESS``), none of the chunk's would. The eye must be
outside the box (a box around the eye is clipped by the near plane), hence :data:`NEAR_SAFE`.
The queries of a round are read back at once (llvmpipe rasterizes what it has binned when a
result is read, so one read per round, not one per query). Hand-written because GL offers the
queries, not the policy, and moderngl has no scene graph.

The boxes are drawn into a framebuffer of their own that holds only the depth buffer being
drawn (:func:`query_framebuffer`), so no colour can be written whatever the colour masks say:
moderngl (5.13) does not apply ``Framebuffer.color_mask`` to a bound framebuffer with a single
colour attachment, so masking the RGB-only framebuffer let the boxes' undefined colour into the
image (coloured blocks in every RGB-only view of a scan, while the views with more outputs were
right).

Frames: world z up, metres; ``cam_from_world`` 4x4 world -> OpenCV camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from markerplace.render.culling import MIN_TRIANGLES, ChunkedTriangles, chunk_triangles
from markerplace.render.vertices import indexed_part_vertices, part_vertices
from markerplace.scene.types import MeshPart

__all__ = ["BOX_MARGIN", "NEAR_SAFE", "ROUNDS", "Draw", "OcclusionTest", "by_distance", "query_framebuffer",
           "scene_buffers"]

BOX_MARGIN = 0.01
"""Metres added on every side of a chunk's box for its occlusion query (far more than the
depth buffer's resolution at any planning range)."""

ROUNDS = (0.1, 0.4, 1.0)
"""Cumulative shares of a view's chunks, nearest first: the first round is drawn untested, each
later one is tested against the depth of all the rounds before it."""

NEAR_SAFE = 0.2
"""A chunk whose box comes this close to the eye (metres) is always drawn, never tested."""

_BOX_VERTEX = """
#version 330
uniform mat4 proj;
uniform mat4 cam_from_world;
in vec3 in_pos;
void main() { gl_Position = proj * cam_from_world * vec4(in_pos, 1.0); }
"""
_BOX_FRAGMENT = """
#version 330
void main() {}
"""
# the 12 triangles of a box from its 8 corners (bit 0: x, bit 1: y, bit 2: z at the max side)
_BOX_TRIANGLES = np.array([[0, 2, 1], [1, 2, 3], [4, 5, 6], [5, 7, 6], [0, 1, 4], [1, 5, 4],
                           [2, 6, 3], [3, 6, 7], [0, 4, 2], [2, 4, 6], [1, 3, 5], [3, 7, 5]])


@dataclass(frozen=True, eq=False)
class Draw:
    """One draw of the renderer: a texture, a vertex buffer, ``n`` corners (vertices, or index
    entries when ``ibo`` is set), the spatial chunks of a culled draw (None: drawn whole) and
    their occlusion test."""

    texture: object
    vbo: object
    n: int
    chunks: ChunkedTriangles | None = None
    ibo: object = None
    occlusion: "OcclusionTest | None" = None


def scene_buffers(ctx, parts: Sequence[MeshPart], cull: bool) -> tuple:
    """GL buffers of the opaque parts sharing one texture: ``(vbo, n, chunks, ibo)`` of a
    :class:`Draw`. Small groups (and every group with ``cull`` off) are one de-indexed buffer
    drawn whole; a large group is culled (:mod:`markerplace.render.culling`), indexed when every
    part has per-vertex normals (llvmpipe then shades each vertex once, not once per corner: the
    same images, about a third faster on a scan)."""
    n_triangles = sum(len(p.faces) for p in parts)
    if not cull or n_triangles < MIN_TRIANGLES:
        data = np.concatenate([part_vertices(p) for p in parts])
        return ctx.buffer(data.tobytes()), len(data), None, None
    if all(p.normals is not None for p in parts):
        records, faces, offset = [], [], 0
        for p in parts:
            rec, f = indexed_part_vertices(p)
            records.append(rec)
            faces.append(f + offset)
            offset += len(rec)
        data, faces = np.concatenate(records), np.concatenate(faces)
        chunks = chunk_triangles(data["pos"][faces])
        # vertices renumbered in order of first use, so a chunk's triangles index a compact range
        faces = faces[chunks.order].reshape(-1)
        used, first_use = np.unique(faces, return_index=True)
        by_first_use = used[np.argsort(first_use, kind="stable")]
        new_index = np.empty(len(data), np.int64)
        new_index[by_first_use] = np.arange(len(by_first_use))
        index = new_index[faces].astype(np.uint32)
        data = data[by_first_use]
        return ctx.buffer(data.tobytes()), index.size, chunks, ctx.buffer(index.tobytes())
    data = np.concatenate([part_vertices(p) for p in parts])
    chunks = chunk_triangles(data["pos"].reshape(-1, 3, 3))
    data = data.reshape(-1, 3)[chunks.order].reshape(-1)
    return ctx.buffer(data.tobytes()), len(data), chunks, None


def by_distance(chunks: ChunkedTriangles, visible: np.ndarray, eye: np.ndarray) -> list[np.ndarray]:
    """The ``visible`` chunks in rounds by the distance from ``eye`` (3,) to their box, each
    round ascending: the first (drawn without a test) holds the nearest :data:`ROUNDS` [0] share
    and every chunk within :data:`NEAR_SAFE`; each later round the next share up to ROUNDS[i]."""
    lo, hi = chunks.box_min[visible] - BOX_MARGIN, chunks.box_max[visible] + BOX_MARGIN
    gap = np.linalg.norm(np.maximum(np.maximum(lo - eye, eye - hi), 0.0), axis=1)
    order = np.argsort(gap, kind="stable")
    ends = [max(int(np.ceil(ROUNDS[0] * len(visible))), int(np.sum(gap < NEAR_SAFE)))]
    ends += [max(ends[-1], int(np.ceil(share * len(visible)))) for share in ROUNDS[1:]]
    starts = [0] + ends[:-1]
    return [np.sort(visible[order[a:b]]) for a, b in zip(starts, ends)]


class OcclusionTest:
    """Occlusion queries of chunk boxes against the depth drawn so far (see the module docstring).

    Args:
        ctx: the renderer's moderngl context.
        chunks: the chunks of one draw.
        proj: (4, 4) float32 projection of the renderer.
    """

    def __init__(self, ctx, chunks: ChunkedTriangles, proj: np.ndarray):
        lo, hi = chunks.box_min - BOX_MARGIN, chunks.box_max + BOX_MARGIN
        bits = np.arange(8)[:, None] >> np.arange(3)[None, :] & 1  # (8, 3) which side per axis
        corners = np.where(bits[None].astype(bool), hi[:, None, :], lo[:, None, :])  # (C, 8, 3)
        verts = corners[:, _BOX_TRIANGLES.reshape(-1)].astype("f4")  # (C, 36, 3)
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=_BOX_VERTEX, fragment_shader=_BOX_FRAGMENT)
        self.prog["proj"].write(np.asarray(proj, "f4").T.tobytes())
        self.vao = ctx.vertex_array(self.prog, [(ctx.buffer(verts.tobytes()), "3f", "in_pos")])
        self.queries: list = []

    def passed(self, query_fbo, cam_from_world: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """(len(ids),) bool: some sample of chunk ``ids[i]``'s box passes the depth test against
        the depth drawn so far, nothing written. ``query_fbo`` is the :func:`query_framebuffer`
        of the depth buffer being drawn; it is left bound (the caller binds its own again)."""
        while len(self.queries) < len(ids):
            self.queries.append(self.ctx.query(samples=True))
        self.prog["cam_from_world"].write(np.asarray(cam_from_world, "f4").T.tobytes())
        query_fbo.use()
        for query, c in zip(self.queries, ids):
            with query:
                self.vao.render(vertices=36, first=36 * int(c))
        return np.array([q.samples > 0 for q in self.queries[:len(ids)]], dtype=bool)


def query_framebuffer(ctx, depth_attachment):
    """A framebuffer for occlusion queries: ``depth_attachment`` (the depth buffer being drawn)
    and no colour attachment, depth writes off (applied when it is bound). Nothing drawn into it
    changes an image (see the module docstring)."""
    fbo = ctx.framebuffer(depth_attachment=depth_attachment)
    fbo.depth_mask = False
    return fbo
