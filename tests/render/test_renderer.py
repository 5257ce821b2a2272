"""Renderer: exact planar depth, projection agreement with geometry.project, normals, textures,
determinism, set_markers, views (default pose, output files)."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.geometry import Intrinsics, invert, project, transform_points, world_from_cam_pose, world_from_marker_pose
from markerplace.markers import Marker
from markerplace.render.gl_resources import projection_matrix
from markerplace.render.renderer import Renderer, RenderResult
from markerplace.render.views import default_pose, write_render_outputs
from markerplace.scene.types import MeshPart, Room, Scene
from markerplace.tagfamily import outer_size

K = Intrinsics().K
CAM = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)  # looks along +x


def quad(center, u, v, name="quad", color=(1.0, 1.0, 1.0, 1.0), texture=None) -> MeshPart:
    """Parallelogram center +- u +- v (two triangles), uv (0,0) at center - u - v."""
    c, u, v = (np.asarray(a, float) for a in (center, u, v))
    verts = np.array([c - u - v, c + u - v, c + u + v, c - u + v], np.float32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32) if texture is not None else None
    return MeshPart(name, verts, np.array([[0, 1, 2], [0, 2, 3]], np.int32), uv=uv, texture=texture, base_color=color)


def wall_scene(x=3.0, color=(0.6, 0.6, 0.6, 1.0)) -> Scene:
    """A 10 x 10 m wall in the plane x = ``x`` facing the camera at the origin."""
    return Scene("wall", (quad([x, 0, 1.5], [0, 5, 0], [0, 0, 5], color=color),))


def render(scene, pose=CAM, markers=(), **kw) -> RenderResult:
    with Renderer(scene, markers=markers) as r:
        return r.render(pose, **kw)


def test_result_shapes_and_dtypes():
    res = render(wall_scene())
    assert res.rgb.shape == (450, 600, 3) and res.rgb.dtype == np.uint8
    assert res.depth.shape == (450, 600) and res.depth.dtype == np.float32
    assert res.normal.shape == (450, 600, 3) and res.normal.dtype == np.float32
    np.testing.assert_array_equal(res.world_from_cam, CAM)
    partial = render(wall_scene(), rgb=False, normal=False)
    assert partial.rgb is None and partial.normal is None and partial.depth.shape == (450, 600)


def test_depth_fronto_parallel_plane_is_exact():
    res = render(wall_scene(x=3.0))
    assert (res.depth > 0).all()  # the wall fills the view
    assert np.abs(res.depth - 3.0).max() < 1e-3


def test_depth_oblique_plane_matches_ray_plane_intersection():
    # Plane through p0 with normal n, tilted in yaw and pitch, seen from a rotated camera.
    n = np.array([-1.0, 0.4, 0.3])
    n /= np.linalg.norm(n)
    p0 = np.array([4.0, 0.5, 1.2])
    u = np.cross(n, [0, 0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    scene = Scene("oblique", (quad(p0, 20 * u, 20 * v),))
    pose = world_from_cam_pose(np.array([0.3, -0.2, 1.4]), np.radians(20))
    res = render(scene, pose)
    hit = res.depth > 0
    assert hit.mean() > 0.9
    # Analytic planar depth: ray d = K^-1 (u, v, 1) in camera; point = z d with n_c . (z d - p0_c) = 0.
    cam_from_world = invert(pose)
    n_c = cam_from_world[:3, :3] @ n
    p0_c = transform_points(cam_from_world, p0[None])[0]
    vv, uu = np.mgrid[0:450, 0:600]
    d = np.stack([(uu - K[0, 2]) / K[0, 0], (vv - K[1, 2]) / K[1, 1], np.ones_like(uu, float)], -1)
    z = (n_c @ p0_c) / (d @ n_c)
    assert np.abs(res.depth[hit] - z[hit]).max() < 1e-3


def _inside_projected_quad(corners_uv: np.ndarray):
    """Pixel-centre coverage of a convex projected quad, and each centre's distance to its edges."""
    vv, uu = np.mgrid[0:450, 0:600].astype(float)
    inside = np.ones(uu.shape, bool)
    dist = np.full(uu.shape, np.inf)
    area = 0.0
    for i in range(4):
        a, b = corners_uv[i], corners_uv[(i + 1) % 4]
        area += a[0] * b[1] - a[1] * b[0]
    sign = np.sign(area)
    for i in range(4):
        a, b = corners_uv[i], corners_uv[(i + 1) % 4]
        e = b - a
        cross = sign * (e[0] * (vv - a[1]) - e[1] * (uu - a[0]))
        inside &= cross >= 0
        dist = np.minimum(dist, np.abs(cross) / np.linalg.norm(e))
    return inside, dist


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_projection_agrees_with_geometry_project(seed):
    rng = np.random.default_rng(seed)
    center = np.array([3.0, rng.uniform(-1.5, 1.5), 1.5 + rng.uniform(-1.0, 1.0)])
    u, v = np.array([0.0, 0.071, 0.013]), np.array([0.0, -0.02, 0.083])
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), rng.uniform(-0.2, 0.2))
    res = render(Scene("q", (quad(center, u, v),)), pose, rgb=False, normal=False)
    corners = np.array([center - u - v, center + u - v, center + u + v, center - u + v])
    uv, _ = project(K, pose, corners)
    expected, dist = _inside_projected_quad(uv)
    got = res.depth > 0
    assert expected.sum() > 100
    # Coverage at pixel centres matches the analytic projection except within 0.02 px of an edge.
    assert not ((got != expected) & (dist > 0.02)).any()
    # Centroid of the covered pixels vs the projected centre (sub-pixel).
    vs, us = np.nonzero(got)
    c_uv, _ = project(K, pose, center[None])
    assert np.hypot(us.mean() - c_uv[0, 0], vs.mean() - c_uv[0, 1]) < 0.5


