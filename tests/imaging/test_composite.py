"""Tags composited into frames (markerplace.imaging.composite, its estimators in
markerplace.imaging.frame_estimates): against the project's renderer
(the real detector finds the same id and corners), exact edges, depth occlusion and holes,
decoding under the frame's estimated blur and noise, the estimators themselves, determinism."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from markerplace.geometry import Intrinsics, backproject, project, world_from_cam_pose, world_from_marker_pose
from markerplace.imaging.composite import CompositeConfig, CompositeStats, composite_sheet, composite_tags
from markerplace.imaging.frame_estimates import estimate_blur_sigma, estimate_noise_sigma
from markerplace.localization.tags import detect_tags
from markerplace.markers import Marker
from markerplace.tagfamily import outer_size

INTR = Intrinsics(640, 480, 525.0, 525.0, 319.5, 239.5)  # 7-Scenes' colour camera
K = INTR.K
RAW = CompositeConfig(match_blur=False, match_brightness=False, match_noise=False)


def wall_depth(pose: np.ndarray, x_wall: float, shape=(INTR.height, INTR.width)) -> np.ndarray:
    """(H, W) planar depth of the plane x = ``x_wall`` seen from ``pose``."""
    vs, us = np.mgrid[:shape[0], :shape[1]].astype(float)
    rays = np.stack([(us - K[0, 2]) / K[0, 0], (vs - K[1, 2]) / K[1, 1], np.ones_like(us)], axis=-1)
    dx = rays @ pose[:3, :3].T[:, 0]
    return np.where(dx > 1e-9, (x_wall - pose[0, 3]) / np.where(dx > 1e-9, dx, 1.0), 0.0)


def box_coverage(shape, x0, y0, x1, y1) -> np.ndarray:
    """(H, W) exact area coverage of pixels (centres at integers) by the box [x0, x1] x [y0, y1]."""
    def overlap(n, a, b):
        c = np.arange(n)
        return np.clip(np.minimum(b, c + 0.5) - np.maximum(a, c - 0.5), 0.0, 1.0)
    return np.outer(overlap(shape[0], y0, y1), overlap(shape[1], x0, x1))


def textured_frame(seed: int, blur: float = 0.0, noise: float = 0.0, shape=(INTR.height, INTR.width)) -> np.ndarray:
    """A frame like a photo of a room: smooth shading and colour, a few sharp-edged, area-sampled
    patches, then Gaussian ``blur`` (pixels) and Gaussian ``noise`` (DN)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    img = cv2.resize(rng.uniform(90, 170, (6, 8, 3)).astype(np.float32), (W, H), interpolation=cv2.INTER_CUBIC)
    img = img.astype(np.float64)
    for _ in range(14):
        x0, y0 = rng.uniform(0, W - 40), rng.uniform(0, H - 40)
        cov = box_coverage(shape, x0, y0, x0 + rng.uniform(25, 120), y0 + rng.uniform(25, 120))[..., None]
        img = img * (1 - cov) + cov * rng.uniform(30, 230, 3)
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    img = img + noise * rng.standard_normal(img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def facing_marker(tag_id=7, size=0.2, centre=(3.0, 0.1, 1.5)) -> Marker:
    return Marker(tag_id, size, world_from_marker_pose(np.array(centre, float), np.array([-1.0, 0.0, 0.0])))


def outer_quad_uv(marker: Marker, pose: np.ndarray) -> np.ndarray:
    """(4, 2) pixels of the drawn quad's corners (quiet zone included)."""
    h = outer_size(marker.size) / 2
    local = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]])
    return project(K, pose, local @ marker.world_from_marker[:3, :3].T + marker.position)[0]


