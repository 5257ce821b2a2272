"""Localizer and map database on a synthetic textured world (planar warps, no renderer).

World: three textured walls of a 6 m x 5 m room (back wall y = 4, side walls x = -3 and x = 3,
z in [0, 3]); the back wall carries a tag36h11 tag with a known pose. Images are rendered by
warping each wall's texture with its exact homography and z-buffering the analytic depth.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data

from helpers.official_tags import official_square
from markerplace.geometry import Intrinsics, invert, so3_exp, world_from_cam_pose, world_from_marker_pose
from markerplace.localization.database import MapDatabase, map_image_from_rgbd
from markerplace.localization.localizer import LocalizerConfig, SiftPnP
from markerplace.localization.pnp import pose_errors
from markerplace.localization.sift import SIFT_DEFAULT
from markerplace.localization.vlad import VladCodebook
from markerplace.markers import Marker

INTR = Intrinsics()
K = INTR.K
PX_PER_M = 150.0
TAG_ID = 17


class Wall:
    """A textured rectangle: ``world_from_wall`` (x right, y up, z towards viewers), w x h metres."""

    def __init__(self, center, normal, w, h, texture):
        self.T = world_from_marker_pose(np.asarray(center, float), np.asarray(normal, float))
        self.w, self.h = w, h
        self.tex = cv2.resize(texture, (int(w * PX_PER_M), int(h * PX_PER_M)), interpolation=cv2.INTER_LINEAR)

    def wall_from_texture(self) -> np.ndarray:
        """(3, 3): texture pixel (u, v, 1) -> wall-plane (x, y, 1); pixel edges at +-0.5."""
        th, tw = self.tex.shape[:2]
        sx, sy = self.w / tw, self.h / th
        return np.array([[sx, 0, 0.5 * sx - 0.5 * self.w], [0, -sy, 0.5 * self.h - 0.5 * sy], [0, 0, 1]])

    def point(self, u: float, v: float) -> np.ndarray:
        """World point of texture pixel coordinates (u, v)."""
        x, y, _ = self.wall_from_texture() @ np.array([u, v, 1.0])
        return self.T[:3, :3] @ np.array([x, y, 0.0]) + self.T[:3, 3]


def _make_world() -> tuple[list[Wall], Marker]:
    tile = lambda im, nx: np.concatenate([im] * nx, axis=1)  # noqa: E731
    back = Wall([0, 4, 1.5], [0, -1, 0], 6.0, 3.0, np.concatenate([data.astronaut(), cv2.resize(data.coffee(), (512, 512))], axis=1))
    left = Wall([-3, 1.5, 1.5], [1, 0, 0], 5.0, 3.0, tile(data.chelsea(), 2))
    right = Wall([3, 1.5, 1.5], [-1, 0, 0], 5.0, 3.0, np.dstack([data.camera()] * 3)[:, ::-1].copy())
    # paste a 0.5 m tag (plus a white quiet zone) into the back wall's texture
    size = int(0.5 * PX_PER_M)
    u0, v0 = int(3.6 * PX_PER_M), int(0.8 * PX_PER_M)
    tag = official_square(TAG_ID, size)  # the official image, top edge up
    q = size // 6
    back.tex[v0 - q : v0 + size + q, u0 - q : u0 + size + q] = 255
    back.tex[v0 : v0 + size, u0 : u0 + size] = tag[:, :, None]
    center = (back.point(u0 - 0.5, v0 - 0.5) + back.point(u0 + size - 0.5, v0 + size - 0.5)) / 2
    marker = Marker(TAG_ID, size / PX_PER_M, world_from_marker_pose(center, [0, -1, 0]))
    return [back, left, right], marker


def _render(walls: list[Wall], world_from_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) uint8 image and (H, W) planar depth (0 where nothing is hit)."""
    W, H = INTR.width, INTR.height
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
    rgb = np.zeros((H, W, 3), np.uint8)
    depth = np.full((H, W), np.inf)
    for wall in walls:
        cam_from_wall = invert(world_from_cam) @ wall.T
        R, t = cam_from_wall[:3, :3], cam_from_wall[:3, 3]
        Hm = K @ np.column_stack([R[:, 0], R[:, 1], t]) @ wall.wall_from_texture()
        img = cv2.warpPerspective(wall.tex, Hm, (W, H), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        th, tw = wall.tex.shape[:2]
        mask = cv2.warpPerspective(np.ones((th, tw), np.uint8), Hm, (W, H), flags=cv2.INTER_NEAREST) > 0
        n = R[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (n @ t) / (rays @ n)
        hit = mask & (z > 0.05) & (z < depth)
        rgb[hit] = img[hit]
        depth[hit] = z[hit]
    depth[~np.isfinite(depth)] = 0.0
    return rgb, depth


def _tilted(position, yaw_deg, tilt_deg=(0.0, 0.0, 0.0)) -> np.ndarray:
    T = world_from_cam_pose(np.asarray(position, float), np.radians(yaw_deg))
    T[:3, :3] = T[:3, :3] @ so3_exp(np.radians(np.asarray(tilt_deg, float)))
    return T


@pytest.fixture(scope="module")
def world():
    walls, marker = _make_world()
    records = []
    for x in (-1.5, -0.5, 0.5, 1.5):
        for y in (0.0, 1.2):
            for yaw in (60.0, 90.0, 120.0):
                T = _tilted([x, y, 1.5], yaw)
                rgb, depth = _render(walls, T)
                records.append(map_image_from_rgbd(rgb, depth, T, K, SIFT_DEFAULT))
    codebook = VladCodebook.train(np.concatenate([r.descriptors for r in records]), num_clusters=16, seed=0)
    db = MapDatabase.build(records, [marker], codebook)
    return walls, marker, db


def test_synthetic_world_is_consistent(world):
    """The renderer's depth and the tag pose agree with the world geometry."""
    walls, marker, db = world
    T = _tilted([0.0, 1.0, 1.5], 90.0)
    rgb, depth = _render(walls, T)
    assert depth[225, 300] == pytest.approx(3.0, abs=1e-6)  # back wall straight ahead
    from markerplace.localization.tags import detect_tags, pose_from_tag

    dets = detect_tags(rgb)
    assert [d.tag_id for d in dets] == [TAG_ID]
    dt, dr = pose_errors(pose_from_tag(dets[0], marker, K), T)
    assert dt < 0.1 and dr < 3.0, (dt, dr)
    # map images that saw the tag are indexed
    assert TAG_ID in db.tag_index and len(db.tag_index[TAG_ID]) >= 3
    assert db.num_features > 24 * 300


QUERIES = [
    ([0.2, 0.6, 1.45], 95.0, (2.0, -1.0, 3.0)),
    ([-1.0, 0.5, 1.55], 70.0, (-2.0, 1.0, -2.0)),
    ([1.1, 1.0, 1.5], 110.0, (0.0, 2.0, 1.0)),
]


@pytest.mark.parametrize("config", [
    LocalizerConfig(),
    LocalizerConfig(use_tags=False),
    LocalizerConfig(tag_corners=True, num_candidates=5),
], ids=["tags", "no-tags", "tag-corners"])
def test_localizer_recovers_query_pose(world, config):
    walls, _, db = world
    loc = SiftPnP(db, K, config)
    for pos, yaw, tilt in QUERIES:
        T = _tilted(pos, yaw, tilt)
        rgb, _ = _render(walls, T)
        res = loc.localize(rgb)
        assert res.world_from_cam is not None, (pos, yaw)
        dt, dr = pose_errors(res.world_from_cam, T)
        assert dt < 0.05 and dr < 5.0, (pos, yaw, dt, dr)
        assert res.num_inliers >= config.pnp.min_inliers
        assert 0 < len(res.candidates) <= config.num_candidates
        assert set(res.timing) >= {"features", "tags", "retrieval", "matching", "pnp", "total"}


def test_tag_retrieval_puts_tag_observers_first(world):
    walls, _, db = world
    T = _tilted([0.2, 0.6, 1.45], 95.0, (2.0, -1.0, 3.0))
    rgb, _ = _render(walls, T)
    loc = SiftPnP(db, K, LocalizerConfig())
    res = loc.localize(rgb)
    assert res.detected_tag_ids == [TAG_ID]
    first = res.candidates[0]
    assert first in db.tag_index[TAG_ID]
    assert np.linalg.norm(db.poses[first][:3, 3] - T[:3, 3]) <= 2.0
    assert SiftPnP(db, K, LocalizerConfig(use_tags=False)).localize(rgb).detected_tag_ids == []


def test_localizer_fails_on_featureless_query(world):
    _, _, db = world
    res = SiftPnP(db, K).localize(np.full((INTR.height, INTR.width, 3), 127, np.uint8))
    assert res.world_from_cam is None and not res.success
    assert res.num_matches == 0 and res.detected_tag_ids == []


def test_database_build_drops_invalid_points(tmp_path):
    rng = np.random.default_rng(0)
    desc = rng.uniform(0, 50, (30, 128)).astype(np.float32)
    cb = VladCodebook.train(desc, num_clusters=4, seed=0)
    pts = rng.normal(size=(30, 3))
    pts[:10] = np.nan
    db = MapDatabase.build([(np.eye(4), rng.uniform(0, 600, (30, 2)), desc, pts, [3, 5])], [], cb)
    assert db.num_features == 20 and db.tag_index == {3: [0], 5: [0]}


def test_localizer_registry(world):
    """The localizer is chosen by name; the registry's one gives what the class gives."""
    from dataclasses import dataclass

    from markerplace.errors import UserError
    from markerplace.localization.localizer import LOCALIZERS, Localizer, LocalizerSettings, get_localizer

    walls, _, db = world
    assert LOCALIZERS.names() == ("sift_pnp",) and LOCALIZERS["sift_pnp"] is SiftPnP
    with pytest.raises(UserError, match="--localizer 'hloc' is not known: use one of sift_pnp"):
        get_localizer("hloc", db, K)
    loc = get_localizer("sift_pnp", db, K, use_tags=False, num_candidates=4)
    assert loc.config == LocalizerConfig(use_tags=False, num_candidates=4)
    assert SiftPnP(db, K).config == SiftPnP.default_conf == LocalizerConfig()
    pos, yaw, tilt = QUERIES[0]
    rgb, _ = _render(walls, _tilted(pos, yaw, tilt))
    a, b = loc.localize(rgb), SiftPnP(db, K, LocalizerConfig(use_tags=False, num_candidates=4)).localize(rgb)
    assert a.candidates == b.candidates and np.array_equal(a.world_from_cam, b.world_from_cam)

    @dataclass(frozen=True)
    class Conf(LocalizerSettings):
        pass

    @dataclass(frozen=True)
    class Bare:
        use_tags: bool = True

    class Second(Localizer):
        name, summary, Config, default_conf = "second", "a second one", Conf, Conf()

    class Unsettled(Localizer):  # a Config without the settings the testbed sets
        name, summary, Config, default_conf = "unsettled", "no LocalizerSettings", Bare, Bare()

    class Stranger:  # not a Localizer
        name, summary, Config, default_conf = "stranger", "no base class", Conf, Conf()

    for cls in (Unsettled, Stranger):
        with pytest.raises(ValueError, match="subclasses Localizer and its Config subclasses LocalizerSettings"):
            LOCALIZERS.register(cls)
    try:
        LOCALIZERS.register(Second)
        assert LOCALIZERS.names() == ("sift_pnp", "second")
    finally:
        del LOCALIZERS["second"]
