"""Frustum culling and indexed drawing of large buffers: the images are GL's own images of the
whole buffer (renders with ``cull=False`` are the reference), and the culling helpers keep every
triangle that can appear."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.poses import look_at_pose
from markerplace.geometry import Intrinsics, invert, project
from markerplace.render.culling import MIN_TRIANGLES, chunk_triangles, frustum_planes, visible_ranges
from markerplace.render.gl_resources import FAR, NEAR
from markerplace.render.renderer import Renderer
from markerplace.scene.types import MeshPart, Scene

ROOM = (6.0, 5.0, 2.7)
CELLS = 80  # per face side: 6 faces x 2 x 80^2 = 76,800 triangles, more than MIN_TRIANGLES


def _grid(origin, u, v, n):
    """(n+1)^2 vertices and 2 n^2 faces of the parallelogram origin + s u + t v."""
    s, t = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij")
    verts = np.asarray(origin) + s.reshape(-1, 1) * np.asarray(u) + t.reshape(-1, 1) * np.asarray(v)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    return verts, faces


def _room_faces():
    x, y, z = ROOM
    return [((0, 0, 0), (x, 0, 0), (0, y, 0)), ((0, 0, z), (x, 0, 0), (0, y, 0)),
            ((0, 0, 0), (x, 0, 0), (0, 0, z)), ((0, y, 0), (x, 0, 0), (0, 0, z)),
            ((0, 0, 0), (0, y, 0), (0, 0, z)), ((x, 0, 0), (0, y, 0), (0, 0, z))]


def scan_like_scene(seed: int = 0) -> Scene:
    """One vertex-coloured part with per-vertex normals (as a fused scan), walls bumped a little."""
    rng = np.random.default_rng(seed)
    verts, faces, normals = [], [], []
    for origin, u, v in _room_faces():
        p, f = _grid(origin, u, v, CELLS)
        n = np.cross(u, v) / np.linalg.norm(np.cross(u, v))
        p = p + n * rng.normal(0, 0.01, (len(p), 1))
        faces.append(f + sum(len(q) for q in verts))
        verts.append(p)
        normals.append(np.tile(n, (len(p), 1)))
    v = np.concatenate(verts).astype(np.float32)
    colors = rng.integers(0, 256, (len(v), 4), dtype=np.uint8)
    colors[:, 3] = 255
    part = MeshPart("scan", v, np.concatenate(faces).astype(np.int32), colors=colors,
                    normals=np.concatenate(normals).astype(np.float32))
    return Scene("scan-like", (part,))


def textured_scene(seed: int = 0) -> Scene:
    """The room as six textured parts without normals (sharing one texture): the de-indexed path."""
    rng = np.random.default_rng(seed)
    texture = rng.integers(0, 256, (64, 64, 3), dtype=np.uint8)
    parts = []
    for i, (origin, u, v) in enumerate(_room_faces()):
        p, f = _grid(origin, u, v, CELLS)
        s, t = np.meshgrid(np.linspace(0, 3, CELLS + 1), np.linspace(0, 3, CELLS + 1), indexing="ij")
        parts.append(MeshPart(f"wall{i}", p.astype(np.float32), f.astype(np.int32),
                              uv=np.column_stack([s.ravel(), t.ravel()]).astype(np.float32), texture=texture))
    return Scene("textured", tuple(parts))


def _poses():
    eye = np.array([2.0, 1.5, 1.5])
    targets = [(5.5, 1.5, 1.4), (2.0, 4.8, 1.0), (0.2, 0.3, 2.0), (3.0, 2.5, 0.0), (5.8, 4.8, 2.6), (2.1, 1.6, 2.7)]
    poses = [look_at_pose(eye, np.array(t)) for t in targets]
    poses.append(look_at_pose(np.array([-2.0, 2.5, 1.5]), np.array([3.0, 2.5, 1.4])))  # outside, through a wall
    return poses


@pytest.mark.parametrize("make_scene", [scan_like_scene, textured_scene], ids=["indexed", "deindexed"])
def test_culled_renders_equal_whole_renders(make_scene):
    scene = make_scene()
    assert scene.num_faces >= MIN_TRIANGLES
    with Renderer(scene, cull=False) as whole, Renderer(scene) as culled:
        assert culled._scene_draws[0].chunks is not None and whole._scene_draws[0].chunks is None
        occlusion = culled._scene_draws[0].occlusion
        tested, hidden = [], []
        test = occlusion.passed

        def counting(fbo, cam_from_world, ids):
            passed = test(fbo, cam_from_world, ids)
            tested.append(len(ids))
            hidden.append(int((~passed).sum()))
            return passed

        occlusion.passed = counting
        for pose in _poses():
            a, b = whole.render(pose), culled.render(pose)
            np.testing.assert_array_equal(a.rgb, b.rgb)
            np.testing.assert_array_equal(a.depth, b.depth)
            np.testing.assert_array_equal(a.normal, b.normal)
            assert (a.depth > 0).mean() > 0.5  # the view sees the room
        # the occlusion queries ran, and seen from outside (the last pose) the near wall hides
        # most of what lies behind it
        assert sum(tested) > 0 and sum(hidden) > 0
        tested.clear(), hidden.clear()
        culled.render(_poses()[-1])
        assert sum(hidden) > 0.5 * sum(tested), (tested, hidden)


def test_culling_drops_what_a_view_cannot_see():
    scene = scan_like_scene()
    tri = scene.parts[0].vertices[scene.parts[0].faces]
    chunks = chunk_triangles(tri)
    planes = frustum_planes(Intrinsics(), NEAR, FAR)
    toward_wall = look_at_pose(np.array([3.0, 2.5, 1.35]), np.array([6.0, 2.5, 1.35]))
    drawn = sum(n for _, n in visible_ranges(chunks, invert(toward_wall), planes)) / 3
    assert drawn < 0.6 * len(tri)
    outside = look_at_pose(np.array([-5.0, 2.5, 1.35]), np.array([-9.0, 2.5, 1.35]))  # looking away
    assert visible_ranges(chunks, invert(outside), planes) == []


def test_chunks_keep_every_triangle_and_bound_it():
    rng = np.random.default_rng(3)
    tri = rng.uniform(-5, 5, (5000, 1, 3)) + rng.normal(0, 0.05, (5000, 3, 3))
    chunks = chunk_triangles(tri, chunk=256)
    assert sorted(chunks.order.tolist()) == list(range(len(tri)))
    assert chunks.n_vertices.sum() == 3 * len(tri)
    reordered = tri[chunks.order]
    for c, (first, n) in enumerate(zip(chunks.first_vertex // 3, chunks.n_vertices // 3)):
        pts = reordered[first:first + n].reshape(-1, 3)
        assert (pts >= chunks.box_min[c] - 1e-12).all() and (pts <= chunks.box_max[c] + 1e-12).all()
    # Morton order makes chunks compact: far smaller than the whole cloud
    assert np.median(np.prod(chunks.box_max - chunks.box_min, axis=1)) < 0.5 * 10 ** 3


def test_every_triangle_in_the_image_is_drawn():
    """Brute force: each small triangle with a corner that projects into the image (in front of
    the camera) lies in a drawn range."""
    rng = np.random.default_rng(4)
    centres = rng.uniform(-8, 8, (20000, 3))
    tri = centres[:, None, :] + rng.normal(0, 0.05, (20000, 3, 3))
    chunks = chunk_triangles(tri, chunk=64)
    K = Intrinsics()
    planes = frustum_planes(K, NEAR, FAR)
    for seed in range(5):
        r = np.random.default_rng(seed)
        pose = look_at_pose(r.uniform(-3, 3, 3), r.uniform(-8, 8, 3))
        drawn = np.zeros(len(tri), bool)
        for first, n in visible_ranges(chunks, invert(pose), planes):
            drawn[chunks.order[first // 3:(first + n) // 3]] = True
        uv, z = project(K.K, pose, tri.reshape(-1, 3))
        inside = ((z > NEAR) & (uv[:, 0] >= -0.5) & (uv[:, 0] <= K.width - 0.5)
                  & (uv[:, 1] >= -0.5) & (uv[:, 1] <= K.height - 0.5)).reshape(-1, 3).any(axis=1)
        assert inside.sum() > 50
        assert drawn[inside].all()
        assert drawn.mean() < 0.9