# ------------------------------------------------------------------------------- the renderer
@pytest.fixture(scope="module")
def rendered():
    """``tiny``'s south wall with a tag, rendered with the tag (reference) and without, from a
    near-facing (15 degrees) and an oblique (31 degrees) pose, 7-Scenes intrinsics. The renderer lifts
    its quad 4 mm off the wall: its corners sit up to f * 4 mm * sin(angle) / depth (0.5 px here)
    from the projection of the marker corners, where the composite puts them."""
    from markerplace.render.renderer import Renderer
    from markerplace.scene import load_scene

    out = []
    with Renderer(load_scene("tiny"), INTR) as r:
        probe = world_from_cam_pose(np.array([1.9, 1.8, 1.5]), -np.pi / 2)
        wall = backproject(K, probe, np.array([[319.5, 239.5]]), r.render(probe, normal=False).depth[240:241, 320])[0]
        marker = Marker(42, 0.2, world_from_marker_pose(wall, np.array([0.0, 1.0, 0.0])))
        for offset, turn in (((0.5, 1.9, -0.1), 0.1), ((1.1, 1.8, 0.1), -0.05)):
            cam = wall + np.array(offset)
            d = wall - cam
            pose = world_from_cam_pose(cam, np.arctan2(d[1], d[0]) + turn)
            r.set_markers([])
            plain = r.render(pose, normal=False)
            r.set_markers([marker])
            out.append((pose, plain, r.render(pose, normal=False).rgb))
    return marker, out


@pytest.mark.parametrize("view", [0, 1])
def test_composite_into_a_render_detects_like_the_rendered_tag(rendered, view):
    marker, views = rendered
    pose, plain, reference = views[view]
    out, stats = composite_tags(plain.rgb, plain.depth, K, pose, [marker], CompositeConfig(),
                                np.random.default_rng(0))
    assert stats[0].tag_id == 42 and stats[0].covered_px > 1000 and stats[0].visible_fraction == 1.0
    expected, _ = project(K, pose, marker.corners_world())
    ref, got = detect_tags(reference), detect_tags(out)
    assert [d.tag_id for d in ref] == [d.tag_id for d in got] == [42]
    err_ref = np.linalg.norm(got[0].corners - ref[0].corners, axis=1)
    err_proj = np.linalg.norm(got[0].corners - expected, axis=1)
    assert err_ref.max() < 1.0 and err_proj.max() < 1.0, (err_ref, err_proj)
    # outside the tag's quad (and its blur margin) the frame is untouched
    pad = int(np.ceil(3 * stats[0].blur_sigma)) + 3
    quad = outer_quad_uv(marker, pose)
    lo, hi = np.floor(quad.min(axis=0)).astype(int) - pad, np.ceil(quad.max(axis=0)).astype(int) + pad + 1
    far = np.ones(out.shape[:2], bool)
    far[max(lo[1], 0):hi[1], max(lo[0], 0):hi[0]] = False
    assert np.array_equal(out[far], plain.rgb[far])


# ------------------------------------------------------------------------------- exact edges
def test_black_square_corners_land_within_a_quarter_pixel_of_the_projection():
    """Head-on, the edges are axis-aligned: each edge's sub-pixel position is the summed
    coverage across it (exact for area sampling), read in many rows and columns."""
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    for centre in ((3.0, 0.137, 1.471), (2.4, -0.3115, 1.6083)):
        marker = facing_marker(size=0.24, centre=centre)
        frame = np.full((INTR.height, INTR.width, 3), 255, np.uint8)  # white: only the black square shows
        out, _ = composite_tags(frame, wall_depth(pose, centre[0]), K, pose, [marker], RAW)
        dark = 1.0 - out[..., 1].astype(float) / 255.0
        uv, _ = project(K, pose, marker.corners_world())  # BL, BR, TR, TL
        left, right, top, bottom = uv[0, 0], uv[1, 0], uv[2, 1], uv[0, 1]
        rows = np.arange(int(top) + 3, int(bottom) - 2)
        cols = np.arange(int(left) + 3, int(right) - 2)
        # the black border is 1 bit wide: sum darkness from the white quiet zone into it
        bit = (right - left) / 8.0
        a, b = int(np.floor(left - 2)), int(np.floor(left + 0.5 * bit))
        got_left = np.mean([(a - 0.5) + (b - a + 1) - dark[r, a:b + 1].sum() for r in rows])
        a, b = int(np.ceil(top - 2)), int(np.floor(top + 0.5 * bit))
        got_top = np.mean([(a - 0.5) + (b - a + 1) - dark[a:b + 1, c].sum() for c in cols])
        a, b = int(np.ceil(right - 0.5 * bit)), int(np.ceil(right + 2))
        got_right = np.mean([(a - 0.5) + dark[r, a:b + 1].sum() for r in rows])
        a, b = int(np.ceil(bottom - 0.5 * bit)), int(np.ceil(bottom + 2))
        got_bottom = np.mean([(a - 0.5) + dark[a:b + 1, c].sum() for c in cols])
        errs = np.abs(np.array([got_left - left, got_right - right, got_top - top, got_bottom - bottom]))
        assert errs.max() < 0.25, errs


