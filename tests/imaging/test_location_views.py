"""Looking at a camera location once (imaging/location_views.py): the face layout covers every
ray of the poses it serves, an even pose's image is the face's crop, an odd pose's image and
features follow from the faces by the rotation alone, and candidate occlusion agrees with a
render of the pose itself."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.geometry import Intrinsics, project, world_from_cam_poses
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import ImageFeatures
from markerplace.imaging.location_views import crop, face_layout, location_groups, split_features, unoccluded_from_faces, warp_view
from markerplace.imaging.visibility import marker_points, markers_unoccluded
from markerplace.render.renderer import Renderer
from markerplace.scene import load_scene

CAMERA = Intrinsics()


def location_poses(centre, n: int = 8, first_yaw: float = 0.3) -> np.ndarray:
    """(n, 4, 4) level poses at one centre, yaws first_yaw + 2 pi j / n (the discretization's)."""
    yaws = first_yaw + 2 * np.pi * np.arange(n) / n
    return world_from_cam_poses(np.tile(np.asarray(centre, float), (n, 1)), yaws)


def test_groups_are_runs_of_one_centre():
    T = np.concatenate([location_poses((0, 0, 1.5)), location_poses((1, 0, 1.5), 4), location_poses((0, 0, 1.5), 2)])
    groups = location_groups(T)
    assert [list(g) for g in groups] == [list(range(8)), list(range(8, 12)), [12, 13]]
    assert location_groups(np.zeros((0, 4, 4))) == []


def test_layout_serves_every_ray_of_the_odd_poses():
    T = location_poses((0, 0, 1.5))
    layout = face_layout(T, location_groups(T), CAMERA)
    assert layout is not None
    f = layout.face
    assert (f.fx, f.fy) == (CAMERA.fx, CAMERA.fy)
    assert (f.cx - CAMERA.cx, f.cy - CAMERA.cy) == (layout.ox, layout.oy)
    assert f.width == CAMERA.width + 2 * layout.ox and f.height == CAMERA.height + 2 * layout.oy
    # the odd view's centre column is the faces' bisector: 45 deg off both axes, 0.75 / cos 45
    # of the focal length above and below the axis in the face
    assert layout.oy >= int(np.ceil(CAMERA.fy * 0.75 / np.cos(np.pi / 4) - CAMERA.cy))
    # every pixel of the odd pose maps inside the face image through one of its neighbours
    u, v = np.meshgrid(np.arange(CAMERA.width), np.arange(CAMERA.height))
    pts = np.stack([u.ravel(), v.ravel()], 1).astype(float)
    rays = np.c_[(pts - [CAMERA.cx, CAMERA.cy]) / [CAMERA.fx, CAMERA.fy], np.ones(len(pts))]
    world = rays @ T[1, :3, :3].T * 3.0 + T[1, :3, 3]
    covered = np.zeros(len(pts), bool)
    for face in (T[0], T[2]):
        uv, z = project(f.K, face, world)
        covered |= (z > 0) & (uv[:, 0] > 0) & (uv[:, 0] < f.width - 1) & (uv[:, 1] > 0) & (uv[:, 1] < f.height - 1)
    assert covered.all()


def test_layout_refused_where_neighbours_cannot_serve():
    T = location_poses((0, 0, 1.5), n=4)  # 90 deg apart: the odd view's centre is 90 deg off both faces
    assert face_layout(T, location_groups(T), CAMERA) is None
    T = location_poses((0, 0, 1.5), n=2)
    assert face_layout(T, location_groups(T), CAMERA) is None


def test_split_features_projects_face_points_into_the_pose():
    rng = np.random.default_rng(0)
    T = location_poses((0.0, 0.0, 1.5))
    layout = face_layout(T, location_groups(T), CAMERA)
    bearings = rng.uniform(0, 2 * np.pi, 4000)
    world = np.c_[3 * np.cos(bearings), 3 * np.sin(bearings), rng.uniform(-1.5, 3.5, 4000)]
    faces = []
    for j in (0, 2):
        uv, z = project(layout.face.K, T[j], world)
        seen = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= layout.face.width - 1) & (uv[:, 1] >= 0) \
            & (uv[:, 1] <= layout.face.height - 1)
        desc = np.tile(np.flatnonzero(seen)[:, None] % 256, (1, 128)).astype(np.uint8)
        faces.append((T[j], ImageFeatures(uv[seen].astype(np.float32), desc, world[seen].astype(np.float32))))
    odd = split_features(layout, T[1], faces)
    uv, z = project(CAMERA.K, T[1], world)
    inside = (z > 0) & (uv[:, 0] >= -0.5) & (uv[:, 0] < CAMERA.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < CAMERA.height - 0.5)
    # each point the odd pose sees comes once, at its own projection
    assert len(odd.points_world) == inside.sum()
    order = np.lexsort(odd.points_world.T)
    want = np.lexsort(world[inside].T)
    np.testing.assert_allclose(odd.points_world[order], world[inside][want], atol=1e-5)
    got_uv, _ = project(CAMERA.K, T[1], odd.points_world.astype(float))
    np.testing.assert_allclose(odd.keypoints, got_uv, atol=1e-3)
    # an even pose: its own face's points inside its crop, shifted by the offsets
    even = split_features(layout, T[0], faces[:1])
    uv0, z0 = project(CAMERA.K, T[0], world)
    inside0 = (z0 > 0) & (uv0[:, 0] >= -0.5) & (uv0[:, 0] < CAMERA.width - 0.5) & (uv0[:, 1] >= -0.5) \
        & (uv0[:, 1] < CAMERA.height - 0.5)
    assert len(even.keypoints) == inside0.sum()


