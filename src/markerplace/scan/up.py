"""The up axis of a frame set: parsing ``--up``, estimating it, and the rotation that makes it +z.

Every frame set is handed out in a world whose +z is up (what ``plan`` expects of a mesh). The up
direction of the input's world comes, in this order, from ``--up``, the layout itself (a gravity
file, or a world frame the layout defines), or an estimate:

* :func:`estimate_up_from_cameras`: people hold cameras roughly level (little roll), so up is
  the direction most nearly perpendicular to the cameras' x axes, else (a camera that barely
  turned) the mean of their up axes (the OpenCV camera's -y axis in the world); the spread is
  the arcsine of the mean ``|u_i x up|`` over the up axes (degrees), warned about over
  :data:`SPREAD_WARN_DEG`;
* :func:`estimate_up_from_mesh`: the dominant normal of the horizontal surfaces (floors, table
  tops) within :data:`MESH_SEARCH_DEG` of a prior up, used by ``fuse`` to refine the camera
  estimate (only when within :data:`MESH_REFINE_DEG` of it).

:func:`rotation_to_z_up` is the minimal rotation taking the up vector to +z (no change of
heading); :func:`world_from_input` its (4, 4) homogeneous form. Vectors are (3,) float64, unit
length; poses (4, 4) ``world_from_cam`` (OpenCV camera axes), metres.
"""

from __future__ import annotations

import logging
import math
from typing import Sequence

import numpy as np

from markerplace.errors import UserError

log = logging.getLogger(__name__)

SPREAD_WARN_DEG = 30.0
"""A camera estimate whose spread (degrees) exceeds this is logged as a warning."""
MESH_SEARCH_DEG = 25.0
"""Upward normals within this angle (degrees) of the prior up are candidate floor/table normals."""
MESH_REFINE_DEG = 15.0
"""``fuse`` adopts the mesh estimate only within this angle (degrees) of the camera estimate."""

UP_SOURCE_CAMERAS = "estimated from the cameras' down axes"
"""``FrameSet.up_source`` of an up axis estimated by :func:`estimate_up_from_cameras`."""

_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


def parse_up(value: str | Sequence[float] | np.ndarray, option: str = "--up") -> np.ndarray:
    """The unit up vector of ``x, y, z, -x, -y, -z`` or three numbers (``"0,0.9,0.4"``).

    Raises:
        UserError: anything else, or a zero or non-finite vector.
    """
    if isinstance(value, str):
        s = value.strip().lower().replace("+", "")
        sign = -1.0 if s.startswith("-") and s[1:] in _AXES else 1.0
        if s.lstrip("-") in _AXES and len(s) <= 2:
            return sign * np.array(_AXES[s.lstrip("-")])
        parts = s.replace(",", " ").split()
        try:
            vec = np.array([float(p) for p in parts], dtype=np.float64)
        except ValueError:
            vec = np.zeros(0)
    else:
        vec = np.asarray(value, dtype=np.float64).reshape(-1)
    if vec.shape != (3,) or not np.all(np.isfinite(vec)) or np.linalg.norm(vec) < 1e-9:
        raise UserError(f"{option} {value!r}: give x, y, z, -x, -y, -z or three numbers such as 0,0.9,0.4 "
                        "(the up direction in the input's world frame)")
    return vec / np.linalg.norm(vec)


def rotation_to_z_up(up: np.ndarray) -> np.ndarray:
    """(3, 3) minimal rotation taking unit ``up`` to +z (about the axis ``up x z``; 180 deg about
    x when ``up`` is -z)."""
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    z = np.array([0.0, 0.0, 1.0])
    c = float(np.dot(u, z))
    axis = np.cross(u, z)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + s * Kx + (1.0 - c) * (Kx @ Kx)