# ------------------------------------------------------------------------------- occlusion
def _occlusion_case(hole_policy: str):
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    marker = facing_marker(size=0.3, centre=backproject(K, pose, np.array([[320.0, 240.0]]), np.array([2.5]))[0])
    depth = wall_depth(pose, 2.5)
    uv = outer_quad_uv(marker, pose)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    assert np.all(np.abs((np.r_[lo, hi] % 1.0) - 0.5) < 0.3)  # edges clear of pixel centres
    vs, us = np.mgrid[:INTR.height, :INTR.width]
    covered = (us > lo[0]) & (us < hi[0]) & (vs > lo[1]) & (vs < hi[1])
    mid = int(round((lo[0] + hi[0]) / 2))
    depth[:, :mid] = 1.2  # a person in front of the left half
    depth[250:270, mid:mid + 5] = 2.5 - 0.031  # just past the margin: hidden
    holes = (us > mid + 8) & (us < mid + 20) & (vs > 180) & (vs < 260)
    depth[holes] = 0.0
    depth[(us > mid + 30) & (vs > 200) & (vs < 210)] = 2.5 - 0.02  # within the margin: not hidden
    frame = textured_frame(3, blur=1.0, noise=3.0)
    out, stats = composite_tags(frame, depth, K, pose, [marker], CompositeConfig(hole_policy=hole_policy),
                                np.random.default_rng(5))
    hidden = (depth > 0) & (depth < 2.5 - 0.03) & covered
    return frame, out, stats[0], covered, hidden, holes & covered


@pytest.mark.parametrize("hole_policy", ["visible", "hidden"])
def test_nearer_depth_hides_tag_pixels_and_holes_follow_the_policy(hole_policy):
    frame, out, st, covered, hidden, holes = _occlusion_case(hole_policy)
    assert st.covered_px == covered.sum()
    assert st.hidden_px == hidden.sum() > 0.4 * covered.sum()
    assert st.hole_px == holes.sum() > 0
    blocked = hidden | (holes if hole_policy == "hidden" else False)
    assert st.visible_fraction == pytest.approx(1.0 - blocked.sum() / covered.sum())
    assert np.array_equal(out[blocked], frame[blocked])  # hidden pixels keep the frame's colour
    drawn = covered & ~blocked
    assert (np.abs(out[drawn].astype(int) - frame[drawn]).max(axis=1) > 0).mean() > 0.9
    if hole_policy == "visible":
        assert (np.abs(out[holes].astype(int) - frame[holes]).max(axis=1) > 0).mean() > 0.9


def test_fully_hidden_or_out_of_view_tags_are_skipped():
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    marker = facing_marker(size=0.3, centre=(2.5, 0.0, 1.5))
    frame = textured_frame(4, blur=0.8, noise=2.0)
    near = np.full(frame.shape[:2], 1.0)
    out, stats = composite_tags(frame, near, K, pose, [marker], CompositeConfig(), np.random.default_rng(0))
    assert np.array_equal(out, frame) and stats[0].visible_fraction == 0.0 and stats[0].hidden_px == stats[0].covered_px
    assert detect_tags(out) == []
    behind = facing_marker(centre=(-2.0, 0.0, 1.5))
    away = Marker(8, 0.2, world_from_marker_pose(np.array([3.0, 0.0, 1.5]), np.array([1.0, 0.0, 0.0])))
    aside = facing_marker(centre=(3.0, 5.0, 1.5))
    out, stats = composite_tags(frame, wall_depth(pose, 3.0), K, pose, [behind, away, aside])
    assert np.array_equal(out, frame)
    assert stats == [CompositeStats(7), CompositeStats(8), CompositeStats(7)]