def test_projection_matrix_maps_principal_point_to_image_centre():
    P = projection_matrix(Intrinsics())
    clip = P @ np.array([0.0, 0.0, 2.0, 1.0])
    ndc = clip[:3] / clip[3]
    # cx = 300 -> window x 300.5 of 600 -> ndc (300.5 / 600) * 2 - 1.
    assert ndc[0] == pytest.approx(2 * 300.5 / 600 - 1)
    assert ndc[1] == pytest.approx(2 * 225.5 / 450 - 1)
    assert -1 < ndc[2] < 1


def test_normals_of_wall_facing_camera():
    res = render(wall_scene())
    np.testing.assert_allclose(res.normal.reshape(-1, 3), np.tile([-1.0, 0.0, 0.0], (450 * 600, 1)), atol=1e-5)
    # Floor seen from above (winding pointing down on purpose): normal still faces the camera (+z).
    verts = np.array([[0, -20, 0], [20, -20, 0], [20, 20, 0], [0, 20, 0]], np.float32)
    floor = MeshPart("floor", verts, np.array([[0, 2, 1], [0, 3, 2]], np.int32))
    res = render(Scene("floor", (floor,)))
    hit = res.depth > 0
    assert hit[300:].all() and not hit[:200].any()  # floor in the lower half, nothing above
    np.testing.assert_allclose(res.normal[hit], np.tile([0.0, 0.0, 1.0], (hit.sum(), 1)), atol=1e-5)
    assert (res.normal[~hit] == 0).all() and (res.depth[~hit] == 0).all()


def test_texture_orientation_and_vertex_colours():
    # Texture: top half red, bottom half blue (row 0 = top); uv (0,0) = bottom-left as displayed.
    tex = np.zeros((64, 64, 3), np.uint8)
    tex[:32, :, 0] = 255
    tex[32:, :, 2] = 255
    wall = quad([3, 0, 1.5], [0, -1.0, 0], [0, 0, 1.0], texture=tex)  # u axis -> viewer's right (-y)
    res = render(Scene("tex", (wall,)))
    top, bottom = res.rgb[225 - 60, 300], res.rgb[225 + 60, 300]
    assert top[0] > 150 and top[2] < 30, top
    assert bottom[2] > 150 and bottom[0] < 30, bottom
    # Vertex colours times base colour, no texture.
    verts = np.array([[3, 2, -1], [3, -2, -1], [3, -2, 4], [3, 2, 4]], np.float32)
    cols = np.tile(np.array([[0, 255, 0, 255]], np.uint8), (4, 1))
    part = MeshPart("vc", verts, np.array([[0, 1, 2], [0, 2, 3]], np.int32), colors=cols, base_color=(1, 0.5, 1, 1))
    px = render(Scene("vc", (part,))).rgb[225, 300].astype(int)
    assert px[0] == 0 and px[2] == 0 and 100 < px[1] < 140  # green x 0.5, head-on lighting = 1


def test_shared_texture_uploaded_once():
    tex = np.full((8, 8, 3), 200, np.uint8)
    parts = tuple(quad([3, y, 1.5], [0, 0.2, 0], [0, 0, 0.2], name=f"q{y}", texture=tex) for y in (-1.0, 0.0, 1.0))
    with Renderer(Scene("shared", parts)) as r:
        assert len(r._scene_draws) == 1
        res = r.render(CAM)
    assert (res.depth > 0).sum() > 3 * 300


@pytest.mark.parametrize("near_first", [False, True])
def test_occlusion_nearer_surface_wins(near_first):
    near = quad([2, 0, 1.5], [0, 0.3, 0], [0, 0, 0.3], color=(1, 0, 0, 1))
    far = wall_scene().parts[0]
    res = render(Scene("occ", (near, far) if near_first else (far, near)))
    assert res.depth[225, 300] == pytest.approx(2.0, abs=1e-4)
    assert res.depth[10, 10] == pytest.approx(3.0, abs=1e-3)
    assert res.rgb[225, 300, 0] > 200 and res.rgb[225, 300, 1] == 0
    np.testing.assert_allclose(res.normal[225, 300], [-1, 0, 0], atol=1e-6)


