"""Planned tags composited into real RGB-D frames (e.g. 7-Scenes: 640 x 480 colour, registered
depth, camera-to-world poses), as if they had hung on the walls when the frame was taken.

:func:`composite_tags` draws each marker's quad -- the official tag36h11 image with its white
quiet zone (:func:`markerplace.tagfamily.tag_image`), edge :func:`~markerplace.tagfamily.outer_size`,
image row 0 towards the marker's +y, as the renderer's quads (:mod:`markerplace.render.vertices`)
-- into the frame:

1. **Geometry**: exact per-pixel inverse mapping. ``supersample`` x ``supersample`` rays per pixel
   meet the marker plane (z = 0 of ``world_from_marker``, on the wall) and read the tag cell there;
   their mean is the pixel's anti-aliased coverage, so edges lie where
   :func:`markerplace.geometry.project` puts ``marker.corners_world()`` (the corners localization
   assumes). The renderer lifts its quad :data:`~markerplace.render.vertices.MARKER_OFFSET` (4 mm)
   off the wall against z-fighting, so its corners sit ``f * 4 mm * sin(viewing angle) / depth``
   away from these: up to 0.7 px at 2 m and 40 degrees with 7-Scenes' f = 525 px. Rays meeting the plane
   behind the camera cover nothing: tags behind the camera, facing away or out of view are
   skipped with zero stats; one crossing the camera plane is drawn where it is in front.
2. **Occlusion**: the tag's planar depth at each pixel centre (ray-plane intersection) against the
   frame's: a pixel is hidden where the reading is > 0 and nearer than the tag by more than
   ``occlusion_margin_m``. Depth holes (0) follow ``hole_policy`` (see :class:`CompositeConfig`).
3. **Appearance** (:func:`tag_levels`): white and black levels from the light on the surface
   around the tag's footprint, and the light's colour from the whole frame.
4. **Blur**: the coverage is blurred by the frame's Gaussian blur (:func:`estimate_blur_sigma`)
   with :func:`markerplace.imaging.degrade.motion_blur`'s defocus; hidden pixels are masked after
   blurring, so they keep the frame's colour exactly.
5. **Noise**: Gaussian noise of the frame's sigma (:func:`estimate_noise_sigma`) on the tag's
   pixels (:func:`markerplace.imaging.degrade.sensor_noise`, read noise only), drawn from ``rng``.

Images are (H, W, 3) uint8 RGB, row 0 on top; depth is planar (camera z) metres, 0 = no reading;
poses are ``world_from_cam`` with OpenCV axes (:mod:`markerplace.geometry`).

Hand-written because no library composites fiducials by depth: OpenCV does the filtering, and the
warp is a ray-plane intersection in numpy because the same rays give the tag's depth for the
occlusion test and its exact, supersampled coverage.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

from markerplace.geometry import invert
from markerplace.imaging.degrade import GAMMA, motion_blur, sensor_noise
from markerplace.imaging.frame_estimates import estimate_blur_sigma, estimate_noise_sigma, luma
from markerplace.markers import Marker
from markerplace.tagfamily import QUIET_BITS, TAG_BITS, outer_size, tag_cells

log = logging.getLogger(__name__)

__all__ = ["CompositeConfig", "CompositeStats", "composite_tags", "composite_sheet", "tag_levels"]

HOLE_POLICIES = ("visible", "hidden")
NEAR_M = 0.01
"""Plane intersections nearer than this (metres, planar depth) cover nothing."""
PAPER_OVER_WALL = 1.6
"""Linear-light ratio of white paper (about 85 % reflectance) to the median surface around it
(painted walls and furniture, about 50-55 %): a white sheet reads ``1.6 ** (1 / GAMMA)``, about
1.24 times the local median DN."""
INK_OVER_PAPER = 0.055
"""Linear-light ratio of black toner (about 4-5 % reflectance) to white paper: black reads
``0.055 ** (1 / GAMMA)``, about 0.27 times the white DN (lens flare keeps it from 0 too)."""
CAST_STRENGTH = 0.5
"""Share (in log chroma) of the frame's mean colour attributed to the light and given to the tag;
the rest is taken as the colours of what the frame shows."""
SHEET_THUMB_WIDTH = 320
"""Width (pixels) of each frame in :func:`composite_sheet`."""


@dataclass(frozen=True)
class CompositeConfig:
    """How tags are composited.

    Attributes:
        occlusion_margin_m: a depth reading nearer than the tag by more than this (metres) hides
            the tag pixel (covers depth noise of a wall: Kinect-type sensors are within 1-2 cm at
            2-3 m).
        hole_policy: tag pixels over depth holes (reading 0): ``"visible"`` (default) draws them,
            ``"hidden"`` treats them as occluded; both count them. Visible because holes on a
            wall are sensor failures (dark, glossy or oblique surfaces, out of range, the
            projector's shadow at depth edges), not evidence of something nearer: where a tag is
            planned the wall is usually read, and where it is not, the paper would still be in
            the colour image. Counting them lets a caller drop frames with much of a tag over holes.
        match_blur: blur the tag by the frame's estimated Gaussian blur.
        match_brightness: white/black levels and colour cast from the frame (:func:`tag_levels`);
            else white 255, black 0.
        match_noise: add noise of the frame's estimated sigma on the tag's pixels.
        supersample: rays per pixel side for the anti-aliased coverage (>= 1).
    """

    occlusion_margin_m: float = 0.03
    hole_policy: str = "visible"
    match_blur: bool = True
    match_brightness: bool = True
    match_noise: bool = True
    supersample: int = 4

    def __post_init__(self):
        if self.hole_policy not in HOLE_POLICIES:
            raise ValueError(f"hole_policy {self.hole_policy!r} is not one of {HOLE_POLICIES}")
        if int(self.supersample) < 1:
            raise ValueError("supersample must be >= 1")
        if not self.occlusion_margin_m >= 0:
            raise ValueError("occlusion_margin_m must be >= 0")


@dataclass(frozen=True)
class CompositeStats:
    """What compositing did to one marker (all zero when it was skipped: behind the camera,
    facing away or out of view).

    Attributes:
        tag_id: the marker's id.
        covered_px: pixels at least half covered by the quad (quiet zone included).
        hidden_px: covered pixels hidden by a nearer depth reading.
        hole_px: covered pixels over depth holes (reading 0).
        visible_fraction: covered pixels drawn / covered pixels (holes count as drawn under
            ``hole_policy="visible"``); 0 when nothing is covered.
        blur_sigma: Gaussian sigma applied to the tag, pixels.
        gain: the tag's white luminance / 255 (black is :data:`INK_OVER_PAPER` ``** (1/GAMMA)`` of it).
        noise_sigma: standard deviation of the noise added on the tag's pixels, DN.
    """

    tag_id: int
    covered_px: int = 0
    hidden_px: int = 0
    hole_px: int = 0
    visible_fraction: float = 0.0
    blur_sigma: float = 0.0
    gain: float = 0.0
    noise_sigma: float = 0.0


def tag_levels(rgb: np.ndarray, region: np.ndarray, frame: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """White and black RGB levels (DN) of a paper tag over ``region`` of a frame.

    White = ``clip(PAPER_OVER_WALL ** (1/GAMMA) * median over region of max(R, G, B), 0, 255)``:
    the brightest channel of a surface follows the light falling on it whatever the paint's hue
    (a red cabinet's red channel, a white wall's every channel), so white paper under that light
    reads about 1.24 times it; black = ``INK_OVER_PAPER ** (1/GAMMA)`` times white. Both are
    tinted by the light's colour, estimated grey-world from the whole ``frame`` (its mean colour
    over its luminance, raised to :data:`CAST_STRENGTH`, clipped to 0.5..2 per channel), not from
    the surface under the tag (whose colour is its paint's).

    Args:
        rgb: (H, W, 3) uint8 pixels around the tag.
        region: (H, W) bool, pixels around the tag's footprint (all pixels when empty).
        frame: (H', W', 3) uint8 whole frame for the light's colour (None: ``rgb``).
    Returns:
        white (3,), black (3,) float64 DN.
    """
    px = np.asarray(rgb, np.float64)[region] if region.any() else np.asarray(rgb, np.float64).reshape(-1, 3)
    white = float(np.clip(PAPER_OVER_WALL ** (1.0 / GAMMA) * np.median(px.max(axis=1)), 0.0, 255.0))
    whole = np.asarray(rgb if frame is None else frame, np.float64).reshape(-1, 3)
    mean = whole.mean(axis=0)
    cast = np.clip((mean / max(float(luma(mean)), 1.0)) ** CAST_STRENGTH, 0.5, 2.0) if luma(mean) > 0 else np.ones(3)
    cast = cast / cast.max()  # the tint lowers channels, never pushes the brightest past the light's level
    w = np.clip(white * cast, 0.0, 255.0)
    return w, w * INK_OVER_PAPER ** (1.0 / GAMMA)


def _coverage(K: np.ndarray, cam_from_marker: np.ndarray, marker: Marker, box: tuple[int, int, int, int],
              s: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Supersampled coverage of the quad over pixel box (x0, y0, x1, y1), exclusive ends.

    Returns (h, w) float64 each: fraction of sub-pixel rays on the quad, fraction on its white
    cells, and the plane's planar depth at each pixel centre (inf where not in front).
    """
    x0, y0, x1, y1 = box
    R, t = cam_from_marker[:3, :3], cam_from_marker[:3, 3]
    n = R[:, 2]
    Kinv = np.linalg.inv(K)
    half = outer_size(marker.size) / 2.0
    cells = np.pad(tag_cells(marker.tag_id), QUIET_BITS, constant_values=True)
    nb = TAG_BITS + 2 * QUIET_BITS
    bit = 2.0 * half / nb

    def hits(us: np.ndarray, vs: np.ndarray):
        d = Kinv @ np.stack([us.ravel(), vs.ravel(), np.ones(us.size)])  # rays with z = 1
        denom = n @ d
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(np.abs(denom) > 1e-12, (n @ t) / denom, -1.0)
        local = R.T @ (d * lam - t[:, None])
        return lam.reshape(us.shape), local[0].reshape(us.shape), local[1].reshape(us.shape)

    h, w = y1 - y0, x1 - x0
    cov, white = np.zeros((h, w)), np.zeros((h, w))
    offs = (np.arange(s) + 0.5) / s - 0.5
    rows = max(1, 2_000_000 // max(w * s * s, 1))
    for r0 in range(0, h, rows):
        r1 = min(h, r0 + rows)
        vs = (np.arange(y0 + r0, y0 + r1)[:, None] + offs[None, :]).ravel()
        us = (np.arange(x0, x1)[:, None] + offs[None, :]).ravel()
        lam, x, y = hits(*np.meshgrid(us, vs))
        inside = (lam > NEAR_M) & (np.abs(x) < half) & (np.abs(y) < half)
        col = np.clip(np.floor((x + half) / bit), 0, nb - 1).astype(int)
        row = np.clip(np.floor((half - y) / bit), 0, nb - 1).astype(int)
        wh = inside & cells[row, col]
        shape = (r1 - r0, s, w, s)
        cov[r0:r1] = inside.reshape(shape).mean(axis=(1, 3))
        white[r0:r1] = wh.reshape(shape).mean(axis=(1, 3))
    lam, _, _ = hits(*np.meshgrid(np.arange(x0, x1, dtype=float), np.arange(y0, y1, dtype=float)))
    return cov, white, np.where(lam > NEAR_M, lam, np.inf)


def _pixel_box(K: np.ndarray, cam_from_marker: np.ndarray, marker: Marker, shape: tuple[int, int],
               pad: int) -> tuple[int, int, int, int] | None:
    """Pixel box (x0, y0, x1, y1) that holds the quad and ``pad`` pixels around it, clipped to the
    image; None when the tag faces away from the camera or its box misses the image."""
    H, W = shape
    R, t = cam_from_marker[:3, :3], cam_from_marker[:3, 3]
    if float(R[:, 2] @ t) >= 0.0:  # the camera is behind the plane (or in it)
        return None
    half = outer_size(marker.size) / 2.0
    pts = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]]) @ R.T + t
    if np.all(pts[:, 2] <= NEAR_M):
        return None
    if np.all(pts[:, 2] > NEAR_M):
        uv = (pts @ K.T)[:, :2] / pts[:, 2:3]
        lo, hi = np.floor(uv.min(axis=0)) - 1 - pad, np.ceil(uv.max(axis=0)) + 2 + pad
        x0, y0 = int(max(lo[0], 0)), int(max(lo[1], 0))
        x1, y1 = int(min(hi[0], W)), int(min(hi[1], H))
    else:  # crosses the camera plane: the rays decide
        x0, y0, x1, y1 = 0, 0, W, H
    return (x0, y0, x1, y1) if x1 > x0 and y1 > y0 else None


