"""Poses the localizability and marker-model tests share."""

from __future__ import annotations

import numpy as np

from markerplace.geometry import world_from_marker_pose


def facing_marker(T, dist, lateral=0.0, yaw_offset_deg=0.0):
    """Marker ``dist`` m ahead of camera T (level), normal towards the camera rotated by an offset."""
    fwd = T[:3, 2]
    right = T[:3, 0]
    centre = T[:3, 3] + dist * fwd + lateral * right
    a = np.radians(yaw_offset_deg)
    n = -fwd
    n = np.array([np.cos(a) * n[0] - np.sin(a) * n[1], np.sin(a) * n[0] + np.cos(a) * n[1], 0.0])
    return world_from_marker_pose(centre, n)


def look_at_pose(eye, target) -> np.ndarray:
    """(4, 4) world_from_cam of an OpenCV camera (x right, y down, z forward) at ``eye`` looking
    at ``target``, world z up."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    T[:3, 3] = eye
    return T
