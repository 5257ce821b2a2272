"""Conventions and SE(3) helpers, written once.

Frames and units
----------------
* World: z up, metres.
* Camera: OpenCV pinhole, x right, y down, z forward. Poses are 4x4 ``world_from_cam``
  (maps camera-frame points to world). Transforms are named ``a_from_b``.
* Yaw: angle of the optical axis in the world xy-plane, counter-clockwise from +x, radians
  unless a name says ``_deg``. A camera with yaw ``psi`` looks along (cos psi, sin psi, 0)
  and is level (no roll, no pitch).
* Marker: ``world_from_marker`` with origin at the tag centre, z out of the wall towards
  viewers (the wall normal), x to a facing viewer's right, y up. This is OpenCV's ArUco
  convention and is right-handed ("y down" together with z towards the viewer and x to the
  right would be left-handed; see docs/design.md section 2). Size is the edge of the black
  square.
* Depth: planar z in metres (distance along the optical axis), 0 where nothing was hit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics for images of ``width`` x ``height`` pixels.

    Defaults are the paper's: 600x450, 90 deg horizontal field of view (fx = fy = 300,
    cx = 300, cy = 225). Pixel centres are at integer coordinates (OpenCV convention: the
    top-left pixel covers [-0.5, 0.5]^2).
    """

    width: int = 600
    height: int = 450
    fx: float = 300.0
    fy: float = 300.0
    cx: float = 300.0
    cy: float = 225.0

    @classmethod
    def from_fov(cls, width: int = 600, height: int = 450, hfov_deg: float = 90.0) -> "Intrinsics":
        """Square pixels, principal point at the image centre, given horizontal FOV in degrees."""
        f = (width / 2.0) / np.tan(np.radians(hfov_deg) / 2.0)
        return cls(width, height, float(f), float(f), width / 2.0, height / 2.0)

    @property
    def K(self) -> np.ndarray:
        """(3, 3) camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def hfov_rad(self) -> float:
        """Horizontal field of view in radians."""
        return 2.0 * float(np.arctan(self.width / (2.0 * self.fx)))

    @property
    def vfov_rad(self) -> float:
        """Vertical field of view in radians."""
        return 2.0 * float(np.arctan(self.height / (2.0 * self.fy)))


def rotation_from_yaw(yaw: float) -> np.ndarray:
    """(3, 3) ``world_from_cam`` rotation of a level camera looking along yaw (radians)."""
    c, s = np.cos(yaw), np.sin(yaw)
    x_cam = np.array([s, -c, 0.0])
    y_cam = np.array([0.0, 0.0, -1.0])
    z_cam = np.array([c, s, 0.0])
    return np.stack([x_cam, y_cam, z_cam], axis=1)


def world_from_cam_pose(position: np.ndarray, yaw: float) -> np.ndarray:
    """(4, 4) ``world_from_cam`` for a level camera at ``position`` (3,) metres looking along yaw."""
    T = np.eye(4)
    T[:3, :3] = rotation_from_yaw(yaw)
    T[:3, 3] = np.asarray(position, dtype=float)
    return T


def world_from_cam_poses(positions: np.ndarray, yaws: np.ndarray) -> np.ndarray:
    """Batched :func:`world_from_cam_pose`: (N, 3) positions and (N,) yaws -> (N, 4, 4)."""
    positions = np.asarray(positions, dtype=float)
    yaws = np.asarray(yaws, dtype=float)
    c, s = np.cos(yaws), np.sin(yaws)
    T = np.zeros((len(yaws), 4, 4))
    T[:, 0, 0], T[:, 1, 0] = s, -c
    T[:, 2, 1] = -1.0
    T[:, 0, 2], T[:, 1, 2] = c, s
    T[:, :3, 3] = positions
    T[:, 3, 3] = 1.0
    return T


def yaw_of(world_from_cam: np.ndarray) -> float:
    """Yaw (radians) of the optical axis of a ``world_from_cam`` pose, projected on the xy-plane."""
    z = world_from_cam[:3, 2]
    return float(np.arctan2(z[1], z[0]))


def world_from_marker_pose(center: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(4, 4) ``world_from_marker`` for a tag centred at ``center`` on a vertical wall.

    ``normal`` (3,) is the wall normal pointing towards viewers; its z part is dropped so the
    tag hangs upright. Marker frame: z = normal, y = world up, x = y cross z (viewer's right).
    """
    n = np.asarray(normal, dtype=float).copy()
    n[2] = 0.0
    norm = np.linalg.norm(n)
    if norm < 1e-9:
        raise ValueError("marker normal must not be vertical")
    z = n / norm
    y = UP.copy()
    x = np.cross(y, z)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2] = x, y, z
    T[:3, 3] = np.asarray(center, dtype=float)
    return T


