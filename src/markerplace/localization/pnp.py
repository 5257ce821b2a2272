"""Absolute pose from 2D-3D correspondences: P3P RANSAC, then Levenberg-Marquardt refinement.

As in the paper (Gao et al. P3P + RANSAC, then OpenCV's LM). Poses are returned as
``world_from_cam`` (4, 4); OpenCV's rvec/tvec are ``cam_from_world``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from markerplace.geometry import invert, rotation_angle_deg

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PnPConfig:
    """RANSAC + refinement parameters.

    Attributes:
        ransac_iterations: maximal RANSAC iterations (the paper uses >= 200; OpenCV stops early
            once ``confidence`` is reached).
        reprojection_error: inlier threshold in pixels (paper: 4 px).
        confidence: RANSAC success probability used for early termination.
        min_inliers: fewer inliers than this is a failure. 12 keeps P3P hypotheses supported by
            a handful of chance matches (or a single tag's 4 corners) from counting as poses.
        refine: run Levenberg-Marquardt on the inliers after RANSAC.
        method: ``"p3p"`` (Gao et al., as in the paper) or ``"ap3p"``.
    """

    ransac_iterations: int = 1000
    reprojection_error: float = 4.0
    confidence: float = 0.9999
    min_inliers: int = 12
    refine: bool = True
    method: str = "p3p"


@dataclass(frozen=True, eq=False)
class PoseEstimate:
    """Result of :func:`estimate_pose`.

    Attributes:
        world_from_cam: (4, 4) estimated pose, or None on failure.
        inliers: (n,) bool inlier mask over the input correspondences.
        num_inliers: number of inliers (0 on failure before RANSAC).
    """

    world_from_cam: np.ndarray | None
    inliers: np.ndarray
    num_inliers: int

    @property
    def success(self) -> bool:
        return self.world_from_cam is not None


def _pose_from_rt(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    cam_from_world = np.eye(4)
    cam_from_world[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))[0]
    cam_from_world[:3, 3] = np.asarray(tvec, float).reshape(3)
    return invert(cam_from_world)


def _reprojection_errors(points: np.ndarray, pixels: np.ndarray, rvec, tvec, K) -> np.ndarray:
    proj, _ = cv2.projectPoints(points.reshape(-1, 1, 3), rvec, tvec, K, None)
    R = cv2.Rodrigues(rvec)[0]
    z = points @ R[2] + float(np.asarray(tvec).reshape(3)[2])
    err = np.linalg.norm(proj.reshape(-1, 2) - pixels, axis=1)
    err[z <= 0] = np.inf
    return err


def estimate_pose(
    points_world: np.ndarray,
    keypoints: np.ndarray,
    K: np.ndarray,
    config: PnPConfig = PnPConfig(),
    seed: int = 0,
) -> PoseEstimate:
    """Estimate ``world_from_cam`` from (n, 3) world points and (n, 2) pixel observations.

    P3P inside RANSAC (``cv2.solvePnPRansac``, OpenCV's RNG seeded with ``seed``), then LM
    refinement on the inliers (``cv2.solvePnPRefineLM``) and a final inlier recount with the
    same threshold. Returns a failure (``world_from_cam=None``) when there are fewer than
    ``max(4, config.min_inliers)`` correspondences or inliers.
    """
    pts = np.ascontiguousarray(points_world, dtype=np.float64).reshape(-1, 3)
    px = np.ascontiguousarray(keypoints, dtype=np.float64).reshape(-1, 2)
    n = len(pts)
    if len(px) != n:
        raise ValueError(f"{n} points but {len(px)} keypoints")
    K = np.asarray(K, dtype=np.float64)
    fail = PoseEstimate(None, np.zeros(n, bool), 0)
    need = max(4, int(config.min_inliers))
    if n < need:
        return fail
    flags = {"p3p": cv2.SOLVEPNP_P3P, "ap3p": cv2.SOLVEPNP_AP3P}[config.method]
    cv2.setRNGSeed(int(seed))
    ok, rvec, tvec, idx = cv2.solvePnPRansac(
        pts.reshape(-1, 1, 3),
        px.reshape(-1, 1, 2),
        K,
        None,
        iterationsCount=int(config.ransac_iterations),
        reprojectionError=float(config.reprojection_error),
        confidence=float(config.confidence),
        flags=flags,
    )
    if not ok or idx is None or len(idx) < need:
        n_in = 0 if idx is None else len(idx)
        log.debug("PnP RANSAC failed: %d inliers of %d", n_in, n)
        mask = np.zeros(n, bool)
        if idx is not None:
            mask[np.asarray(idx).reshape(-1)] = True
        return PoseEstimate(None, mask, int(n_in))
    inl = np.zeros(n, bool)
    inl[np.asarray(idx).reshape(-1)] = True
    if config.refine:
        rvec, tvec = cv2.solvePnPRefineLM(pts[inl].reshape(-1, 1, 3), px[inl].reshape(-1, 1, 2), K, None, rvec, tvec)
        inl = _reprojection_errors(pts, px, rvec, tvec, K) < config.reprojection_error
        if inl.sum() < need:
            return PoseEstimate(None, inl, int(inl.sum()))
        # one more LM pass on the recounted inlier set
        rvec, tvec = cv2.solvePnPRefineLM(pts[inl].reshape(-1, 1, 3), px[inl].reshape(-1, 1, 2), K, None, rvec, tvec)
    return PoseEstimate(_pose_from_rt(rvec, tvec), inl, int(inl.sum()))


def pose_errors(world_from_cam_est: np.ndarray, world_from_cam_true: np.ndarray) -> tuple[float, float]:
    """The paper's errors: (||t_est - t_true||_2 in metres, |arccos((tr(R_est^T R_true) - 1)/2)| in degrees).

    Translations and rotations are those of ``world_from_cam`` (camera centre and orientation
    in the world).
    """
    a = np.asarray(world_from_cam_est, float)
    b = np.asarray(world_from_cam_true, float)
    dt = float(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    return dt, rotation_angle_deg(a[:3, :3], b[:3, :3])
