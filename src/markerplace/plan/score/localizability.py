"""Camera localizability: information matrices, entropy, information gain, marker visibility.

This module implements the closed form of docs/design.md section 4 (the paper's factor graphs
marginalized analytically), batched over all camera poses. What one marker adds is a marker
model's business (:mod:`markerplace.plan.score.marker_models`, chosen by name).

Conventions
-----------
* Poses are ``world_from_cam`` (N, 4, 4), OpenCV camera (x right, y down, z forward), metres.
* Tangent vectors are ``xi = (omega, nu)`` (rotation first, radians then metres) with the
  *right* perturbation ``T' = T Exp(xi)``: exactly GTSAM's ``Pose3`` convention. Hence the 6x6
  information matrix ``Lambda`` returned here is the inverse of
  ``gtsam.Marginals(graph, values).marginalCovariance(camera_key)`` for the paper's graph
  (tested in ``tests/plan/score/test_localizability_gtsam.py``).
* Information matrices are in units of 1/rad^2 (omega block) and 1/m^2 (nu block).

Per landmark ``p`` (world) seen from pose ``T = (R, t)``, with ``p_c = R^T (p - t)`` and the
pinhole projection ``pi``::

    J = dpi/dp_c [ [p_c]x | -I ]              (2x6, pixels per tangent unit)
    P = dpi/dp_c R^T                          (2x3, pixels per metre)
    S = sigma_px^2 I + P Sigma_p P^T,   Sigma_p = landmark_sigma^2 (1 + n_p) I
    Lambda = prior_sigma^-2 I + sum_landmarks J^T S^-1 J (+ sum_markers M)

Because ``Sigma_p`` is isotropic, ``P Sigma_p P^T = s D D^T`` with ``D = dpi/dp_c``; ``J`` is the
classic interaction matrix. Each landmark's term is whitened (``A = L^-1 J`` with ``S = L L^T``).
The per-pose sums ``sum A^T A`` over natural landmarks run in a compiled kernel
(:mod:`markerplace.plan.score.landmark_kernel`, one pass per pose, poses spread over threads); the few
marker terms (the ``corners`` marker model) use the same whitening in numpy
(:func:`whitened_jacobians`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from markerplace.plan.score.landmark_kernel import landmark_information_sums

log = logging.getLogger(__name__)

#: Constant term of the entropy of a 6-d Gaussian: d/2 (1 + ln 2 pi) with d = 6.
ENTROPY_CONST = 3.0 * (1.0 + np.log(2.0 * np.pi))


@dataclass(frozen=True)
class NoiseConfig:
    """Noise parameters of the synthetic localization problem (docs/design.md section 3).

    Attributes:
        prior_sigma: standard deviation of the camera pose prior, the same for all 6 tangent
            components (rad for omega, m for nu). Default 0.1.
        landmark_sigma: standard deviation of a 3D point prior per axis, metres, before the
            similarity scaling ``sqrt(1 + n_p)``. Default 0.05 (the paper's
            Sigma_0 = diag(2.5, 2.5, 2.5) x 1e-3 m^2).
        pixel_sigma: standard deviation of a keypoint / tag-corner measurement, pixels.
            Default 1.0.
        marker_rel_sigma: standard deviation of the camera-to-marker relative pose factor, all
            6 components ('paper' marker model). Default 1e-3.
        marker_prior_sigma: standard deviation of the marker pose prior, all 6 components
            ('paper' marker model). Default 1e-5.
        max_range: landmarks farther than this Euclidean distance from the camera centre,
            metres, are ignored. Default 10.0.
    """

    prior_sigma: float = 0.1
    landmark_sigma: float = 0.05
    pixel_sigma: float = 1.0
    marker_rel_sigma: float = 1e-3
    marker_prior_sigma: float = 1e-5
    max_range: float = 10.0

    def __post_init__(self) -> None:
        for name in ("prior_sigma", "landmark_sigma", "pixel_sigma", "marker_rel_sigma",
                     "marker_prior_sigma", "max_range"):
            if not float(getattr(self, name)) > 0.0:
                raise ValueError(f"NoiseConfig.{name} must be > 0")


# --------------------------------------------------------------------------------------------
# Natural-feature information
# --------------------------------------------------------------------------------------------

def whitened_jacobians(x: np.ndarray, y: np.ndarray, z: np.ndarray, var_p: np.ndarray | float,
                        valid: np.ndarray, K: np.ndarray, pixel_sigma: float) -> np.ndarray:
    """Whitened, transposed Jacobians ``A^T`` of landmarks with landmark noise marginalized.

    Args:
        x, y, z: (B, m) camera-frame coordinates, metres (planar layout).
        var_p: (B, m) or scalar isotropic landmark variance per axis, m^2 (0: known points).
        valid: (B, m) bool; invalid entries contribute nothing.
        K: (3, 3) camera matrix (zero skew; only fx, fy matter).
        pixel_sigma: pixel noise sigma.

    Returns:
        (B, 6, 2 m) array ``G`` such that ``G @ G^T = sum_landmarks J^T S^-1 J`` per row of the
        batch, where ``S = sigma_px^2 I + var_p D D^T``, ``D = dpi/dp_c`` and ``J`` the 2x6
        interaction matrix in (omega, nu) order. Column ``r m + j`` is row ``r`` of the
        whitened ``A = L^-1 J`` (``S = L L^T``) of landmark ``j``.
    """
    fx, fy = float(K[0, 0]), float(K[1, 1])
    B, m = x.shape
    zs = np.where(valid, z, 1.0)
    rho = 1.0 / zs
    u = x * rho
    v = y * rho
    uv = u * v
    uu1 = u * u
    uu1 += 1.0
    vv1 = v * v
    vv1 += 1.0
    # S = sigma^2 I + var_p rho^2 F [[1+u^2, uv], [uv, 1+v^2]] F ; Cholesky S = L L^T.
    sig2 = pixel_sigma * pixel_sigma
    s = rho * rho
    s *= var_p
    l11 = s * (fx * fx) * uu1
    l11 += sig2
    np.sqrt(l11, out=l11)
    l21 = s * (fx * fy) * uv
    l21 /= l11
    l22 = s * (fy * fy) * vv1
    l22 += sig2
    l22 -= l21 * l21
    np.sqrt(l22, out=l22)
    a = np.where(valid, fx / l11, 0.0)  # A row 1 = a * j1
    b = np.where(valid, fy / l22, 0.0)  # A row 2 = b * j2 - c * j1
    c = a * l21
    c /= l22
    # Interaction matrix rows divided by f: j1 = [uv, -(1+u^2), v, -rho, 0, u rho],
    # j2 = [1+v^2, -uv, -u, 0, -rho, v rho].
    G = np.empty((B, 6, 2, m))
    np.multiply(a, uv, out=G[:, 0, 0])
    np.multiply(a, uu1, out=G[:, 1, 0])
    np.negative(G[:, 1, 0], out=G[:, 1, 0])
    np.multiply(a, v, out=G[:, 2, 0])
    np.multiply(a, rho, out=G[:, 3, 0])
    np.negative(G[:, 3, 0], out=G[:, 3, 0])
    G[:, 4, 0] = 0.0
    np.multiply(G[:, 3, 0], u, out=G[:, 5, 0])
    np.negative(G[:, 5, 0], out=G[:, 5, 0])
    np.multiply(b, vv1, out=G[:, 0, 1])
    G[:, 0, 1] -= c * uv
    np.multiply(c, uu1, out=G[:, 1, 1])
    G[:, 1, 1] -= b * uv
    np.multiply(b, u, out=G[:, 2, 1])
    G[:, 2, 1] += c * v
    np.negative(G[:, 2, 1], out=G[:, 2, 1])
    np.multiply(c, rho, out=G[:, 3, 1])
    np.multiply(b, rho, out=G[:, 4, 1])
    np.negative(G[:, 4, 1], out=G[:, 4, 1])
    bv = b * v
    bv -= c * u
    np.multiply(bv, rho, out=G[:, 5, 1])
    return G.reshape(B, 6, 2 * m)


def gram(G: np.ndarray) -> np.ndarray:
    """(B, 6, k) -> (B, 6, 6) ``G @ G^T``."""
    return np.matmul(G, np.swapaxes(G, 1, 2))


def pose_information(world_from_cam: np.ndarray, K: np.ndarray, points_world: np.ndarray,
                     pose_index: np.ndarray, n_similar: np.ndarray | None,
                     noise: NoiseConfig = NoiseConfig()) -> np.ndarray:
    """Information matrices of camera poses localized against natural-feature landmarks.

    Args:
        world_from_cam: (N, 4, 4) camera poses.
        K: (3, 3) pinhole camera matrix (pixels, zero skew).
        points_world: (P, 3) landmark positions, world metres. Each landmark belongs to one pose
            (a 3D point seen from several poses is passed once per pose).
        pose_index: (P,) int in [0, N): the pose that observes each landmark. Grouping the
            landmarks by pose (sorted ``pose_index``) is fastest but not required.
        n_similar: (P,) look-alike counts n_p (int or float >= 0), or None for all zeros.
        noise: noise parameters.

    Returns:
        (N, 6, 6) information matrices Lambda (tangent order (omega, nu), right perturbation):
        camera prior ``prior_sigma^-2 I`` plus, per landmark, ``J^T S^-1 J``. Landmarks behind
        the camera (z <= 1e-6 m) or farther than ``noise.max_range`` (Euclidean distance from
        the camera centre) are dropped. Whether a landmark projects inside the image is the
        caller's business (observed keypoints always do).
    """
    T = np.asarray(world_from_cam, dtype=float)
    N = T.shape[0]
    pts = np.asarray(points_world, dtype=float).reshape(-1, 3)
    idx = np.asarray(pose_index, dtype=np.int64).reshape(-1)
    P = pts.shape[0]
    if idx.shape[0] != P:
        raise ValueError("pose_index must have one entry per point")
    if P and (idx.min() < 0 or idx.max() >= N):
        raise ValueError("pose_index out of range")
    nsim = None if n_similar is None else np.asarray(n_similar, dtype=float).reshape(-1)
    if nsim is not None and nsim.shape[0] != P:
        raise ValueError("n_similar must have one entry per point")
    Lam = np.zeros((N, 6, 6))
    if P and N:
        # imported here: numba is slow to import and only this function needs it

        if np.any(idx[1:] < idx[:-1]):
            order = np.argsort(idx, kind="stable")
            idx, pts = idx[order], pts[order]
            nsim = None if nsim is None else nsim[order]
        starts = np.zeros(N + 1, dtype=np.int64)
        np.cumsum(np.bincount(idx, minlength=N), out=starts[1:])
        R = np.ascontiguousarray(T[:, :3, :3])
        # Camera-frame offset: p_c = R^T p + c with c = -R^T t.
        c_off = np.ascontiguousarray(-np.einsum("nji,nj->ni", R, T[:, :3, 3]))
        var = np.full(P, noise.landmark_sigma**2)
        if nsim is not None:
            var *= 1.0 + nsim
        landmark_information_sums(R, c_off, np.ascontiguousarray(pts), starts, var,
                                  float(K[0, 0]), float(K[1, 1]), float(noise.pixel_sigma)**2,
                                  float(noise.max_range)**2, Lam)
    Lam[:, np.arange(6), np.arange(6)] += 1.0 / noise.prior_sigma**2
    return Lam


# --------------------------------------------------------------------------------------------
# Entropy and information gain
# --------------------------------------------------------------------------------------------


def logdet_spd(M: np.ndarray) -> np.ndarray:
    """ln det of (..., n, n) symmetric positive definite matrices via Cholesky."""
    L = np.linalg.cholesky(M)
    d = np.log(np.diagonal(L, axis1=-2, axis2=-1))
    # Explicit left-to-right sum: the result of one matrix never depends on the batch shape.
    acc = d[..., 0].copy()
    for i in range(1, d.shape[-1]):
        acc += d[..., i]
    return 2.0 * acc


def entropy(Lambda: np.ndarray) -> np.ndarray:
    """Entropy (nats) of the Gaussian with information matrix Lambda (..., 6, 6).

    ``H = 1/2 ln det(Lambda^-1) + 3 (1 + ln 2 pi)``. The localizability score is ``-H``.
    """
    return -0.5 * logdet_spd(np.asarray(Lambda, dtype=float)) + ENTROPY_CONST


def score(Lambda: np.ndarray) -> np.ndarray:
    """Localizability score ``l = -H`` (nats) of (..., 6, 6) information matrices."""
    return -entropy(Lambda)


def whitening(Lambda: np.ndarray) -> np.ndarray:
    """(..., 6, 6) ``L^-1`` with ``Lambda = L L^T`` (Cholesky): the whitening used by gains."""
    return np.linalg.inv(np.linalg.cholesky(np.asarray(Lambda, dtype=float)))


def information_gain_whitened(L_inv: np.ndarray, M: np.ndarray) -> np.ndarray:
    """:func:`information_gain` given the precomputed :func:`whitening` ``L^-1`` of Lambda.

    Args:
        L_inv: (..., 6, 6) inverse Cholesky factor of Lambda.
        M: (..., 6, 6) symmetric PSD information added.

    Returns:
        (...,) ``1/2 ln det(I + L^-1 M L^-T)`` (nats), clipped at 0.
    """
    X = np.matmul(np.matmul(L_inv, M), np.swapaxes(L_inv, -1, -2))
    X = 0.5 * (X + np.swapaxes(X, -1, -2))
    X[..., np.arange(6), np.arange(6)] += 1.0
    return np.maximum(0.5 * logdet_spd(X), 0.0)


def information_gain(Lambda: np.ndarray, M: np.ndarray) -> np.ndarray:
    """Entropy decrease ``1/2 [ln det(Lambda + M) - ln det(Lambda)]`` (nats), >= 0.

    Args:
        Lambda: (..., 6, 6) SPD information before the marker.
        M: (..., 6, 6) symmetric PSD information the marker adds (may be zero or huge).

    Computed as ``1/2 ln det(I + L^-1 M L^-T)`` with ``Lambda = L L^T``, which stays accurate
    both when M dominates Lambda by many orders of magnitude and when M is tiny.
    """
    return information_gain_whitened(whitening(Lambda), np.asarray(M, dtype=float))


# --------------------------------------------------------------------------------------------
# Visibility
# --------------------------------------------------------------------------------------------


def marker_visibility(world_from_cam: np.ndarray, world_from_marker: np.ndarray, K: np.ndarray,
                      image_size: tuple[int, int], max_range: float = 10.0,
                      max_bearing_deg: float | None = 45.0, max_view_angle_deg: float = 80.0,
                      occluded: np.ndarray | None = None) -> np.ndarray:
    """Which camera poses see a marker (docs/design.md section 3, marker visibility).

    A pose sees the marker when all hold:

    * the tag centre is in front of the camera (camera-frame z > 0) and projects inside the
      image (``0 <= u <= width``, ``0 <= v <= height``);
    * Euclidean distance camera centre -> tag centre < ``max_range`` metres;
    * |horizontal bearing| = |atan2(x_c, z_c)| <= ``max_bearing_deg`` (None: half the
      horizontal FOV from K and the image width);
    * the angle between the marker normal (marker z) and the direction from the tag to the
      camera is < ``max_view_angle_deg`` (so the camera is on the tag's front side);
    * not ``occluded`` (caller-provided (N,) bool, e.g. from rendered depth), if given.

    Args:
        world_from_cam: (N, 4, 4) camera poses.
        world_from_marker: (4, 4) marker pose.
        K: (3, 3) camera matrix.
        image_size: (width, height) pixels.

    Returns:
        (N,) bool.
    """
    T = np.asarray(world_from_cam, dtype=float).reshape(-1, 4, 4)
    Tm = np.asarray(world_from_marker, dtype=float)
    centre = Tm[:3, 3]
    normal = Tm[:3, 2]
    d_w = centre[None] - T[:, :3, 3]  # camera -> tag, world
    dist = np.linalg.norm(d_w, axis=1)
    p_c = np.einsum("nji,nj->ni", T[:, :3, :3], d_w)
    z = p_c[:, 2]
    zs = np.where(z > 0, z, 1.0)
    u = K[0, 0] * p_c[:, 0] / zs + K[0, 2]
    v = K[1, 1] * p_c[:, 1] / zs + K[1, 2]
    W, H = float(image_size[0]), float(image_size[1])
    vis = (z > 0) & (u >= 0) & (u <= W) & (v >= 0) & (v <= H) & (dist < max_range)
    if max_bearing_deg is None:
        max_bearing_deg = float(np.degrees(np.arctan2(W / 2.0, K[0, 0])))
    bearing = np.degrees(np.abs(np.arctan2(p_c[:, 0], p_c[:, 2])))
    vis &= bearing <= max_bearing_deg
    with np.errstate(invalid="ignore", divide="ignore"):
        cos_view = -(d_w @ normal) / np.maximum(dist, 1e-12)
    vis &= cos_view > np.cos(np.radians(max_view_angle_deg))
    if occluded is not None:
        occ = np.asarray(occluded, dtype=bool).reshape(-1)
        if occ.shape[0] != T.shape[0]:
            raise ValueError("occluded must have one entry per pose")
        vis &= ~occ
    return vis


__all__ = [
    "ENTROPY_CONST", "NoiseConfig", "entropy", "information_gain", "logdet_spd", "marker_visibility",
    "pose_information", "score", "information_gain_whitened", "whitening", "gram", "whitened_jacobians",
]
