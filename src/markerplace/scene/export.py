"""Write a :class:`Scene` as a standard binary glTF 2.0 file (.glb).

glTF is y-up: a world point (x, y, z) (z up) is written as (x, z, -y), the inverse of the loader's
conversion. UVs are flipped to glTF's convention (v down, origin at the image's top-left).
Textures are embedded once each as PNG (parts sharing one array share one image), materials are
metallic-roughness with metallic 0 and roughness 1, and the file is written atomically.
Transparent parts (``MeshPart.transparent``, glass) get their own materials with
``alphaMode: "BLEND"``, ``doubleSided`` and a ``baseColorFactor`` alpha below 1
(:func:`~markerplace.scene.transparency.drawn_alpha`: the part's alpha, or about 0.3), which the
loader reads back as transparent.
"""

from __future__ import annotations

import io
import json
import logging
import struct
from pathlib import Path

import numpy as np

from markerplace.runtime.atomic_io import atomic_path
from markerplace.scene.transparency import drawn_alpha
from markerplace.scene.types import Scene

log = logging.getLogger(__name__)

# gltf_from_world: (x, y, z) -> (x, z, -y)
GLTF_FROM_WORLD = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])

_FLOAT, _UINT, _UBYTE = 5126, 5125, 5121
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


class _GlbBuilder:
    """Accumulates the JSON tree and the binary buffer of one GLB file."""

    def __init__(self) -> None:
        self.tree: dict = {
            "asset": {"version": "2.0", "generator": "markerplace"},
            "scene": 0,
            "scenes": [{"nodes": []}],
            "nodes": [],
            "meshes": [],
            "materials": [],
            "textures": [],
            "images": [],
            "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497},
                         {"magFilter": 9728, "minFilter": 9728, "wrapS": 33071, "wrapT": 33071}],
            "accessors": [],
            "bufferViews": [],
            "buffers": [],
        }
        self.chunks: list[bytes] = []
        self.offset = 0
        self._images: dict[int, int] = {}
        self._materials: dict[tuple, int] = {}

    def view(self, data: bytes, target: int | None = None) -> int:
        pad = (-self.offset) % 4
        if pad:
            self.chunks.append(b"\0" * pad)
            self.offset += pad
        bv = {"buffer": 0, "byteOffset": self.offset, "byteLength": len(data)}
        if target is not None:
            bv["target"] = target
        self.tree["bufferViews"].append(bv)
        self.chunks.append(data)
        self.offset += len(data)
        return len(self.tree["bufferViews"]) - 1

    def accessor(self, array: np.ndarray, ctype: int, type_: str, target: int, normalized: bool = False, bounds: bool = False) -> int:
        array = np.ascontiguousarray(array)
        acc = {"bufferView": self.view(array.tobytes(), target), "componentType": ctype, "count": int(len(array)), "type": type_}
        if normalized:
            acc["normalized"] = True
        if bounds:
            acc["min"] = array.min(axis=0).tolist()
            acc["max"] = array.max(axis=0).tolist()
        self.tree["accessors"].append(acc)
        return len(self.tree["accessors"]) - 1

    def image(self, texture: np.ndarray, nearest: bool = False) -> int:
        """Texture index of an (H, W, 3) uint8 array; one PNG per distinct array object.
        ``nearest``: sampled without filtering (crisp tag modules at any distance)."""
        from PIL import Image

        key = id(texture)
        if key not in self._images:
            buf = io.BytesIO()
            Image.fromarray(np.ascontiguousarray(texture, dtype=np.uint8)).save(buf, format="PNG")
            self.tree["images"].append({"bufferView": self.view(buf.getvalue()), "mimeType": "image/png"})
            self.tree["textures"].append({"sampler": int(nearest), "source": len(self.tree["images"]) - 1})
            self._images[key] = len(self.tree["textures"]) - 1
        return self._images[key]

    def material(self, name: str, base_color, texture: np.ndarray | None, transparent: bool = False,
                 nearest: bool = False) -> int:
        """Material index for a base colour, texture and transparency (one material per distinct key)."""
        color = tuple(float(c) for c in base_color)
        if transparent:
            color = color[:3] + (drawn_alpha(color[3]),)
        key = (color, None if texture is None else id(texture), bool(transparent))
        if key not in self._materials:
            pbr: dict = {"baseColorFactor": list(color), "metallicFactor": 0.0, "roughnessFactor": 1.0}
            if texture is not None:
                pbr["baseColorTexture"] = {"index": self.image(texture, nearest)}
            material = {"name": name, "pbrMetallicRoughness": pbr}
            if transparent:
                material["alphaMode"] = "BLEND"
                material["doubleSided"] = True
            self.tree["materials"].append(material)
            self._materials[key] = len(self.tree["materials"]) - 1
        return self._materials[key]

    def to_bytes(self) -> bytes:
        binary = b"".join(self.chunks)
        binary += b"\0" * ((-len(binary)) % 4)
        self.tree["buffers"] = [{"byteLength": len(binary)}]
        tree = {k: v for k, v in self.tree.items() if v != []}
        text = json.dumps(tree, separators=(",", ":")).encode("utf-8")
        text += b" " * ((-len(text)) % 4)
        length = 12 + 8 + len(text) + 8 + len(binary)
        return b"".join(
            [
                struct.pack("<4sII", b"glTF", 2, length),
                struct.pack("<I4s", len(text), b"JSON"),
                text,
                struct.pack("<I4s", len(binary), b"BIN\0"),
                binary,
            ]
        )