# ------------------------------------------------------------------------------- degradations
@pytest.mark.parametrize("blur, noise, size", [(1.2, 4.0, 0.16), (2.0, 6.0, 0.3)])
def test_tag_in_a_blurred_noisy_textured_frame_still_decodes(blur, noise, size):
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), np.radians(12))
    marker = facing_marker(tag_id=213, size=size, centre=(2.6, 0.3, 1.55))
    frame = textured_frame(11, blur=blur, noise=noise)
    out, stats = composite_tags(frame, wall_depth(pose, 2.6), K, pose, [marker], CompositeConfig(),
                                np.random.default_rng(2))
    st = stats[0]
    assert st.blur_sigma == pytest.approx(blur, rel=0.3) and st.noise_sigma == pytest.approx(noise, rel=0.2)
    assert 0.3 < st.gain <= 1.0
    dets = detect_tags(out)
    assert [d.tag_id for d in dets] == [213]
    expected, _ = project(K, pose, marker.corners_world())
    assert np.linalg.norm(dets[0].corners - expected, axis=1).max() < 1.0


def test_brightness_follows_the_surroundings():
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    marker = facing_marker(size=0.3, centre=(2.5, 0.0, 1.5))
    depth = wall_depth(pose, 2.5)
    levels = []
    for value in ((60, 60, 60), (140, 120, 100)):
        frame = np.full((INTR.height, INTR.width, 3), value, np.uint8)
        out, st = composite_tags(frame, depth, K, pose, [marker], CompositeConfig(match_noise=False))
        levels.append((st[0].gain, out.reshape(-1, 3).max(axis=0), out.reshape(-1, 3).min(axis=0)))
    (g_dark, w_dark, b_dark), (g_warm, w_warm, b_warm) = levels
    assert g_dark * 255 == pytest.approx(60 * 1.6 ** (1 / 2.2), abs=1.0)
    assert b_dark.max() == pytest.approx(w_dark.max() * 0.055 ** (1 / 2.2), abs=1.5)
    assert w_warm[0] > w_warm[1] > w_warm[2]  # the warm cast carries over


def test_tag_pixels_get_the_frames_noise():
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    marker = facing_marker(size=0.5, centre=(2.0, 0.0, 1.5))
    rng = np.random.default_rng(4)
    frame = np.clip(np.rint(120 + 5.0 * rng.standard_normal((INTR.height, INTR.width, 3))), 0, 255).astype(np.uint8)
    out, stats = composite_tags(frame, wall_depth(pose, 2.0), K, pose, [marker], rng=np.random.default_rng(1))
    assert stats[0].blur_sigma < 0.1 and stats[0].noise_sigma == pytest.approx(5.0, rel=0.1)
    inner = (slice(240 - 60, 240 + 60), slice(320 - 60, 320 + 60))  # inside the 131 px black square
    assert estimate_noise_sigma(out[inner]) == pytest.approx(5.0, rel=0.15)
    quiet, _ = composite_tags(frame, wall_depth(pose, 2.0), K, pose, [marker], CompositeConfig(match_noise=False))
    assert estimate_noise_sigma(quiet[inner]) < 0.5