def composite_tags(rgb: np.ndarray, depth_m: np.ndarray, K: np.ndarray, world_from_cam: np.ndarray,
                   markers: Sequence[Marker], config: CompositeConfig = CompositeConfig(),
                   rng: np.random.Generator | None = None) -> tuple[np.ndarray, list[CompositeStats]]:
    """Draw ``markers`` into a real frame as printed tags on its walls (see the module docstring).

    Args:
        rgb: (H, W, 3) uint8 RGB frame.
        depth_m: (H, W) planar depth registered to ``rgb``, metres, 0 = no reading (NaN and inf
            count as 0; convert a dataset's own invalid value, e.g. 7-Scenes' 65535 mm, to 0).
        K: (3, 3) camera matrix.
        world_from_cam: (4, 4) pose of the frame, OpenCV camera axes.
        markers: the tags to draw (world frame); nearer ones are drawn over farther ones.
        config: occlusion, hole and appearance settings.
        rng: random stream of the noise (``np.random.default_rng(0)`` when None).
    Returns:
        the new (H, W, 3) uint8 frame, and one :class:`CompositeStats` per marker, in order.
    """
    rgb = np.asarray(rgb)
    depth = np.asarray(depth_m, np.float64)
    depth = np.where(np.isfinite(depth), depth, 0.0)
    if rgb.ndim != 3 or rgb.shape[2] != 3 or rgb.dtype != np.uint8:
        raise ValueError(f"rgb must be (H, W, 3) uint8, got {rgb.shape} {rgb.dtype}")
    if depth.shape != rgb.shape[:2]:
        raise ValueError(f"depth_m {depth.shape} does not match rgb {rgb.shape[:2]}")
    K = np.asarray(K, np.float64)
    rng = np.random.default_rng(0) if rng is None else rng
    sigma_b = estimate_blur_sigma(rgb) if config.match_blur else 0.0
    sigma_n = estimate_noise_sigma(rgb) if config.match_noise else 0.0
    pad = int(np.ceil(3.0 * sigma_b)) + 2
    cam_from_world = invert(np.asarray(world_from_cam, np.float64))
    out = rgb.copy()
    stats: list[CompositeStats | None] = [None] * len(markers)
    dist = [float(np.linalg.norm(transform[:3, 3])) for transform in
            (cam_from_world @ np.asarray(m.world_from_marker, np.float64) for m in markers)]
    for i in sorted(range(len(markers)), key=lambda j: -dist[j]):
        m = markers[i]
        cam_from_marker = cam_from_world @ np.asarray(m.world_from_marker, np.float64)
        box = _pixel_box(K, cam_from_marker, m, depth.shape, pad)
        cov, white, zc = _coverage(K, cam_from_marker, m, box, int(config.supersample)) if box else (None,) * 3
        if cov is None or not cov.any():
            stats[i] = CompositeStats(int(m.tag_id))
            log.debug("composite: tag %d not in view", m.tag_id)
            continue
        x0, y0, x1, y1 = box
        d = depth[y0:y1, x0:x1]
        hidden = (d > 0) & (d < zc - config.occlusion_margin_m)
        hole = d <= 0
        blocked = hidden | hole if config.hole_policy == "hidden" else hidden
        covered = cov >= 0.5
        n_cov = int(covered.sum())
        if config.match_brightness:
            grow = max(3, int(0.25 * np.sqrt(max(n_cov, 1))))
            near = cv2.dilate((cov > 0).astype(np.uint8), np.ones((2 * grow + 1,) * 2, np.uint8)).astype(bool)
            w_rgb, b_rgb = tag_levels(rgb[y0:y1, x0:x1], near & ~hidden, rgb)
        else:
            w_rgb, b_rgb = np.full(3, 255.0), np.zeros(3)
        if sigma_b > 0.05:
            layers = np.clip(np.rint(np.stack([cov, white, np.zeros_like(cov)], axis=2) * 255), 0, 255).astype(np.uint8)
            blurred = motion_blur(layers, 0.0, 0.0, defocus=sigma_b).astype(np.float64) / 255.0
            cov, white = blurred[..., 0], np.minimum(blurred[..., 1], blurred[..., 0])
        alpha = (cov * ~blocked)[..., None]
        tag = (cov[..., None] * b_rgb + white[..., None] * (w_rgb - b_rgb)) / np.maximum(cov[..., None], 1e-9)
        tag = np.clip(np.rint(tag), 0, 255).astype(np.uint8)
        if sigma_n > 0:
            tag = sensor_noise(tag, rng, 0.0, sigma_n)
        crop = out[y0:y1, x0:x1].astype(np.float64)
        out[y0:y1, x0:x1] = np.clip(np.rint(crop * (1.0 - alpha) + alpha * tag), 0, 255).astype(np.uint8)
        n_hidden, n_hole = int((covered & hidden).sum()), int((covered & hole).sum())
        n_drawn = int((covered & ~blocked).sum())
        stats[i] = CompositeStats(int(m.tag_id), n_cov, n_hidden, n_hole, n_drawn / n_cov if n_cov else 0.0,
                                  float(sigma_b), float(luma(w_rgb) / 255.0), float(sigma_n))
        log.debug("composite: %s", stats[i])
    return out, list(stats)


