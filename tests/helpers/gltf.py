"""Hand-written glTF files for the loader's checks."""

from __future__ import annotations

import base64
import json

import numpy as np


def gltf_with_texture_uri(path, uri):
    """A 4 x 4 x 2.7 m inward-facing box room whose material points at the texture file ``uri``."""
    import trimesh

    box = trimesh.creation.box(extents=(4.0, 2.7, 4.0))
    box.invert()
    V, F = box.vertices.astype(np.float32), box.faces.astype(np.uint32)
    uv = (V[:, [0, 2]] / 4 + 0.5).astype(np.float32)
    blob = V.tobytes() + uv.tobytes() + F.tobytes()
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "textures": [{"source": 0}], "images": [{"uri": uri}],
        "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64," + base64.b64encode(blob).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": V.nbytes},
                        {"buffer": 0, "byteOffset": V.nbytes, "byteLength": uv.nbytes},
                        {"buffer": 0, "byteOffset": V.nbytes + uv.nbytes, "byteLength": F.nbytes}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(V), "type": "VEC3",
                       "min": V.min(0).tolist(), "max": V.max(0).tolist()},
                      {"bufferView": 1, "componentType": 5126, "count": len(V), "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5125, "count": int(F.size), "type": "SCALAR"}],
    }
    path.write_text(json.dumps(doc))
    return path
