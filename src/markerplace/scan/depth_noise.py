"""Depth-sensor noise model of a simulated RGB-D scan: rendered planar depth in, Kinect-like
depth out.

A Kinect-like camera (320x240, fx = fy = 262.5 px: 63 x 49 deg, half the Kinect v1 resolution)
rendered by :class:`markerplace.render.renderer.Renderer` (planar depth, world normals). Noise
model, per frame, from these sources:

* axial noise (Nguyen, Izadi, Lovell, "Modeling Kinect Sensor Noise for Improved 3D
  Reconstruction and Tracking", 3DIMPVT 2012, eq. 6): sigma_z(z, theta) = 0.0012 + 0.0019
  (z - 0.4)^2 + 0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2 metres, z in metres, theta the
  angle between the surface normal and the viewing ray (clipped at 80 deg);
* lateral noise (same paper, eq. 5): sigma_L = 0.8 + 0.035 theta / (pi/2 - theta) pixels at the
  Kinect's 585 px focal length, scaled to ours; each pixel takes the depth of a neighbour offset
  by the rounded Gaussian jitter;
* depth quantization of a disparity sensor (Khoshelham & Elberink, Sensors 2012): inverse depth
  in steps of 2.85e-3 per metre (2.9 mm at 1 m, 2.6 cm at 3 m), then whole millimetres;
* dropouts: grazing angles (probability rising linearly from 0 at 65 deg to 1 at 78 deg),
  depth discontinuities (a jump over 5 % of the depth to a neighbour, dilated by one pixel),
  random speckle (small discs), nothing nearer than 0.4 m or beyond 5 m, and no reading on glass
  (parts with ``MeshPart.transparent`` that are the first surface along the ray, found with a
  second renderer that draws only the transparent parts, opaque; the main renderer's depth is
  what lies behind glass, which ``glass_dropout=False`` keeps).

Depth images are (H, W) planar depth (camera z) in metres, 0 = no reading; normals are (H, W, 3)
world-frame; poses are (4, 4) ``world_from_cam``. :func:`to_depth_png` stores metres as uint16
in ``DEPTH_SCALE`` units per metre (millimetres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from markerplace.geometry import Intrinsics

DEPTH_SCALE = 1000.0
"""Simulated depth images are stored in millimetres."""


@dataclass(frozen=True)
class DepthNoiseConfig:
    """Depth sensor model (see the module docstring for the sources).

    Attributes:
        min_range, max_range: readings outside [min, max] metres are dropped (default 0.4, 5.0).
        axial_a, axial_b, axial_z0, axial_angle: Nguyen et al. 2012 axial noise coefficients
            sigma = a + b (z - z0)^2 + angle / sqrt(z) * theta^2 / (pi/2 - theta)^2 (metres).
        lateral_px, lateral_angle, lateral_focal: Nguyen et al. lateral noise sigma_L =
            lateral_px + lateral_angle * theta / (pi/2 - theta) pixels at focal length
            ``lateral_focal`` px (scaled by fx / lateral_focal); 0 turns jitter off.
        disparity_step: inverse-depth quantization step, 1/metres (default 2.85e-3; 0 = off).
        grazing_start_deg, grazing_end_deg: dropout probability rises linearly from 0 to 1
            between these incidence angles (default 65, 78).
        edge_rel: a depth jump to a 4-neighbour above this fraction of the depth is a
            discontinuity (default 0.05); both sides and ``edge_dilate_px`` pixels around drop.
        speckle_rate, speckle_radius_px: seeds per pixel and radius of random dropout discs
            (default 1e-3, 2 px: about 1.3 % of the pixels).
        glass_dropout: no reading where a transparent part is the first surface (default
            True); False keeps the renderer's depth of what lies behind the glass.
    """

    min_range: float = 0.4
    max_range: float = 5.0
    axial_a: float = 0.0012
    axial_b: float = 0.0019
    axial_z0: float = 0.4
    axial_angle: float = 0.0001
    lateral_px: float = 0.8
    lateral_angle: float = 0.035
    lateral_focal: float = 585.0
    disparity_step: float = 2.85e-3
    grazing_start_deg: float = 65.0
    grazing_end_deg: float = 78.0
    edge_rel: float = 0.05
    edge_dilate_px: int = 1
    speckle_rate: float = 1e-3
    speckle_radius_px: int = 2
    glass_dropout: bool = True



def camera_rays(intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) unit viewing rays in the camera frame."""
    v, u = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width].astype(np.float64)
    r = np.stack([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones_like(u)], axis=2)
    return r / np.linalg.norm(r, axis=2, keepdims=True)


def _disc(radius: int) -> np.ndarray:
    y, x = np.mgrid[-radius : radius + 1, -radius : radius + 1]
    return (x * x + y * y <= radius * radius + 0.5).astype(np.uint8)


