"""Ray queries on a triangle mesh: first hits and all hits along rays, on Intel Embree.

A thin layer over Open3D's :class:`open3d.t.geometry.RaycastingScene` (Embree BVH, multi-threaded)
so the rest of the package never tests rays against triangles itself. Embree works in float32;
to keep millimetre precision for models far from the origin (survey coordinates near 1e6 m) the
mesh and every ray are shifted by the mesh's bounding-box centre (float64) before the
conversion, and distances are returned in the original metres.

Both sides of every face are hit (no back-face culling): scans have inconsistent normals.

Frames: whatever frame the vertices are in (the package uses world z up, metres).
"""

from __future__ import annotations

import logging

import numpy as np

log = logging.getLogger(__name__)

__all__ = ["RayCaster"]


def _o3d():
    import open3d as o3d

    return o3d


class RayCaster:
    """A mesh prepared for ray queries.

    Args:
        vertices: (V, 3) vertex positions, metres (float64 or float32).
        faces: (F, 3) vertex indices.

    Attributes:
        vertices, faces: the mesh as given (float64, int64).
        face_normal: (F, 3) unit face normals (zero for degenerate faces), by the right-hand
            rule on the vertex order.
        face_area: (F,) face areas, square metres.
        centre: (3,) float64 offset subtracted before the float32 conversion.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        self.faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        tri = self.vertices[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area2 = np.linalg.norm(n, axis=1)
        self.face_area = 0.5 * area2
        with np.errstate(invalid="ignore", divide="ignore"):
            self.face_normal = np.where(area2[:, None] > 0, n / np.maximum(area2, 1e-300)[:, None], 0.0)
        if len(self.vertices):
            self.centre = 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))
        else:
            self.centre = np.zeros(3)
        self._scene = None

    @property
    def num_faces(self) -> int:
        return len(self.faces)

    def _embree(self):
        if self._scene is None:
            o3d = _o3d()
            scene = o3d.t.geometry.RaycastingScene()
            if len(self.faces):
                v = (self.vertices - self.centre).astype(np.float32)
                scene.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(self.faces.astype(np.uint32)))
            self._scene = scene
        return self._scene

    def _rays(self, origins: np.ndarray, dirs: np.ndarray):
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3) - self.centre
        d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        d = d / np.where(norm > 0, norm, 1.0)
        return _o3d().core.Tensor(np.concatenate([o, d], axis=1).astype(np.float32))

    def first_hits(self, origins: np.ndarray, dirs: np.ndarray, max_t: float | np.ndarray = np.inf
                   ) -> tuple[np.ndarray, np.ndarray]:
        """First intersection of each ray with the mesh.

        Args:
            origins: (M, 3) ray origins, metres.
            dirs: (M, 3) directions (normalized here).
            max_t: rays end at this distance, metres (scalar or (M,)).

        Returns:
            (M,) float64 hit distance (``inf`` where none within ``max_t``) and (M,) int64 face
            index (-1 where none).
        """
        M = len(np.asarray(origins).reshape(-1, 3))
        t = np.full(M, np.inf)
        f = np.full(M, -1, dtype=np.int64)
        if M == 0 or self.num_faces == 0:
            return t, f
        out = self._embree().cast_rays(self._rays(origins, dirs))
        th = out["t_hit"].numpy().astype(np.float64)
        ids = out["primitive_ids"].numpy().astype(np.int64)
        ok = np.isfinite(th) & (th <= np.broadcast_to(np.asarray(max_t, dtype=np.float64), (M,))) & (ids < self.num_faces)
        t[ok] = th[ok]
        f[ok] = ids[ok]
        return t, f

    def all_hits(self, origins: np.ndarray, dirs: np.ndarray, max_t: float | np.ndarray = np.inf,
                 step: float = 1e-4, max_hits: int = 256) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every intersection along each ray, nearest first per ray.

        Repeated first-hit queries, each ray restarting ``step`` metres past its last hit
        (Open3D's ``list_intersections`` was seen to corrupt the heap on large batches, so it
        is not used). Surfaces closer together than ``step`` along a ray count once.

        Args:
            origins: (M, 3) ray origins, metres.
            dirs: (M, 3) directions (normalized here).
            max_t: rays end at this distance, metres (scalar or (M,)).
            step: restart offset past each hit, metres.
            max_hits: at most this many hits per ray.

        Returns:
            ``ray`` (H,) int64 ray index, ``t`` (H,) float64 distance and ``face`` (H,) int64,
            sorted by ray and then by distance.
        """
        o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
        M = len(o)
        if M == 0 or self.num_faces == 0:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
        d = d / np.where(np.linalg.norm(d, axis=1, keepdims=True) > 0, np.linalg.norm(d, axis=1, keepdims=True), 1.0)
        lim = np.broadcast_to(np.asarray(max_t, dtype=np.float64), (M,)).copy()
        active = np.arange(M)
        offset = np.zeros(M)  # distance travelled so far
        rays, ts, faces = [], [], []
        for _ in range(max_hits):
            if len(active) == 0:
                break
            t, f = self.first_hits(o[active] + d[active] * offset[active, None], d[active], lim[active] - offset[active])
            hit = f >= 0
            active, t, f = active[hit], t[hit], f[hit]
            total = offset[active] + t
            rays.append(active)
            ts.append(total)
            faces.append(f)
            offset[active] = total + step
        if not rays:
            return np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int64)
        ray, t, face = np.concatenate(rays), np.concatenate(ts), np.concatenate(faces)
        order = np.lexsort((t, ray))
        return ray[order], t[order], face[order]
