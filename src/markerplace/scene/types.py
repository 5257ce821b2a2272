"""In-memory scene representation shared by the loader, the procedural generator and the renderer.

A :class:`Scene` is a list of :class:`MeshPart` in the world frame (z up, metres). Each part has
one material: an optional texture (with per-vertex UVs), optional per-vertex colours, and a base
colour multiplied with both. Parts may share one texture array object (repeated items); the
renderer uploads each distinct array once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True, eq=False)
class MeshPart:
    """One triangle mesh with one material.

    Attributes:
        name: human-readable name (e.g. ``"office/desk_3"``).
        vertices: (N, 3) float32, world frame, metres, z up.
        faces: (M, 3) int32 vertex indices, counter-clockwise seen from outside.
        uv: (N, 2) float32 texture coordinates, or None. glTF/trimesh convention: (0, 0) is the
            bottom-left of the texture image as displayed (i.e. v grows upwards).
        colors: (N, 4) uint8 RGBA vertex colours, or None.
        texture: (H, W, 3) uint8 RGB image (row 0 = top), or None.
        base_color: (4,) float RGBA in [0, 1], multiplied with texture / vertex colour.
        normals: (N, 3) float32 unit vertex normals, or None (renderer then uses face normals).
        transparent: glass or another see-through material (glTF ``alphaMode`` BLEND with
            alpha < 0.9 or ``KHR_materials_transmission``; OBJ ``d`` < 0.9 or ``Tr`` > 0.1; see
            :mod:`markerplace.scene.transparency`). It still bounds free space (nobody walks
            through glass) but never carries a tag.
        names: what the source calls the part, for :func:`markerplace.scene.semantics.classify`
            (which keeps tags off windows, doors, furniture, ...): for a glTF file the node, its
            parent nodes, the mesh and the material; for OBJ the object/group and the material;
            for the procedural scenes the item's label (``"bookshelf"``, ``"wall"``, ``"door"``).
            Empty when the source names nothing (a PLY scan): only geometry then tells.
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray | None = None
    colors: np.ndarray | None = None
    texture: np.ndarray | None = None
    base_color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    normals: np.ndarray | None = None
    transparent: bool = False
    names: tuple[str, ...] = ()


@dataclass(frozen=True)
class Room:
    """An axis-aligned room footprint of a procedural scene.

    Attributes:
        name: room name.
        bounds: (xmin, ymin, xmax, ymax) world metres.
        floor_z: height of the room's floor, world metres (a sunken room or an upper storey
            differs from 0).
    """

    name: str
    bounds: tuple[float, float, float, float]
    floor_z: float = 0.0

    @property
    def area(self) -> float:
        x0, y0, x1, y1 = self.bounds
        return (x1 - x0) * (y1 - y0)


@dataclass(frozen=True, eq=False)
class Scene:
    """A normalized scene: z up, metres, textured.

    Attributes:
        name: built-in name or file stem.
        parts: mesh parts in the world frame.
        rooms: room footprints when known (procedural scenes); empty for loaded meshes.
        floor_z: height of the main floor (metres) when known, else None.
        source: where it came from (``builtin:office`` or a file path).
    """

    name: str
    parts: tuple[MeshPart, ...]
    rooms: tuple[Room, ...] = ()
    floor_z: float | None = None
    source: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounding box [min, max] over all parts."""
        mins = np.min([p.vertices.min(axis=0) for p in self.parts], axis=0)
        maxs = np.max([p.vertices.max(axis=0) for p in self.parts], axis=0)
        return np.stack([mins, maxs]).astype(float)

    @property
    def num_faces(self) -> int:
        return int(sum(len(p.faces) for p in self.parts))

    def geometry(self) -> tuple[np.ndarray, np.ndarray]:
        """All parts concatenated: (V, 3) float64 vertices and (F, 3) int64 faces (for ray casting)."""
        verts, faces, offset = [], [], 0
        for p in self.parts:
            verts.append(np.asarray(p.vertices, dtype=float))
            faces.append(np.asarray(p.faces, dtype=np.int64) + offset)
            offset += len(p.vertices)
        return np.concatenate(verts), np.concatenate(faces)

    def face_transparent(self) -> np.ndarray:
        """(F,) bool per face of :meth:`geometry`: the face belongs to a transparent part."""
        return np.concatenate([np.full(len(p.faces), bool(p.transparent)) for p in self.parts])

    def face_part(self) -> np.ndarray:
        """(F,) int64 index into :attr:`parts` of each face of :meth:`geometry`."""
        return np.repeat(np.arange(len(self.parts), dtype=np.int64), [len(p.faces) for p in self.parts])

    def to_trimesh(self):
        """Untextured combined :class:`trimesh.Trimesh` for geometric queries (slicing, rays)."""
        import trimesh

        v, f = self.geometry()
        return trimesh.Trimesh(vertices=v, faces=f, process=False)
