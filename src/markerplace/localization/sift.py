"""SIFT extraction and lifting of keypoints to 3D with a depth map.

Two presets (docs/design.md section 3):

* :data:`SIFT_SCORING` -- nfeatures 1000, contrastThreshold 0.1, edgeThreshold 5 (planner).
* :data:`SIFT_DEFAULT` -- OpenCV defaults (localization: map and query images).

Keypoints are pixel coordinates ``(x, y)`` in OpenCV's convention (pixel centres at integers).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass

import cv2
import numpy as np

from markerplace.geometry import backproject

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SiftConfig:
    """Parameters of ``cv2.SIFT_create``. Defaults are OpenCV's.

    Attributes:
        nfeatures: keep the best n features (0 = all).
        n_octave_layers: layers per octave (OpenCV default 3).
        contrast_threshold: DoG contrast threshold (default 0.04).
        edge_threshold: edge-response threshold (default 10).
        sigma: Gaussian sigma of the base image (default 1.6).
    """

    nfeatures: int = 0
    n_octave_layers: int = 3
    contrast_threshold: float = 0.04
    edge_threshold: float = 10.0
    sigma: float = 1.6


SIFT_SCORING = SiftConfig(nfeatures=1000, contrast_threshold=0.1, edge_threshold=5)
SIFT_DEFAULT = SiftConfig()

_SIFT_CACHE: dict[tuple[int, SiftConfig], "cv2.SIFT"] = {}


def _sift(config: SiftConfig):
    """One ``cv2.SIFT`` per config per process (keyed by pid so forked workers build their own)."""
    key = (os.getpid(), config)
    sift = _SIFT_CACHE.get(key)
    if sift is None:
        sift = cv2.SIFT_create(
            nfeatures=config.nfeatures,
            nOctaveLayers=config.n_octave_layers,
            contrastThreshold=config.contrast_threshold,
            edgeThreshold=config.edge_threshold,
            sigma=config.sigma,
        )
        _SIFT_CACHE[key] = sift
    return sift


def to_gray(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) RGB or (H, W) uint8 -> (H, W) uint8 gray."""
    image = np.asarray(image)
    if image.ndim == 2:
        return np.ascontiguousarray(image, dtype=np.uint8)
    if image.ndim == 3 and image.shape[2] in (3, 4):
        return cv2.cvtColor(np.ascontiguousarray(image[..., :3], dtype=np.uint8), cv2.COLOR_RGB2GRAY)
    raise ValueError(f"expected an (H, W) or (H, W, 3) image, got shape {image.shape}")


def extract_sift(rgb: np.ndarray, config: SiftConfig = SIFT_DEFAULT) -> tuple[np.ndarray, np.ndarray]:
    """Detect and describe SIFT features.

    Args:
        rgb: (H, W, 3) uint8 RGB image (or (H, W) gray).
        config: detector parameters.

    Returns:
        keypoints (K, 2) float32 pixel ``(x, y)`` and descriptors (K, 128) float32.
    """
    gray = to_gray(rgb)
    kps, desc = _sift(config).detectAndCompute(gray, None)
    if desc is None or len(kps) == 0:
        return np.zeros((0, 2), np.float32), np.zeros((0, 128), np.float32)
    xy = np.array([kp.pt for kp in kps], dtype=np.float32).reshape(-1, 2)
    return xy, np.asarray(desc, dtype=np.float32)


def lift_to_3d(
    keypoints: np.ndarray,
    depth: np.ndarray,
    K: np.ndarray,
    world_from_cam: np.ndarray,
    max_depth: float = 10.0,
    discontinuity_rel: float = 0.05,
    image_size: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Lift pixel keypoints to world points with a planar depth map.

    The depth map must be pixel-aligned with the image the keypoints come from; if it has a
    different resolution (the paper renders depth at half resolution) keypoints are scaled by
    the ratio ``depth.shape / image shape`` where the image shape is ``image_size`` or, when not
    given, read from ``K`` (``2 cx, 2 cy``: right for renders, whose principal point is the image
    centre; a real camera's is not, so callers with real images pass ``image_size``). Depth is read bilinearly when the 2x2 neighbours are all valid and agree
    within ``discontinuity_rel`` (relative); points whose neighbours disagree (depth edges),
    with zero/non-finite depth, or farther than ``max_depth`` metres are dropped.

    Args:
        keypoints: (K, 2) pixel ``(x, y)`` in the image of intrinsics ``K``.
        depth: (H, W) planar depth in metres, 0 where nothing was hit.
        K: (3, 3) camera matrix of the image.
        world_from_cam: (4, 4) camera pose.
        max_depth: points farther than this (metres, planar depth) are invalid.
        discontinuity_rel: maximal relative spread of the 2x2 neighbour depths.
        image_size: (width, height) of the keypoints' image in pixels, or None (``2 cx, 2 cy``).

    Returns:
        points_world (K, 3) float64 (NaN where invalid) and valid (K,) bool.
    """
    kp = np.asarray(keypoints, dtype=np.float64).reshape(-1, 2)
    depth = np.asarray(depth, dtype=np.float64)
    n = len(kp)
    out = np.full((n, 3), np.nan)
    if n == 0:
        return out, np.zeros(0, bool)
    h, w = depth.shape
    img_w, img_h = (2.0 * K[0, 2], 2.0 * K[1, 2]) if image_size is None else (float(image_size[0]), float(image_size[1]))
    sx, sy = w / img_w, h / img_h
    # pixel centres at integers in both images: x_d = (x + 0.5) * s - 0.5
    xd = (kp[:, 0] + 0.5) * sx - 0.5
    yd = (kp[:, 1] + 0.5) * sy - 0.5
    x0 = np.clip(np.floor(xd).astype(int), 0, w - 2)
    y0 = np.clip(np.floor(yd).astype(int), 0, h - 2)
    fx = np.clip(xd - x0, 0.0, 1.0)
    fy = np.clip(yd - y0, 0.0, 1.0)
    d00, d01 = depth[y0, x0], depth[y0, x0 + 1]
    d10, d11 = depth[y0 + 1, x0], depth[y0 + 1, x0 + 1]
    nb = np.stack([d00, d01, d10, d11], axis=1)
    ok = np.all(np.isfinite(nb) & (nb > 0), axis=1)
    with np.errstate(invalid="ignore"):
        spread = nb.max(axis=1) - nb.min(axis=1)
        ok &= spread <= discontinuity_rel * nb.min(axis=1)
    z = (1 - fy) * ((1 - fx) * d00 + fx * d01) + fy * ((1 - fx) * d10 + fx * d11)
    ok &= z <= max_depth
    if np.any(ok):
        out[ok] = backproject(K, world_from_cam, kp[ok], z[ok])
    return out, ok
