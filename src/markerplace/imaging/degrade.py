"""Image degradations a phone camera adds to what the renderer draws: pure numpy / OpenCV filters
of an (H, W, 3) uint8 RGB image, each with its parameters given (the testbed's query conditions,
:mod:`markerplace.simulation.conditions`, draw them per image).

Pixel values are 8-bit digital numbers (DN, 0..255) of the rendered, display-encoded image.
Gain-type changes (exposure, white balance) act on linear light: the image is decoded with a
pure power law of exponent :data:`GAMMA` (2.2), scaled, re-encoded, then clipped to 0..255
(sensor saturation) and rounded. Noise acts on the 8-bit values, as the noise of a camera's
8-bit output is usually modelled (signal-dependent Gaussian, the Poisson-Gaussian model).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["GAMMA", "exposure", "white_balance", "sensor_noise", "motion_kernel", "motion_blur", "occlude"]

#: Display gamma of the power-law encoding assumed for gain changes.
GAMMA = 2.2


def _gain(rgb: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """Scale linear light by ``gains`` ((3,) per channel), re-encode, clip to 0..255, round."""
    lin = (np.asarray(rgb, np.float64) / 255.0) ** GAMMA
    out = 255.0 * (lin * np.asarray(gains, np.float64).reshape(1, 1, 3)) ** (1.0 / GAMMA)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def exposure(rgb: np.ndarray, ev: float) -> np.ndarray:
    """Over- (``ev`` > 0) or under-exposure by ``ev`` stops: linear light times ``2**ev``, so an
    unclipped 8-bit value is multiplied by ``2 ** (ev / GAMMA)``; values past 255 saturate.

    Args:
        rgb: (H, W, 3) uint8.
        ev: exposure change in stops (EV).
    Returns:
        (H, W, 3) uint8.
    """
    return _gain(rgb, np.full(3, 2.0 ** float(ev)))


def white_balance(rgb: np.ndarray, shift: float) -> np.ndarray:
    """A colour-temperature error: linear red times ``exp(shift)``, blue times ``exp(-shift)``,
    green unchanged (``shift`` > 0: too warm, < 0: too cold; 0.2 is roughly a 1000 K error
    around 5000 K), then clipped.

    Args:
        rgb: (H, W, 3) uint8 RGB.
        shift: log gain of red over green (blue gets its opposite).
    Returns:
        (H, W, 3) uint8.
    """
    s = float(shift)
    return _gain(rgb, np.array([np.exp(s), 1.0, np.exp(-s)]))


def sensor_noise(rgb: np.ndarray, rng: np.random.Generator, shot: float, read: float) -> np.ndarray:
    """Shot and read noise: every value x (DN) becomes ``x + sqrt(shot * x + read**2) * z``,
    z standard normal (independent per pixel and channel), then rounded and clipped. The
    variance at signal x is ``shot * x + read**2`` DN^2 (plus 1/12 from rounding): shot noise
    (Poisson, variance proportional to the signal, ``shot`` DN per electron) and read noise
    (``read`` DN standard deviation).

    Args:
        rgb: (H, W, 3) uint8.
        rng: the random stream.
        shot: DN per photo-electron (shot noise variance / signal).
        read: read-noise standard deviation, DN.
    Returns:
        (H, W, 3) uint8.
    """
    x = np.asarray(rgb, np.float64)
    noisy = x + np.sqrt(shot * x + read ** 2) * rng.standard_normal(x.shape)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def motion_kernel(length: float, angle: float, supersample: int = 16) -> np.ndarray:
    """Normalized linear motion-blur kernel: the camera moved uniformly over a segment of
    ``length`` pixels at ``angle`` (radians, from the image x axis towards y, i.e. clockwise on
    screen). The segment is sampled ``supersample`` times per pixel with bilinear splatting, so
    the kernel's spread along the direction is that of a uniform segment: standard deviation
    ``length / sqrt(12)``, and none across it (beyond the splatting's).

    Returns:
        (S, S) float64 kernel summing to 1, S odd, centred.
    """
    length = max(float(length), 0.0)
    half = int(np.ceil(length / 2.0)) + 1
    size = 2 * half + 1
    k = np.zeros((size, size))
    n = max(int(np.ceil(length * supersample)), 1)
    t = (np.arange(n) + 0.5) / n - 0.5 if length > 0 else np.zeros(1)
    xs, ys = half + t * length * np.cos(angle), half + t * length * np.sin(angle)
    x0, y0 = np.floor(xs).astype(int), np.floor(ys).astype(int)
    fx, fy = xs - x0, ys - y0
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        np.add.at(k, (y0 + dy, x0 + dx), w)
    return k / k.sum()


def motion_blur(rgb: np.ndarray, length: float, angle: float, defocus: float = 0.0) -> np.ndarray:
    """Linear motion blur (:func:`motion_kernel`), then a Gaussian defocus of ``defocus`` pixels
    standard deviation (0: none); borders replicate the edge (OpenCV's ``BORDER_REPLICATE``).

    Args:
        rgb: (H, W, 3) uint8.
        length: blur length, pixels.
        angle: direction, radians (see :func:`motion_kernel`).
        defocus: Gaussian sigma, pixels.
    Returns:
        (H, W, 3) uint8.
    """
    img = np.asarray(rgb, np.float32)
    out = cv2.filter2D(img, -1, motion_kernel(length, angle).astype(np.float32), borderType=cv2.BORDER_REPLICATE)
    if defocus > 0:
        out = cv2.GaussianBlur(out, (0, 0), float(defocus), borderType=cv2.BORDER_REPLICATE)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def occlude(rgb: np.ndarray, depth: np.ndarray, K: np.ndarray, people: list[dict], width: float = 0.5,
            height: float = 1.75, eye: float = 1.5) -> np.ndarray:
    """Paste people standing in front of a level camera: each an upright ellipse ``width`` x
    ``height`` metres (its top ``height - eye`` metres above the optical axis, its feet ``eye``
    metres below: the camera held at ``eye`` metres) at ``distance`` metres, so ``fx * width /
    distance`` pixels wide; it covers only pixels whose rendered depth is beyond it (or where
    nothing was hit). Fill: the person's colour times a smooth fold pattern (0.6..1.0).
    Farther people are pasted first.

    Args:
        rgb: (H, W, 3) uint8.
        depth: (H, W) planar depth, metres (0: nothing hit).
        K: (3, 3) intrinsics.
        people: dicts with ``distance`` (m), ``u`` (centre column as a fraction of the width),
            ``colour`` (3 values 0..255), ``folds`` ((4, 8) values in [0, 1], the pattern,
            stretched over the person).
    Returns:
        (H, W, 3) uint8.
    """
    out = np.array(rgb, np.uint8, copy=True)
    H, W = out.shape[:2]
    fx, fy, cy = float(K[0, 0]), float(K[1, 1]), float(K[1, 2])
    vs, us = np.mgrid[:H, :W]
    for p in sorted(people, key=lambda q: -q["distance"]):
        d = float(p["distance"])
        uc, half_w = float(p["u"]) * (W - 1), 0.5 * fx * width / d
        top, bottom = cy - fy * (height - eye) / d, cy + fy * eye / d
        vc, half_h = 0.5 * (top + bottom), 0.5 * (bottom - top)
        inside = ((us - uc) / half_w) ** 2 + ((vs - vc) / half_h) ** 2 <= 1.0
        mask = inside & ((depth > d) | (depth <= 0))
        if not mask.any():
            continue
        x0, y0 = int(max(np.floor(uc - half_w), 0)), int(max(np.floor(top), 0))
        x1, y1 = int(min(np.ceil(uc + half_w), W - 1)) + 1, int(min(np.ceil(bottom), H - 1)) + 1
        folds = cv2.resize(np.asarray(p["folds"], np.float32), (max(x1 - x0, 1), max(y1 - y0, 1)),
                           interpolation=cv2.INTER_CUBIC)
        fill = np.zeros((H, W), np.float32)
        fill[y0:y1, x0:x1] = 0.6 + 0.4 * np.clip(folds, 0.0, 1.0)
        colour = np.asarray(p["colour"], np.float32).reshape(1, 3)
        out[mask] = np.clip(np.rint(fill[mask][:, None] * colour), 0, 255).astype(np.uint8)
    return out
