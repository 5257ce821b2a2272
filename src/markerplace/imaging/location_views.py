"""Look at a camera location once: render every other yaw of a location as a taller "face" and
give the yaws between two faces the faces' features instead of rendering and extracting them.

Why: on a scan, rendering and SIFT are nearly all of the plan's time (benchmarks/plan_profile.py),
and the ``num_yaws`` level poses of a location look at the same surroundings twice over (with the
paper's 8 yaws and a 90 deg camera, each view shares half its width with each neighbour). All
poses of a location share the camera centre, so every ray of an in-between ("odd") pose is a ray
of one of its two neighbouring faces: its 3D features can be read off those faces' features.

The layout (:func:`face_layout`): the faces are the poses of even index j within a location (a
group of consecutive poses with one centre, as the discretization makes them); face j is rendered
with the pose's own rotation and focal lengths but a camera ``ox`` columns and ``oy`` rows larger on
each side, so that (a) the pose's own image is the face's centre crop, pixel for pixel the same
rays, and (b) every ray of an odd neighbour j +- 1 that is nearer this face's axis than the other
neighbour's falls inside the face with a margin of :data:`FACE_MARGIN_PX` (SIFT finds no keypoint
within a few pixels of a border). For the paper's camera (600x450, 90 deg) and 8 yaws the face is
632x674 pixels.

What each pose gets (:func:`split_features`): an even pose, the face's keypoints inside its crop
(shifted by ``(ox, oy)``); an odd pose, the keypoints of both neighbouring faces whose ray is
nearer that face's axis (the bisector splits them, so none twice) and inside the odd pose's
image, at their projection into it; descriptors and 3D points as the face found them. An odd
pose's features are therefore not those SIFT would find in its own render (a surface seen near a
face's edge is stretched there, by up to 1 / cos^2 45 deg = 2x): how much the planner's scores
change is measured, not assumed (benchmarks/location_views.py, docs/results/benchmarks.md).
Candidate occlusion of an odd pose reads the depth of the face each sample's ray belongs to.

Not for the testbed's map images (those must be the renders a test would make; observe renders
per pose whenever it also writes them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from markerplace.geometry import Intrinsics
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import ImageFeatures
from markerplace.imaging.visibility import markers_unoccluded

__all__ = ["FACE_MARGIN_PX", "FaceLayout", "face_layout", "location_groups", "split_features",
           "unoccluded_from_faces", "crop", "warp_view"]

FACE_MARGIN_PX = 16
"""Pixels a face extends beyond the farthest ray it must serve (SIFT's border and its blur)."""

MIN_COS = 0.5
"""A ray more than 60 deg off the face axis that serves it: the layout is refused (per pose)."""


@dataclass(frozen=True)
class FaceLayout:
    """How the poses of a location are looked at.

    Attributes:
        camera: the pose camera (every pose's image).
        face: the face camera: the pose camera's focal lengths, principal point shifted by
            ``(ox, oy)``, ``ox`` and ``oy`` more pixels on each side.
        ox, oy: the pose image is the face's crop ``[oy : oy + H, ox : ox + W]``.
    """

    camera: Intrinsics
    face: Intrinsics
    ox: int
    oy: int

    def face_config(self, config: ImagingConfig) -> ImagingConfig:
        """``config`` for rendering faces: the face camera, SIFT's feature cap scaled by the area."""
        sift = config.sift
        if sift.nfeatures:
            area = (self.face.width * self.face.height) / (self.camera.width * self.camera.height)
            sift = replace(sift, nfeatures=int(math.ceil(sift.nfeatures * area)))
        return replace(config, camera=self.face, sift=sift)


def location_groups(world_from_cam: np.ndarray) -> list[np.ndarray]:
    """Indices of the runs of consecutive poses with the same camera centre (bit for bit), in order.

    Args:
        world_from_cam: (N, 4, 4) poses.
    """
    T = np.asarray(world_from_cam, float)
    if len(T) == 0:
        return []
    change = np.flatnonzero(np.any(T[1:, :3, 3] != T[:-1, :3, 3], axis=1)) + 1
    return np.split(np.arange(len(T)), change)


def _pixel_rays(camera: Intrinsics, step: int = 4) -> np.ndarray:
    """(P, 3) camera-frame rays (z = 1) of a grid of pixel centres, the border rows and columns
    included."""
    us = np.unique(np.r_[np.arange(0, camera.width, step), camera.width - 1]).astype(float)
    vs = np.unique(np.r_[np.arange(0, camera.height, step), camera.height - 1]).astype(float)
    # the pixel edges too: a keypoint may sit up to half a pixel outside the centres
    us = np.r_[-0.5, us, camera.width - 0.5]
    vs = np.r_[-0.5, vs, camera.height - 0.5]
    u, v = np.meshgrid(us, vs)
    return np.stack([(u.ravel() - camera.cx) / camera.fx, (v.ravel() - camera.cy) / camera.fy,
                     np.ones(u.size)], axis=1)


def _nearer(rays_a: np.ndarray, rays_b: np.ndarray) -> np.ndarray:
    """(P,) bool: the ray is nearer face a's axis than face b's (rays in each face's frame)."""
    return rays_a[:, 2] / np.linalg.norm(rays_a, axis=1) >= rays_b[:, 2] / np.linalg.norm(rays_b, axis=1)


def face_layout(world_from_cam: np.ndarray, groups: list[np.ndarray], camera: Intrinsics) -> FaceLayout | None:
    """The face layout serving every odd pose of every group, or None where faces cannot serve
    them (a group of fewer than 3 poses, a ray more than 60 deg off its face's axis, or a face
    more than twice the pose image in either direction): then observe renders every pose.

    Args:
        world_from_cam: (N, 4, 4) poses.
        groups: :func:`location_groups` of them.
        camera: the pose camera.
    """
    T = np.asarray(world_from_cam, float)
    rays = _pixel_rays(camera)
    need_x = need_y = 0.0
    seen: set[bytes] = set()
    for g in groups:
        if len(g) < 3:
            return None
        for j in range(1, len(g), 2):
            R_odd = T[g[j], :3, :3]
            nbrs = [T[g[j - 1], :3, :3], T[g[(j + 1) % len(g)], :3, :3]]
            key = np.round(np.concatenate([(n.T @ R_odd).ravel() for n in nbrs]), 9).tobytes()
            if key in seen:
                continue
            seen.add(key)
            in_face = [rays @ (n.T @ R_odd).T for n in nbrs]  # rays in each face's frame
            for a, b in ((0, 1), (1, 0)):
                r = in_face[a][_nearer(in_face[a], in_face[b])]
                if len(r) == 0:
                    continue
                if np.min(r[:, 2] / np.linalg.norm(r, axis=1)) < MIN_COS:
                    return None
                need_x = max(need_x, float(np.max(np.abs(r[:, 0] / r[:, 2]))) * camera.fx)
                need_y = max(need_y, float(np.max(np.abs(r[:, 1] / r[:, 2]))) * camera.fy)
    need_x += FACE_MARGIN_PX
    need_y += FACE_MARGIN_PX
    ox = max(0, math.ceil(max(need_x - camera.cx, camera.cx + need_x - camera.width + 1)))
    oy = max(0, math.ceil(max(need_y - camera.cy, camera.cy + need_y - camera.height + 1)))
    if ox > camera.width / 2 or oy > camera.height / 2:
        return None
    face = Intrinsics(camera.width + 2 * ox, camera.height + 2 * oy, camera.fx, camera.fy,
                      camera.cx + ox, camera.cy + oy)
    return FaceLayout(camera, face, ox, oy)


def _face_rays(layout: FaceLayout, keypoints: np.ndarray) -> np.ndarray:
    """(K, 3) face-frame rays (z = 1) of face keypoints (K, 2)."""
    f = layout.face
    kp = np.asarray(keypoints, float).reshape(-1, 2)
    return np.stack([(kp[:, 0] - f.cx) / f.fx, (kp[:, 1] - f.cy) / f.fy, np.ones(len(kp))], axis=1)


def _inside(camera: Intrinsics, uv: np.ndarray) -> np.ndarray:
    return (uv[:, 0] >= -0.5) & (uv[:, 0] < camera.width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < camera.height - 0.5)


def split_features(layout: FaceLayout, pose: np.ndarray, faces: list[tuple[np.ndarray, ImageFeatures]]) -> ImageFeatures:
    """The features of the pose ``pose`` from its faces.

    Args:
        layout: the face layout.
        pose: (4, 4) world_from_cam of the pose.
        faces: [(face world_from_cam (4, 4), the face's features)]: one face (the pose's own:
            its crop) or the two neighbours of an odd pose (each keeps the rays nearer its axis).

    Returns:
        keypoints in the pose image's pixels, descriptors and 3D points as the faces found them,
        the first face's keypoints first.
    """
    cam = layout.camera
    R = np.asarray(pose, float)[:3, :3]
    parts = []
    for i, (face_pose, feats) in enumerate(faces):
        Rf = np.asarray(face_pose, float)[:3, :3]
        rays_face = _face_rays(layout, feats.keypoints)
        rays_pose = rays_face @ (R.T @ Rf).T
        keep = rays_pose[:, 2] > 1e-6
        for j, (other_pose, _) in enumerate(faces):
            if j != i:
                Ro = np.asarray(other_pose, float)[:3, :3]
                keep &= _nearer(rays_face, rays_face @ (Ro.T @ Rf).T) if j > i else \
                    ~_nearer(rays_face @ (Ro.T @ Rf).T, rays_face)
        z = np.where(keep, rays_pose[:, 2], 1.0)
        uv = np.stack([cam.fx * rays_pose[:, 0] / z + cam.cx, cam.fy * rays_pose[:, 1] / z + cam.cy], axis=1)
        keep &= _inside(cam, uv)
        parts.append((uv[keep], feats.descriptors[keep], feats.points_world[keep]))
    if not parts:
        return ImageFeatures(np.zeros((0, 2), np.float32), np.zeros((0, 128), np.uint8), np.zeros((0, 3), np.float32))
    return ImageFeatures(np.concatenate([p[0] for p in parts]).astype(np.float32),
                         np.concatenate([p[1] for p in parts]), np.concatenate([p[2] for p in parts]))


def unoccluded_from_faces(layout: FaceLayout, pose: np.ndarray, faces: list[tuple[np.ndarray, np.ndarray]],
                          samples: np.ndarray, tolerance: float) -> np.ndarray:
    """(M,) bool: :func:`~markerplace.imaging.visibility.markers_unoccluded` for the pose
    ``pose``, every sample's surface read from the face whose axis its ray is nearer.

    Args:
        faces: [(face world_from_cam, face planar depth (H', W'))], one or two as in
            :func:`split_features`.
        samples: (M, S, 3) world sample points.
    """
    if len(samples) == 0:
        return np.zeros(0, bool)
    if len(faces) == 1:
        depth = faces[0][1][layout.oy:layout.oy + layout.camera.height, layout.ox:layout.ox + layout.camera.width]
        return markers_unoccluded(depth, pose, layout.camera.K, samples, tolerance)
    cam = layout.camera
    pts = np.asarray(samples, float).reshape(-1, 3)
    T = np.asarray(pose, float)
    p = (pts - T[:3, 3]) @ T[:3, :3]
    z = p[:, 2]
    zs = np.where(z > 1e-3, z, 1.0)
    uv = np.stack([cam.fx * p[:, 0] / zs + cam.cx, cam.fy * p[:, 1] / zs + cam.cy], axis=1)
    ui, vi = np.round(uv[:, 0]), np.round(uv[:, 1])
    inside = (z > 1e-3) & (ui >= 0) & (ui < cam.width) & (vi >= 0) & (vi < cam.height)
    in_face = [(pts - Tf[:3, 3]) @ np.asarray(Tf, float)[:3, :3] for Tf, _ in faces]
    first = _nearer(in_face[0], in_face[1])
    ok = np.ones(len(pts), bool)
    f = layout.face
    for i, (_, depth) in enumerate(faces):
        sel = inside & (first if i == 0 else ~first)
        q = in_face[i][sel]
        qz = np.where(q[:, 2] > 1e-3, q[:, 2], 1.0)
        fu = np.round(f.fx * q[:, 0] / qz + f.cx).astype(int)
        fv = np.round(f.fy * q[:, 1] / qz + f.cy).astype(int)
        within = (q[:, 2] > 1e-3) & (fu >= 0) & (fu < f.width) & (fv >= 0) & (fv < f.height)
        surface = np.zeros(len(q))
        surface[within] = depth[fv[within], fu[within]]
        ok[sel] = (surface == 0) | (surface >= q[:, 2] - tolerance)
    return (inside & ok).reshape(samples.shape[:2]).all(axis=1)


def crop(layout: FaceLayout, image: np.ndarray) -> np.ndarray:
    """The pose image's part ``[oy : oy + H, ox : ox + W]`` of a face image (H', W', ...)."""
    return image[layout.oy:layout.oy + layout.camera.height, layout.ox:layout.ox + layout.camera.width]


_WARP_MAPS: dict[bytes, list] = {}


def _warp_maps(layout: FaceLayout, rotations: list[np.ndarray]) -> list:
    """Per face: (selected pixels (H*W,) bool, map_x, map_y (H, W) float32, 1 / ray z (H*W,)) of
    the pose image's pixels served by that face; cached per relative rotation."""
    key = np.round(np.concatenate([r.ravel() for r in rotations]), 9).tobytes() + repr(layout).encode()
    if key in _WARP_MAPS:
        return _WARP_MAPS[key]
    cam, f = layout.camera, layout.face
    u, v = np.meshgrid(np.arange(cam.width, dtype=float), np.arange(cam.height, dtype=float))
    rays = np.stack([(u.ravel() - cam.cx) / cam.fx, (v.ravel() - cam.cy) / cam.fy, np.ones(u.size)], axis=1)
    in_face = [rays @ r.T for r in rotations]
    first = _nearer(in_face[0], in_face[1])
    maps = []
    for i, q in enumerate(in_face):
        z = np.where(q[:, 2] > 1e-6, q[:, 2], 1e-6)
        mx = (f.fx * q[:, 0] / z + f.cx).astype(np.float32).reshape(cam.height, cam.width)
        my = (f.fy * q[:, 1] / z + f.cy).astype(np.float32).reshape(cam.height, cam.width)
        maps.append((first if i == 0 else ~first, mx, my, 1.0 / z))
    if len(_WARP_MAPS) > 64:
        _WARP_MAPS.clear()
    _WARP_MAPS[key] = maps
    return maps


def warp_view(layout: FaceLayout, pose: np.ndarray, faces: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
              ) -> tuple[np.ndarray, np.ndarray]:
    """The pose's image and planar depth resampled from its two neighbouring faces (a rotation
    about the camera centre is a homography: exact up to the resampling).

    Args:
        faces: two [(face world_from_cam, face RGB (H', W', 3) uint8, face depth (H', W'))].

    Returns:
        RGB (H, W, 3) uint8 (bilinear) and planar depth (H, W) float32 in metres (nearest face
        pixel, converted to the pose's planar depth; 0 where nothing was hit).
    """
    import cv2

    cam = layout.camera
    R = np.asarray(pose, float)[:3, :3]
    maps = _warp_maps(layout, [np.asarray(T, float)[:3, :3].T @ R for T, _, _ in faces])
    rgb = np.zeros((cam.height * cam.width, 3), np.uint8)
    depth = np.zeros(cam.height * cam.width, np.float32)
    for (sel, mx, my, inv_z), (_, face_rgb, face_depth) in zip(maps, faces):
        rgb[sel] = cv2.remap(face_rgb, mx, my, cv2.INTER_LINEAR).reshape(-1, 3)[sel]
        d = cv2.remap(face_depth, mx, my, cv2.INTER_NEAREST).reshape(-1)
        depth[sel] = (d * inv_z)[sel]
    return rgb.reshape(cam.height, cam.width, 3), depth.reshape(cam.height, cam.width)