def composite_sheet(images: list[np.ndarray], titles: list[str], columns: int = 4) -> np.ndarray:
    """Tile frames, each scaled to :data:`SHEET_THUMB_WIDTH` pixels wide under its title, into one
    RGB image for a report (white background, ``columns`` per row).

    Args:
        images: (H_i, W_i, 3) uint8 RGB frames.
        titles: one line per frame.
        columns: frames per row (>= 1).
    Returns:
        (H, W, 3) uint8 RGB.
    """
    if len(images) != len(titles) or not images:
        raise ValueError("composite_sheet needs one title per image and at least one image")
    columns = max(1, min(int(columns), len(images)))
    thumbs = []
    for img in images:
        img = np.asarray(img, np.uint8)
        h = max(1, int(round(img.shape[0] * SHEET_THUMB_WIDTH / img.shape[1])))
        thumbs.append(cv2.resize(img, (SHEET_THUMB_WIDTH, h), interpolation=cv2.INTER_AREA))
    strip, gap = 22, 6
    cell_h = max(t.shape[0] for t in thumbs) + strip
    rows = (len(thumbs) + columns - 1) // columns
    sheet = np.full((rows * (cell_h + gap) + gap, columns * (SHEET_THUMB_WIDTH + gap) + gap, 3), 255, np.uint8)
    for k, (thumb, title) in enumerate(zip(thumbs, titles)):
        y, x = gap + (k // columns) * (cell_h + gap), gap + (k % columns) * (SHEET_THUMB_WIDTH + gap)
        cv2.putText(sheet, str(title), (x + 2, y + strip - 7), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1,
                    cv2.LINE_AA)
        sheet[y + strip:y + strip + thumb.shape[0], x:x + SHEET_THUMB_WIDTH] = thumb
    return sheet