def marker_corners_local(size: float) -> np.ndarray:
    """(4, 3) corners of the black square in the marker frame, metres.

    Order: bottom-left, bottom-right, top-right, top-left as seen by a facing viewer: the order
    of the AprilTag library's detections (``apriltag_detection.p``, pupil-apriltags'
    ``Detection.corners``: counter-clockwise in the image, from the bottom-left), so detected
    corners pair with these by index.
    """
    h = size / 2.0
    return np.array([[-h, -h, 0.0], [h, -h, 0.0], [h, h, 0.0], [-h, h, 0.0]])


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of (..., 4, 4) rigid transforms."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    out = np.zeros_like(T)
    Rt = np.swapaxes(R, -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, t)
    out[..., 3, 3] = 1.0
    return out


def transform_points(a_from_b: np.ndarray, points_b: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) transform to (N, 3) points."""
    return points_b @ a_from_b[:3, :3].T + a_from_b[:3, 3]


def project(K: np.ndarray, world_from_cam: np.ndarray, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project (N, 3) world points. Returns (N, 2) pixels and (N,) planar depth (z in camera)."""
    p_cam = transform_points(invert(world_from_cam), points_world)
    z = p_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = (p_cam[:, :2] / z[:, None]) * np.array([K[0, 0], K[1, 1]]) + np.array([K[0, 2], K[1, 2]])
    return uv, z


def project_with_depth_lookup(depth: np.ndarray, world_from_cam: np.ndarray, K: np.ndarray,
                              points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project world points and read the rendered depth under each one.

    Args:
        depth: (H, W) planar depth image in metres (0 where nothing was hit).
        world_from_cam: (4, 4) pose of that image.
        K: (3, 3) intrinsics.
        points_world: (N, 3) world points.

    Returns:
        uv (N, 2) pixel coordinates (meaningless where z <= 1e-3), z (N,) planar depth of the
        points, surface (N,) rendered depth at the nearest pixel (0 behind the camera or
        outside the image).
    """
    H, W = depth.shape
    cam_from_world = invert(world_from_cam)
    p = np.asarray(points_world, dtype=float) @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
    z = p[:, 2]
    front = z > 1e-3
    zs = np.where(front, z, 1.0)
    uv = np.stack([K[0, 0] * p[:, 0] / zs + K[0, 2], K[1, 1] * p[:, 1] / zs + K[1, 2]], axis=1)
    ui, vi = np.round(uv[:, 0]).astype(int), np.round(uv[:, 1]).astype(int)
    inside = front & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
    surface = np.zeros_like(z)
    surface[inside] = depth[vi[inside], ui[inside]]
    return uv, z, surface


def backproject(K: np.ndarray, world_from_cam: np.ndarray, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(N, 2) pixels with (N,) planar depth in metres -> (N, 3) world points."""
    x = (uv[:, 0] - K[0, 2]) / K[0, 0] * depth
    y = (uv[:, 1] - K[1, 2]) / K[1, 1] * depth
    p_cam = np.stack([x, y, depth], axis=1)
    return transform_points(world_from_cam, p_cam)


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors -> (..., 3, 3) cross-product matrices ``[v]x``."""
    v = np.asarray(v)
    out = np.zeros(v.shape[:-1] + (3, 3), dtype=v.dtype if v.dtype.kind == "f" else float)
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def so3_exp(omega: np.ndarray) -> np.ndarray:
    """Rodrigues: (3,) rotation vector -> (3, 3) rotation."""
    theta = float(np.linalg.norm(omega))
    if theta < 1e-12:
        return np.eye(3) + skew(omega)
    k = skew(np.asarray(omega) / theta)
    return np.eye(3) + np.sin(theta) * k + (1 - np.cos(theta)) * k @ k


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angular distance in degrees between two rotations (the paper's delta_R)."""
    c = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def adjoint(T: np.ndarray) -> np.ndarray:
    """(6, 6) adjoint of a 4x4 transform for tangent vectors ordered (omega, nu), GTSAM's order."""
    R = T[:3, :3]
    t = T[:3, 3]
    A = np.zeros((6, 6))
    A[:3, :3] = R
    A[3:, 3:] = R
    A[3:, :3] = skew(t) @ R
    return A