@pytest.fixture(scope="module")
def room_renders():
    scene = load_scene("room")
    lo, hi = scene.bounds[0], scene.bounds[1]
    centre = ((lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 1.5)
    T = location_poses(centre)
    layout = face_layout(T, location_groups(T), CAMERA)
    with Renderer(scene, CAMERA) as pose_r, Renderer(scene, layout.face) as face_r:
        direct = [pose_r.render(t, depth=True, normal=False) for t in T[:3]]
        faces = [face_r.render(t, depth=True, normal=False) for t in T[:3:2]]
    return scene, T, layout, direct, faces


def test_even_pose_is_the_face_crop(room_renders):
    _, T, layout, direct, faces = room_renders
    rgb, depth = crop(layout, faces[0].rgb), crop(layout, faces[0].depth)
    diff = np.abs(rgb.astype(int) - direct[0].rgb)
    assert diff.max() <= 2 and (diff > 0).mean() < 0.1
    np.testing.assert_allclose(depth, direct[0].depth, atol=1e-3)


def test_odd_pose_image_resampled_from_faces(room_renders):
    _, T, layout, direct, faces = room_renders
    rgb, depth = warp_view(layout, T[1], [(T[0], faces[0].rgb, faces[0].depth), (T[2], faces[1].rgb, faces[1].depth)])
    assert np.abs(rgb.astype(float) - direct[1].rgb).mean() < 3.0
    hit = (direct[1].depth > 0) & (depth > 0)
    assert hit.mean() > 0.95
    rel = np.abs(depth[hit] - direct[1].depth[hit]) / direct[1].depth[hit]
    assert np.median(rel) < 0.005 and (rel < 0.05).mean() > 0.97


def test_occlusion_from_faces_agrees_with_the_pose_render(room_renders):
    scene, T, layout, direct, faces = room_renders
    rng = np.random.default_rng(1)
    lo, hi = scene.bounds[0], scene.bounds[1]
    centres = rng.uniform(lo + 0.2, hi - 0.2, (300, 3))
    poses = np.tile(np.eye(4), (300, 1, 1))
    poses[:, :3, 3] = centres
    samples = marker_points(poses, 0.1)
    tol = ImagingConfig().occlusion_tolerance
    for j, used in ((0, [(T[0], faces[0].depth)]), (1, [(T[0], faces[0].depth), (T[2], faces[1].depth)])):
        want = markers_unoccluded(direct[j].depth, T[j], CAMERA.K, samples, tol)
        got = unoccluded_from_faces(layout, T[j], used, samples, tol)
        assert want.sum() > 10
        assert (want == got).mean() > 0.97