def world_from_input(up: np.ndarray) -> np.ndarray:
    """(4, 4) rotation of :func:`rotation_to_z_up` as a homogeneous transform."""
    T = np.eye(4)
    T[:3, :3] = rotation_to_z_up(up)
    return T


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two vectors, degrees."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def estimate_up_from_cameras(world_from_cams: Sequence[np.ndarray]) -> tuple[np.ndarray, float]:
    """Up from how the cameras were held (OpenCV axes: x right, y down).

    People hold cameras with little roll but look up and down at will, and often mostly one way
    (a kitchen counter): the cameras' x axes are then close to horizontal whatever the pitch,
    while the mean of their up axes (-y) leans towards where they looked (25 deg on 7-Scenes'
    redkitchen, whose cameras look down 25 deg on average). So the estimate is the direction
    most nearly perpendicular to every x axis (the eigenvector of the smallest eigenvalue of
    ``mean(x_i x_i^T)``), signed like the mean up axis; when the x axes are too close to one
    direction for that to be determined (second eigenvalue under :data:`_X_SPAN_MIN`: the
    camera barely turned), or it is over 60 deg from the mean up axis, the normalised mean of the
    up axes is used instead.

    Returns:
        (unit up (3,), spread in degrees: arcsine of the mean ``|u_i x up|`` over the cameras'
        up axes ``u_i``, the measure warned about over :data:`SPREAD_WARN_DEG`).

    Raises:
        UserError: no cameras, or up axes that cancel out (cameras held every way).
    """
    Rs = np.array([np.asarray(T, dtype=np.float64)[:3, :3] for T in world_from_cams]).reshape(-1, 3, 3)
    if len(Rs) == 0:
        raise UserError("cannot estimate the up axis without cameras")
    ups = -Rs[:, :, 1]
    mean = ups.mean(axis=0)
    n = float(np.linalg.norm(mean))
    if n < 0.1:
        raise UserError("cannot estimate the up axis: the cameras are held every way (give --up, e.g. --up z)")
    up = mean / n
    xs = Rs[:, :, 0]
    w, v = np.linalg.eigh(xs.T @ xs / len(xs))
    perp = v[:, 0] * (1.0 if float(v[:, 0] @ up) >= 0 else -1.0)
    how = "mean of the up axes"
    if w[1] >= _X_SPAN_MIN and angle_deg(perp, up) <= 60.0:
        how = f"perpendicular to the x axes, {angle_deg(perp, up):.1f} deg from the mean up axis"
        up = perp
    spread = math.degrees(math.asin(min(1.0, float(np.mean(np.linalg.norm(np.cross(ups, up), axis=1))))))
    roll = math.degrees(math.asin(min(1.0, float(np.mean(np.abs(xs @ up))))))
    log.info("camera up estimate (%s): mean |roll| %.1f deg, up-axis spread %.1f deg", how, roll, spread)
    return up, spread


_X_SPAN_MIN = 0.02
"""Second-smallest eigenvalue of ``mean(x_i x_i^T)`` needed to trust the x-axis estimate
(about 16 deg of heading spread: the x axes must span a plane)."""


def estimate_up_from_mesh(vertices: np.ndarray, normals: np.ndarray, prior: Sequence[float] = (0.0, 0.0, 1.0),
                          search_deg: float = MESH_SEARCH_DEG) -> np.ndarray | None:
    """The dominant normal of the horizontal surfaces facing up (floors, table tops).

    Args:
        vertices: (N, 3) mesh vertices (metres); used only to count.
        normals: (N, 3) vertex normals, pointing out of the surface into free space.
        prior: up direction to search around (default +z: a mesh already in a z-up world).
        search_deg: normals within this angle of ``prior`` are candidates.

    Returns:
        unit (3,) up, or None when fewer than 200 vertices or 2 % of them face up within
        ``search_deg``. The estimate starts at the mean of the candidates and moves to the mean
        of those within 6 deg of it until it settles (the dominant mode, not the average of
        slopes and ramps).
    """
    V = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    N = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    if len(N) == 0 or len(N) != len(V):
        return None
    norm = np.linalg.norm(N, axis=1)
    ok = norm > 1e-9
    N = N[ok] / norm[ok, None]
    p = np.asarray(prior, dtype=np.float64)
    p = p / np.linalg.norm(p)
    cand = N[N @ p > math.cos(math.radians(search_deg))]
    if len(cand) < max(200, 0.02 * len(V)):
        return None
    up = cand.mean(axis=0)
    up /= np.linalg.norm(up)
    for _ in range(30):  # mean shift with a flat 6 deg window: to the mode, not the mean
        near = cand[cand @ up > math.cos(math.radians(6.0))]
        if len(near) < 100:
            break
        new = near.mean(axis=0)
        new /= np.linalg.norm(new)
        moved = float(np.linalg.norm(new - up))
        up = new
        if moved < 1e-6:
            break
    return up


__all__ = ["SPREAD_WARN_DEG", "MESH_SEARCH_DEG", "MESH_REFINE_DEG", "UP_SOURCE_CAMERAS", "parse_up", "rotation_to_z_up",
           "world_from_input", "angle_deg", "estimate_up_from_cameras", "estimate_up_from_mesh"]
