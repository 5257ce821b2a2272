"""Mesh accumulation for procedural scenes: materials, textured quads and axis-aligned boxes.

World frame: z up, metres. :class:`MeshBuilder` collects quads per label and :class:`Material`
and emits one :class:`~markerplace.scene.types.MeshPart` per (label, material), so a whole scene
is a few dozen to a few hundred parts and repeated items share one texture array. The label says
truthfully what the quads are (``"wall"``, ``"door"``, ``"bookshelf"``: :meth:`MeshBuilder.labelled`);
it becomes the part's name (``"<scene>/<label>/<material>"``) and ``names`` (read by
:func:`markerplace.scene.semantics.classify`, which keeps tags off doors, windows, furniture, ...).
:func:`add_box` adds a box (optionally yawed and translated) with one material per face.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from markerplace.scene.builtin import textures as tx
from markerplace.scene.types import MeshPart

__all__ = ["AXES", "Material", "MeshBuilder", "add_box", "box_face"]

@dataclass(frozen=True)
class Material:
    """Texture key (or None), RGBA base colour, and UV mapping: ``repeat`` metres per texture
    repeat (planar, world-scaled), or None to stretch the texture once over each face.
    ``transparent`` marks glass: its part gets ``MeshPart.transparent`` and ``color``'s alpha is
    its opacity."""

    key: str
    texture: str | None = None
    color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    repeat: float | None = 1.0
    transparent: bool = False


class MeshBuilder:
    """Accumulates quads per (label, material) and emits one :class:`MeshPart` per pair.

    ``label`` (set with :meth:`labelled`) names what the quads added now belong to; ``""`` (the
    default) leaves them unlabelled.
    """

    def __init__(self, scene_name: str, bank: tx.TextureBank, texture_fns: dict):
        self.scene_name = scene_name
        self.bank = bank
        self.texture_fns = texture_fns
        self.label = ""
        self._data: dict[tuple[str, str], dict] = {}
        self._mats: dict[str, Material] = {}

    @contextmanager
    def labelled(self, label: str):
        """Within the ``with`` block, quads belong to ``label`` (e.g. ``"bookshelf"``)."""
        before, self.label = self.label, str(label)
        try:
            yield self
        finally:
            self.label = before

    def quad(self, mat: Material, corners: np.ndarray, uv: np.ndarray, normal: np.ndarray) -> None:
        """Add a quad: (4, 3) corners counter-clockwise seen from the ``normal`` side, (4, 2) uv."""
        d = self._data.setdefault((self.label, mat.key), {"v": [], "uv": [], "n": []})
        self._mats[mat.key] = mat
        d["v"].append(np.asarray(corners, dtype=np.float64))
        d["uv"].append(np.asarray(uv, dtype=np.float64))
        d["n"].append(np.broadcast_to(np.asarray(normal, dtype=np.float64), (4, 3)))

    def parts(self) -> list[MeshPart]:
        out = []
        for (label, key), d in self._data.items():
            mat = self._mats[key]
            v = np.concatenate(d["v"]).astype(np.float32)
            n_quads = len(d["v"])
            base = (np.arange(n_quads) * 4)[:, None]
            faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3).astype(np.int32)
            texture = None
            uv = None
            if mat.texture is not None:
                fn, args = self.texture_fns[mat.texture]
                texture = self.bank.get(mat.texture, fn, *args)
                uv = np.concatenate(d["uv"]).astype(np.float32)
            normals = np.concatenate(d["n"]).astype(np.float32)
            for arr in (v, faces, uv, normals):
                if arr is not None:
                    arr.flags.writeable = False
            out.append(
                MeshPart(
                    name=f"{self.scene_name}/{label}/{key}" if label else f"{self.scene_name}/{key}",
                    vertices=v,
                    faces=faces,
                    uv=uv,
                    texture=texture,
                    base_color=tuple(float(c) for c in mat.color),
                    normals=normals,
                    transparent=mat.transparent,
                    names=(label,) if label else (),
                )
            )
        return out


AXES = {
    "+x": (np.array([1.0, 0, 0]), np.array([0, 0, 1.0])),
    "-x": (np.array([-1.0, 0, 0]), np.array([0, 0, 1.0])),
    "+y": (np.array([0, 1.0, 0]), np.array([0, 0, 1.0])),
    "-y": (np.array([0, -1.0, 0]), np.array([0, 0, 1.0])),
    "+z": (np.array([0, 0, 1.0]), np.array([0, 1.0, 0])),
    "-z": (np.array([0, 0, -1.0]), np.array([0, -1.0, 0])),
}


def box_face(lo: np.ndarray, hi: np.ndarray, face: str):
    """Corners (4, 3), uv-plane coordinates (4, 2) in metres, normal, extent (w, h) of a box face.

    Corners go bottom-left, bottom-right, top-right, top-left as seen from outside: counter-clockwise.
    Right = up x normal, so images on vertical faces read left to right and upright.
    """
    n, up = AXES[face]
    right = np.cross(up, n)
    c = (lo + hi) / 2
    half = (hi - lo) / 2
    c = c + n * (np.abs(n) @ half)  # centre of the face
    hr = np.abs(right) @ half
    hu = np.abs(up) @ half
    corners = np.array([c - right * hr - up * hu, c + right * hr - up * hu, c + right * hr + up * hu, c - right * hr + up * hu])
    plane = np.stack([corners @ right, corners @ up], axis=1)
    return corners, plane, n, (2 * hr, 2 * hu)


def add_box(
    mb: MeshBuilder,
    lo,
    hi,
    mats: Material | dict[str, Material],
    transform: tuple[float, np.ndarray] | None = None,
    skip: tuple[str, ...] = ("-z",),
) -> None:
    """Add an axis-aligned box [lo, hi] (local metres) with one material or one per face.

    ``mats`` may map face names ("+x", "-x", "+y", "-y", "+z", "-z", or "*" for the rest) to
    materials. ``transform`` = (yaw radians, (3,) translation) places the local box in the world.
    Faces in ``skip`` are omitted (default: the bottom, which stands on something).
    """
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    if transform is not None:
        yaw, t = transform
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    for face in AXES:
        if face in skip:
            continue
        mat = mats if isinstance(mats, Material) else mats.get(face, mats.get("*"))
        if mat is None:
            continue
        corners, plane, n, (w, h) = box_face(lo, hi, face)
        if w <= 0 or h <= 0:
            continue
        if mat.repeat is None:
            uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        else:
            uv = plane / mat.repeat
        if transform is not None:
            corners = corners @ R.T + t
            n = R @ n
        mb.quad(mat, corners, uv, n)
