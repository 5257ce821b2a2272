"""Which markers a rendered view shows: sample points on each marker, projected into the view
and compared with the depth rendered without markers.

One sampling and one projection test, two questions:

* :func:`markers_unoccluded` (scoring): is the whole tag visible? Its centre and four corners
  all project inside the image and nothing is in front of them.
* :func:`markers_in_view` (caching renders): could the tag change this image? Some point of its
  drawn quad (quiet zone included) projects near the image and is not hidden.

Frames: world z up, metres; pixels with centres at integers (OpenCV).
"""

from __future__ import annotations

import numpy as np

from markerplace.geometry import project_with_depth_lookup
from markerplace.tagfamily import outer_size

__all__ = ["MARKER_SAMPLES", "marker_points", "markers_unoccluded", "markers_in_view", "select_in_view"]

MARKER_SAMPLES = "marker_samples.npy"
"""File next to a stored (N, C) in-view mask: the (C, S, 3) sample points of its C markers."""

_CENTRE_CORNERS = np.array([[0, 0, 0], [-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]], dtype=float) / 2.0


def marker_points(world_from_marker: np.ndarray, sizes, grid: int | None = None) -> np.ndarray:
    """(M, S, 3) world sample points per marker.

    Args:
        world_from_marker: (M, 4, 4) marker poses.
        sizes: black-square edge in metres, (M,) or one for all.
        grid: None: the centre and the 4 black-square corners (S = 5); an integer g: a g x g
            grid over the drawn quad including the white quiet zone (S = g^2).
    """
    T = np.asarray(world_from_marker, dtype=float).reshape(-1, 4, 4)
    M = len(T)
    size = np.broadcast_to(np.asarray(sizes, dtype=float), (M,))
    if grid is None:
        local = _CENTRE_CORNERS[None] * size[:, None, None]
    else:
        u = np.linspace(-0.5, 0.5, grid)
        gu, gv = (a.ravel() for a in np.meshgrid(u, u))
        unit = np.stack([gu, gv, np.zeros_like(gu)], axis=1)
        local = unit[None] * np.array([outer_size(s) for s in size])[:, None, None]
    return np.einsum("mij,mkj->mki", T[:, :3, :3], local) + T[:, None, :3, 3]


def _project(depth, world_from_cam, K, samples):
    M, S, _ = samples.shape
    uv, z, surface = project_with_depth_lookup(depth, world_from_cam, K, samples.reshape(-1, 3))
    return uv.reshape(M, S, 2), z.reshape(M, S), surface.reshape(M, S)


def markers_unoccluded(depth: np.ndarray, world_from_cam: np.ndarray, K: np.ndarray, samples: np.ndarray,
                       tolerance: float) -> np.ndarray:
    """(M,) bool: every sample projects inside the (H, W) image, in front of the camera, and
    the surface rendered there (without markers) is not closer than the sample minus
    ``tolerance`` metres."""
    if len(samples) == 0:
        return np.zeros(0, bool)
    H, W = depth.shape
    uv, z, surface = _project(depth, world_from_cam, K, samples)
    ui, vi = np.round(uv[..., 0]), np.round(uv[..., 1])
    inside = (z > 1e-3) & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
    return (inside & ((surface == 0) | (surface >= z - tolerance))).all(axis=1)


def markers_in_view(depth: np.ndarray, world_from_cam: np.ndarray, K: np.ndarray, samples: np.ndarray,
                    margin_px: float, tolerance: float) -> np.ndarray:
    """(M,) bool: some sample is in front of the camera, within ``margin_px`` of the (H, W)
    image, and not hidden by the surface rendered without markers (conservative: a marker that
    may change the image counts)."""
    if len(samples) == 0:
        return np.zeros(0, bool)
    H, W = depth.shape
    uv, z, surface = _project(depth, world_from_cam, K, samples)
    u, v = uv[..., 0], uv[..., 1]
    near = (z > 1e-3) & (u > -0.5 - margin_px) & (u < W - 0.5 + margin_px) & (v > -0.5 - margin_px) & (v < H - 0.5 + margin_px)
    hidden = near & (surface > 0) & (surface < z - tolerance)
    return (near & ~hidden).any(axis=1)


def select_in_view(mask: np.ndarray, stored_samples: np.ndarray, samples: np.ndarray) -> np.ndarray | None:
    """The (N, U) in-view mask of the markers sampled by ``samples`` (U, S, 3), read from a
    stored (N, C) ``mask`` of the markers sampled by ``stored_samples`` (C, S, 3), or None when
    some marker's samples are not among the stored ones bit for bit (then the mask must be
    computed). :func:`markers_in_view` decides each marker from its own samples alone, so an
    equal row gives an equal column."""
    stored = np.ascontiguousarray(stored_samples, np.float64)
    rows = {stored[c].tobytes(): c for c in range(len(stored))}
    want = np.ascontiguousarray(samples, np.float64)
    if want.shape[1:] != stored.shape[1:] and len(want):
        return None
    cols = [rows.get(want[u].tobytes()) for u in range(len(want))]
    if any(c is None for c in cols):
        return None
    return np.asarray(mask, bool)[:, np.asarray(cols, np.int64)].reshape(len(mask), len(want))
