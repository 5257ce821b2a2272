"""Blur and noise of a real frame, measured from the frame alone: what
:mod:`markerplace.imaging.composite` gives a tag so it looks taken by the same camera.

Images are (H, W, 3) RGB or (H, W) gray in 8-bit digital numbers (DN); sigmas are pixels
(blur) or DN (noise). Hand-written: OpenCV filters, no installed library estimates either.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

__all__ = ["luma", "estimate_noise_sigma", "estimate_blur_sigma"]

BLUR_PROBE = 1.0
"""Gaussian pre-smoothing (pixels) of the blur estimator's gradients."""
BLUR_REBLUR = 2.0
"""Known Gaussian (pixels) the blur estimator re-blurs with."""
BLUR_SELECT = 3.0
"""Gaussian (pixels) of the smooth gradients whose ridges pick the edge pixels."""
EDGE_FLOOR_DN = 3.0
"""Weakest gradient (DN per pixel) an edge pixel of the blur estimator may have."""


def luma(rgb: np.ndarray) -> np.ndarray:
    """Rec. 601 luminance of (..., 3) RGB values (OpenCV's RGB2GRAY weights)."""
    return np.asarray(rgb, np.float64) @ np.array([0.299, 0.587, 0.114])


def estimate_noise_sigma(image: np.ndarray) -> float:
    """Standard deviation (DN) of a frame's additive noise, Immerkaer's method made robust.

    Each channel is filtered with Immerkaer's kernel ``[[1, -2, 1], [-2, 4, -2], [1, -2, 1]]``
    (the difference of two Laplacians: zero on constant and linear shading, ``6 sigma`` standard
    deviation on white noise) and the median absolute response divided by ``0.6745 * 6`` (the
    MAD of a Gaussian); the median (not Immerkaer's mean) ignores the edges and texture that
    cover fewer than half of the pixels. Channels are averaged. Signal-dependent noise is
    measured at the median signal.

    Args:
        image: (H, W, 3) or (H, W) image, any dtype of DN.
    Returns:
        sigma in DN (>= 0).
    """
    img = np.asarray(image, np.float32)
    chans = [img] if img.ndim == 2 else [img[..., c] for c in range(img.shape[2])]
    kernel = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], np.float32)
    sig = [float(np.median(np.abs(cv2.filter2D(c, -1, kernel)[1:-1, 1:-1]))) / (0.6745 * 6.0) for c in chans]
    return float(np.mean(sig))


def _gradients(gray: np.ndarray, sigma: float) -> np.ndarray:
    """Gradient magnitude (central differences) of ``gray`` smoothed by a Gaussian of ``sigma`` px."""
    gy, gx = np.gradient(cv2.GaussianBlur(gray, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE))
    return np.hypot(gx, gy)


def _gradient_noise(sigma: float) -> float:
    """E[magnitude^2] of :func:`_gradients` on white noise of unit variance (its impulse response's energy)."""
    impulse = np.zeros((41, 41))
    impulse[20, 20] = 1.0
    gy, gx = np.gradient(cv2.GaussianBlur(impulse, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT))
    return float((gx ** 2).sum() + (gy ** 2).sum())


def _reblur_ratio(sigma_t: np.ndarray) -> np.ndarray:
    """Central-difference gradient ratio at a step edge of total blur ``sigma_t`` before and after
    re-blurring by :data:`BLUR_REBLUR`: ``(f(1) - f(-1)) / 2 = A erf(1 / (sqrt 2 sigma)) / 2``."""
    g = np.vectorize(lambda s: math.erf(1.0 / (math.sqrt(2.0) * s)))
    return g(sigma_t) / g(np.sqrt(sigma_t ** 2 + BLUR_REBLUR ** 2))


_SIGMA_TABLE = np.linspace(BLUR_PROBE, 12.0, 400)
_RATIO_TABLE = _reblur_ratio(_SIGMA_TABLE)  # decreasing in sigma


def estimate_blur_sigma(image: np.ndarray) -> float:
    """Gaussian blur (pixels) of a frame beyond pixel-area integration, by the re-blur gradient
    ratio at its strong edges (Zhuo and Sim, "Defocus map estimation from a single image", 2011).

    Gradient magnitudes (central differences) of the gray image smoothed by :data:`BLUR_PROBE`
    (``m1``) and by ``sqrt(BLUR_PROBE**2 + BLUR_REBLUR**2)`` (``m2``) are compared at edge pixels:
    the 3 x 3 maxima of the gradient magnitude at the smoother scale :data:`BLUR_SELECT` (whose
    noise barely moves them, so the pick does not favour pixels where noise raised ``m1``) above
    ``max(EDGE_FLOOR_DN, 0.35 * its 99th percentile, 6 x its noise)``. For a step edge of total
    blur ``s`` the ratio ``m1 / m2`` is :func:`_reblur_ratio` ``(s)``, whatever its contrast. The
    noise's expected share of ``m1**2`` and ``m2**2`` (the frame's :func:`estimate_noise_sigma`
    squared times each gradient's response energy) is taken out, the median ratio inverted to
    ``s``, and the blur is ``sqrt(s**2 - BLUR_PROBE**2 - 1/12)`` (1/12: the variance of a pixel's
    box, which the compositor's supersampled coverage has already). Central differences leave
    a bias of about 0.1 px^2 in variance that depends on edge orientation (axis-aligned edges
    read +0.11, round ones -0.07: a sharp frame reads 0-0.35 px); texture and nearby edges bias
    it too (a frame without clean edges reads sharper). Measured on area-sampled synthetic edge
    images blurred by 0.7-4 px with 0-8 DN of noise: within 15 % (the tests ask for 30 %).
    Returns 0 when there are fewer than 20 edge pixels (a blank frame).

    Args:
        image: (H, W, 3) RGB or (H, W) gray, DN.
    Returns:
        sigma in pixels (>= 0).
    """
    img = np.asarray(image, np.float64)
    gray = luma(img) if img.ndim == 3 else img
    noise = estimate_noise_sigma(gray) ** 2
    wide = float(np.hypot(BLUR_PROBE, BLUR_REBLUR))
    n1, n2 = noise * _gradient_noise(BLUR_PROBE), noise * _gradient_noise(wide)
    m1, m2, m3 = _gradients(gray, BLUR_PROBE), _gradients(gray, wide), _gradients(gray, BLUR_SELECT)
    core = np.zeros_like(m1, bool)
    core[6:-6, 6:-6] = True  # away from the replicated border
    m3f = m3.astype(np.float32)
    peak = m3f >= cv2.dilate(m3f, np.ones((3, 3), np.uint8))
    ridge = core & peak & (m3 > 0)
    if ridge.sum() < 20:
        return 0.0
    thr = max(EDGE_FLOOR_DN, 0.35 * float(np.percentile(m3[ridge], 99)), 6.0 * np.sqrt(n2))
    edges = ridge & (m3 >= thr)
    if edges.sum() < 20:
        return 0.0
    # the noise's share of the squared magnitudes taken out
    ratio = float(np.median(np.sqrt(np.maximum(m1[edges] ** 2 - n1, 1e-12) / np.maximum(m2[edges] ** 2 - n2, 1e-12))))
    s = float(np.interp(ratio, _RATIO_TABLE[::-1], _SIGMA_TABLE[::-1]))
    return float(np.sqrt(max(s * s - BLUR_PROBE ** 2 - 1.0 / 12.0, 0.0)))