# ------------------------------------------------------------------------------- estimators
def edge_image(seed: int, shape=(240, 320), round_: bool = False) -> np.ndarray:
    """Sharp, area-sampled step edges on grey: large rectangles (exact coverage), or discs
    (every orientation, sampled 8x)."""
    rng = np.random.default_rng(seed)
    H, W = shape
    if round_:
        S = 8
        big = np.full((H * S, W * S), 128.0, np.float32)
        yy, xx = np.ogrid[:H * S, :W * S]
        for _ in range(6):
            cx, cy, r = rng.uniform(50, W - 50), rng.uniform(50, H - 50), rng.uniform(20, 45)
            big[((xx + 0.5) / S - 0.5 - cx) ** 2 + ((yy + 0.5) / S - 0.5 - cy) ** 2 < r * r] = rng.uniform(20, 235)
        return cv2.resize(big, (W, H), interpolation=cv2.INTER_AREA).astype(np.float64)
    img = np.full(shape, 128.0)
    for _ in range(10):
        x0, y0 = rng.uniform(0, W - 50), rng.uniform(0, H - 50)
        cov = box_coverage(shape, x0, y0, x0 + rng.uniform(40, 140), y0 + rng.uniform(40, 140))
        img = img * (1 - cov) + cov * rng.uniform(20, 235)
    return img


@pytest.mark.parametrize("sigma", [0.7, 1.0, 1.5, 2.5, 4.0])
@pytest.mark.parametrize("noise, round_", [(0.0, False), (2.0, False), (2.0, True)])
def test_blur_estimator_recovers_a_known_gaussian(sigma, noise, round_):
    rng = np.random.default_rng(int(sigma * 10))
    img = cv2.GaussianBlur(edge_image(int(sigma * 10), round_=round_), (0, 0), sigma)
    img = img + noise * rng.standard_normal(img.shape)
    est = estimate_blur_sigma(np.clip(np.rint(img), 0, 255).astype(np.uint8))
    assert est == pytest.approx(sigma, rel=0.3)


def test_blur_estimator_reads_sharp_and_blank_images_as_sharp():
    for round_ in (False, True):  # axis-aligned edges read about 0.34 px, round ones 0
        assert estimate_blur_sigma(np.clip(np.rint(edge_image(1, round_=round_)), 0, 255).astype(np.uint8)) < 0.4
    assert estimate_blur_sigma(np.full((100, 100, 3), 90, np.uint8)) == 0.0


@pytest.mark.parametrize("sigma", [1.5, 3.0, 6.0])
def test_noise_estimator_recovers_a_known_sigma_on_textured_frames(sigma):
    frame = textured_frame(21, blur=1.0, noise=sigma)
    assert estimate_noise_sigma(frame) == pytest.approx(sigma, rel=0.15)
    assert estimate_noise_sigma(textured_frame(21, blur=1.0)) < 0.5


# ------------------------------------------------------------------------------- determinism, sheet
def test_same_seed_same_image():
    pose = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    markers = [facing_marker(tag_id=5, centre=(2.5, 0.3, 1.5)), facing_marker(tag_id=6, centre=(2.5, -0.4, 1.5))]
    frame, depth = textured_frame(8, blur=1.0, noise=3.0), wall_depth(pose, 2.5)
    a, sa = composite_tags(frame, depth, K, pose, markers, rng=np.random.default_rng(9))
    b, sb = composite_tags(frame, depth, K, pose, markers, rng=np.random.default_rng(9))
    c, _ = composite_tags(frame, depth, K, pose, markers, rng=np.random.default_rng(10))
    assert np.array_equal(a, b) and sa == sb and not np.array_equal(a, c)
    assert [s.tag_id for s in sa] == [5, 6]


def test_config_rejects_unknown_policies():
    with pytest.raises(ValueError):
        CompositeConfig(hole_policy="fill")
    with pytest.raises(ValueError):
        CompositeConfig(supersample=0)


def test_composite_sheet_tiles_frames_under_titles():
    frames = [np.random.default_rng(s).integers(0, 255, (480, 640, 3), dtype=np.uint8) for s in range(5)]
    sheet = composite_sheet(frames, [f"frame {i}" for i in range(5)], columns=2)
    assert sheet.dtype == np.uint8 and sheet.ndim == 3
    assert sheet.shape[1] == 2 * 320 + 3 * 6 and sheet.shape[0] == 3 * (240 + 22 + 6) + 6
    with pytest.raises(ValueError):
        composite_sheet(frames, ["one title"])