def scene_to_glb_bytes(scene: Scene, data_from_world: np.ndarray | None = None, roots: list | None = None,
                       nearest_parts: frozenset = frozenset()) -> bytes:
    """Encode ``scene`` as GLB bytes, one mesh + node per part.

    Args:
        scene: parts in the world frame (z up, metres).
        data_from_world: (3, 3) linear map (rotation times a positive scale) from world to the
            stored vertex data; default :data:`GLTF_FROM_WORLD` (y-up metres). Normals get its
            rotation.
        roots: node dicts (``name`` with ``matrix`` (16 numbers, column-major) or
            ``translation``) nested in order, the parts' nodes under the last; default none: the
            part nodes are the scene's roots.
        nearest_parts: names of parts whose textures are sampled without filtering.
    """
    A = GLTF_FROM_WORLD if data_from_world is None else np.asarray(data_from_world, dtype=np.float64)
    N = np.linalg.inv(A).T
    b = _GlbBuilder()
    parent = None
    for root in roots or []:
        b.tree["nodes"].append({**root, "children": []})
        index = len(b.tree["nodes"]) - 1
        (b.tree["scenes"][0]["nodes"] if parent is None else b.tree["nodes"][parent]["children"]).append(index)
        parent = index
    for part in scene.parts:
        v = np.asarray(part.vertices, dtype=np.float64) @ A.T
        attrs = {"POSITION": b.accessor(v.astype(np.float32), _FLOAT, "VEC3", _ARRAY_BUFFER, bounds=True)}
        if part.normals is not None:
            n = np.asarray(part.normals, dtype=np.float64) @ N.T
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
            attrs["NORMAL"] = b.accessor(n.astype(np.float32), _FLOAT, "VEC3", _ARRAY_BUFFER)
        texture = part.texture if (part.texture is not None and part.uv is not None) else None
        if texture is not None:
            uv = np.asarray(part.uv, dtype=np.float64).copy()
            uv[:, 1] = 1.0 - uv[:, 1]  # glTF: v down
            attrs["TEXCOORD_0"] = b.accessor(uv.astype(np.float32), _FLOAT, "VEC2", _ARRAY_BUFFER)
        if part.colors is not None:
            attrs["COLOR_0"] = b.accessor(np.asarray(part.colors, dtype=np.uint8), _UBYTE, "VEC4", _ARRAY_BUFFER, normalized=True)
        indices = np.asarray(part.faces, dtype=np.uint32).reshape(-1)
        prim = {
            "attributes": attrs,
            "indices": b.accessor(indices, _UINT, "SCALAR", _ELEMENT_ARRAY_BUFFER),
            "material": b.material(part.name, part.base_color, texture, part.transparent, part.name in nearest_parts),
            "mode": 4,
        }
        b.tree["meshes"].append({"name": part.name, "primitives": [prim]})
        b.tree["nodes"].append({"name": part.name, "mesh": len(b.tree["meshes"]) - 1})
        (b.tree["scenes"][0]["nodes"] if parent is None else b.tree["nodes"][parent]["children"]).append(
            len(b.tree["nodes"]) - 1)
    b.tree["scenes"][0]["name"] = scene.name
    return b.to_bytes()


def export_glb(scene: Scene, path: str | Path) -> None:
    """Write ``scene`` to ``path`` as a binary glTF 2.0 file, atomically.

    Loading the file back with :func:`markerplace.scene.load_scene` gives the same vertices
    (float32, world frame) and the same texture arrays; parts sharing a texture share one image.
    """
    data = scene_to_glb_bytes(scene)
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(data)
    log.debug("wrote %s: %d parts, %.1f MB", path, len(scene.parts), len(data) / 1e6)