def noisy_depth(depth: np.ndarray, normal: np.ndarray, intrinsics: Intrinsics, world_from_cam: np.ndarray,
                rng: np.random.Generator, cfg: DepthNoiseConfig = DepthNoiseConfig(),
                glass: np.ndarray | None = None, rays: np.ndarray | None = None) -> np.ndarray:
    """Apply the sensor model to a rendered planar depth image.

    Args:
        depth: (H, W) float planar depth, metres, 0 = nothing hit.
        normal: (H, W, 3) world-frame unit normals (any sign; 0 where nothing was hit).
        intrinsics: the camera model of the images.
        world_from_cam: (4, 4) pose of the frame.
        rng: random generator (the only source of randomness).
        cfg: noise settings.
        glass: (H, W) bool, pixels whose first surface is glass (no reading), or None.
        rays: (H, W, 3) camera-frame unit rays of ``intrinsics`` (computed when None).

    Returns:
        (H, W) float32 planar depth, metres, 0 = no reading.
    """
    import cv2

    H, W = depth.shape
    z = np.asarray(depth, dtype=np.float64)
    valid = z > 0
    if glass is not None:
        valid &= ~glass
    if rays is None:
        rays = camera_rays(intrinsics)
    d_world = rays @ np.asarray(world_from_cam, dtype=np.float64)[:3, :3].T
    cos_t = np.abs(np.einsum("hwc,hwc->hw", d_world, np.asarray(normal, dtype=np.float64)))
    theta = np.arccos(np.clip(cos_t, 0.0, 1.0))
    theta_c = np.minimum(theta, math.radians(80.0))
    # dropouts: grazing incidence, discontinuities, speckle, range
    g0, g1 = math.radians(cfg.grazing_start_deg), math.radians(cfg.grazing_end_deg)
    p_graze = np.clip((theta - g0) / max(g1 - g0, 1e-9), 0.0, 1.0)
    drop = rng.random((H, W)) < p_graze
    edge = np.zeros((H, W), dtype=bool)
    both = valid[:, 1:] & valid[:, :-1]
    jump = both & (np.abs(z[:, 1:] - z[:, :-1]) > cfg.edge_rel * np.minimum(z[:, 1:], z[:, :-1]))
    edge[:, 1:] |= jump
    edge[:, :-1] |= jump
    both = valid[1:, :] & valid[:-1, :]
    jump = both & (np.abs(z[1:, :] - z[:-1, :]) > cfg.edge_rel * np.minimum(z[1:, :], z[:-1, :]))
    edge[1:, :] |= jump
    edge[:-1, :] |= jump
    if cfg.edge_dilate_px > 0 and edge.any():
        edge = cv2.dilate(edge.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=int(cfg.edge_dilate_px)) > 0
    drop |= edge
    if cfg.speckle_rate > 0:
        seeds = (rng.random((H, W)) < cfg.speckle_rate).astype(np.uint8)
        drop |= cv2.dilate(seeds, _disc(int(cfg.speckle_radius_px))) > 0
    valid &= ~drop & (z >= cfg.min_range) & (z <= cfg.max_range)
    # lateral noise: each pixel reads a jittered neighbour
    if cfg.lateral_px > 0:
        sigma = (cfg.lateral_px + cfg.lateral_angle * theta_c / (math.pi / 2 - theta_c)) * (intrinsics.fx / cfg.lateral_focal)
        du = np.clip(np.rint(rng.standard_normal((H, W)) * sigma), -2, 2).astype(np.int64)
        dv = np.clip(np.rint(rng.standard_normal((H, W)) * sigma), -2, 2).astype(np.int64)
        vv, uu = np.mgrid[0:H, 0:W]
        sv, su = np.clip(vv + dv, 0, H - 1), np.clip(uu + du, 0, W - 1)
        z, valid, theta_c = z[sv, su], valid[sv, su], theta_c[sv, su]
    # axial noise (Nguyen et al. 2012)
    zc = np.where(valid, z, 1.0)
    sigma_z = (cfg.axial_a + cfg.axial_b * (zc - cfg.axial_z0) ** 2
               + cfg.axial_angle / np.sqrt(zc) * theta_c**2 / (math.pi / 2 - theta_c) ** 2)
    zn = zc + rng.standard_normal((H, W)) * sigma_z
    if cfg.disparity_step > 0:
        q = np.rint(1.0 / (np.maximum(zn, 1e-3) * cfg.disparity_step))
        zn = 1.0 / (np.maximum(q, 1.0) * cfg.disparity_step)
    valid &= (zn >= cfg.min_range) & (zn <= cfg.max_range)
    return np.where(valid, zn, 0.0).astype(np.float32)


def to_depth_png(depth_m: np.ndarray, scale: float = DEPTH_SCALE) -> np.ndarray:
    """(H, W) metres -> uint16 in ``scale`` units per metre (0 stays 0; beyond 65535 units -> 0)."""
    d = np.rint(np.asarray(depth_m, dtype=np.float64) * scale)
    return np.where((d > 0) & (d <= 65535), d, 0).astype(np.uint16)



__all__ = ["DEPTH_SCALE", "DepthNoiseConfig", "camera_rays", "noisy_depth", "to_depth_png"]