def test_determinism_and_set_markers_changes_only_marker_region():
    m = Marker(5, 0.3, world_from_marker_pose(np.array([3.0, 0.4, 1.6]), np.array([-1.0, 0, 0])))
    pose = world_from_cam_pose(np.array([0.2, 0.1, 1.5]), np.radians(5))
    with Renderer(wall_scene()) as r:
        a, b = r.render(pose), r.render(pose)
        for name in ("rgb", "depth", "normal"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        r.set_markers([m])
        c = r.render(pose)
        r.set_markers([])
        d = r.render(pose)
        batch = list(r.render_batch([pose, pose], rgb=True, depth=False, normal=False))
    np.testing.assert_array_equal(d.rgb, a.rgb)
    np.testing.assert_array_equal(batch[0].rgb, a.rgb)
    np.testing.assert_array_equal(batch[1].rgb, a.rgb)
    changed = np.any(c.rgb != a.rgb, axis=2)
    # Projected outer quad (quiet zone included), dilated by one pixel.
    h = outer_size(m.size) / 2
    outer = (np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]]) @ m.world_from_marker[:3, :3].T) + m.position
    uv, _ = project(K, pose, outer)
    assert changed.sum() > 500
    vs, us = np.nonzero(changed)
    assert us.min() >= uv[:, 0].min() - 1 and us.max() <= uv[:, 0].max() + 1
    assert vs.min() >= uv[:, 1].min() - 1 and vs.max() <= uv[:, 1].max() + 1
    # The marker floats a few millimetres in front of the wall.
    in_marker = changed
    assert np.all(c.depth[in_marker] < a.depth[in_marker])
    assert np.all(a.depth[in_marker] - c.depth[in_marker] < 0.01)


def test_default_pose_rooms_and_bbox():
    scene = Scene(
        "rooms",
        wall_scene().parts,
        rooms=(Room("small", (0, 0, 2, 2)), Room("big", (10, 0, 12, 6))),
        floor_z=0.25,
    )
    T = default_pose(scene)
    np.testing.assert_allclose(T[:3, 3], [11.0, 3.0, 1.75])
    np.testing.assert_allclose(T[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)  # longer axis is y
    np.testing.assert_allclose(T[:3, 1], [0.0, 0.0, -1.0], atol=1e-12)  # level, y down
    T2 = default_pose(Scene("box", (quad([5, 0, 1.5], [2, 0, 0], [0, 1, 1.5]),)))
    np.testing.assert_allclose(T2[:3, 3], [5.0, 0.0, 1.5])
    np.testing.assert_allclose(T2[:3, 2], [1.0, 0.0, 0.0], atol=1e-12)


def test_write_render_outputs(tmp_path):
    from PIL import Image

    res = render(wall_scene())
    paths = write_render_outputs(tmp_path / "sub" / "x", res)
    assert [p.name for p in paths] == ["x_rgb.png", "x_depth.npy", "x_normal.png"]
    np.testing.assert_array_equal(np.asarray(Image.open(paths[0])), res.rgb)
    depth = np.load(paths[1], allow_pickle=False)
    assert depth.dtype == np.float32
    np.testing.assert_array_equal(depth, res.depth)
    normal_img = np.asarray(Image.open(paths[2]))
    np.testing.assert_array_equal(normal_img[225, 300], [0, 128, 128])  # n = (-1, 0, 0)


def test_cli_render_writes_three_files(tmp_path):
    import trimesh

    from markerplace.cli.main import main

    # A 6 x 4 x 3 m closed box room as a PLY file (z up, metres); the camera stands inside.
    room = trimesh.creation.box(extents=[6.0, 4.0, 3.0])
    room.apply_translation([3.0, 2.0, 1.5])
    path = tmp_path / "room.ply"
    room.export(path)
    out = tmp_path / "out" / "x"
    assert main(["render", str(path), "--pose", "3,2,1.5,0", "--out", str(out), "--width", "160", "--height", "120"]) == 0
    names = sorted(p.name for p in out.parent.iterdir())
    assert names == ["x_depth.npy", "x_normal.png", "x_rgb.png"]
    depth = np.load(out.parent / "x_depth.npy", allow_pickle=False)
    assert depth.shape == (120, 160)
    # Straight ahead is the wall at x = 6, 3 m away.
    assert depth[60, 80] == pytest.approx(3.0, abs=1e-3)


def test_two_renderers_in_one_process_render_their_own_scene():
    """Each render makes its own GL context current: interleaved renders of two renderers
    give each one's own image (the second-created context used to receive both)."""
    near, far = Renderer(wall_scene(x=2.0)), Renderer(wall_scene(x=5.0))
    try:
        for _ in range(2):
            assert np.abs(near.render(CAM, rgb=False, normal=False).depth - 2.0).max() < 1e-3
            assert np.abs(far.render(CAM, rgb=False, normal=False).depth - 5.0).max() < 1e-3
        near.set_markers([])
        assert np.abs(near.render(CAM, rgb=False, normal=False).depth - 2.0).max() < 1e-3
    finally:
        near.close()
        far.close()
