"""See-through materials: when a loaded material counts as glass, and how opaque glass is drawn.

One rule set shared by the loader, the glTF exporter and the renderer (``MeshPart.transparent``):

* **glTF** material: ``alphaMode`` ``"BLEND"`` with ``baseColorFactor`` alpha below
  :data:`OPAQUE_ALPHA` (0.9), or ``KHR_materials_transmission`` with ``transmissionFactor`` > 0.
  (``OPAQUE`` ignores alpha and ``MASK`` cuts holes, so neither counts.)
* **OBJ** (MTL) material: dissolve ``d`` below 0.9, or, without ``d``, ``Tr`` above 0.1
  (``Tr`` = 1 - ``d``). The opacity then becomes the part's base colour alpha.
* A transparent part is drawn and exported with opacity :func:`drawn_alpha`: its base colour
  alpha when that is below 0.9, else :data:`GLASS_ALPHA` (e.g. glass marked by transmission
  alone, alpha 1).

trimesh keeps ``alphaMode`` and ``baseColorFactor`` of glTF materials and the raw MTL keys of OBJ
materials (``SimpleMaterial.kwargs``), but drops glTF material extensions, so
``KHR_materials_transmission`` is read from the file's JSON (:func:`read_gltf_json`) and matched to
trimesh's materials by name and base colour.
"""

from __future__ import annotations

import json
import logging
import struct
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

__all__ = [
    "GLASS_ALPHA", "OPAQUE_ALPHA", "drawn_alpha", "gltf_material_is_transparent", "material_transparency",
    "mtl_opacity", "read_gltf_json",
]

OPAQUE_ALPHA = 0.9
"""Materials at least this opaque (alpha, or MTL ``d``) are opaque."""
GLASS_ALPHA = 76 / 255
"""Opacity of glass whose material gives none below :data:`OPAQUE_ALPHA` (about 0.3; exact in 8 bits)."""
MIN_TR = 0.1
"""MTL ``Tr`` (transparency, 1 - ``d``) above which a material without ``d`` is transparent."""


def drawn_alpha(base_alpha: float) -> float:
    """Opacity in (0, 1) a transparent part is drawn and exported with, from its base colour alpha."""
    a = float(base_alpha)
    return a if 0.0 < a < OPAQUE_ALPHA else GLASS_ALPHA


def gltf_material_is_transparent(material: dict) -> bool:
    """Whether a glTF material (a dict of the file's ``materials`` list) is see-through."""
    pbr = material.get("pbrMetallicRoughness") or {}
    factor = pbr.get("baseColorFactor") or [1.0, 1.0, 1.0, 1.0]
    alpha = float(factor[3]) if len(factor) > 3 else 1.0
    if material.get("alphaMode") == "BLEND" and alpha < OPAQUE_ALPHA:
        return True
    transmission = (material.get("extensions") or {}).get("KHR_materials_transmission")
    return transmission is not None and float(transmission.get("transmissionFactor", 0.0)) > 0.0


def mtl_opacity(keys: dict) -> float | None:
    """Opacity from the raw MTL keys of one material (``d``, else 1 - ``Tr``), or None if absent.

    ``keys`` maps lower-case MTL keywords to their tokens (trimesh's ``SimpleMaterial.kwargs``);
    the last token is the value (``d -halo 0.5`` has one option before it).
    """
    for key, invert in (("d", False), ("tr", True)):
        tokens = keys.get(key)
        if tokens is None:
            continue
        try:
            value = float(np.atleast_1d(tokens)[-1])
        except (TypeError, ValueError):
            log.warning("MTL %s value %r is not a number; ignored", key, tokens)
            continue
        if not np.isfinite(value):
            continue
        value = float(np.clip(value, 0.0, 1.0))
        if invert:
            return 1.0 - value if value > MIN_TR else 1.0
        return value
    return None


def read_gltf_json(path: str | Path) -> dict:
    """The JSON tree of a ``.gltf`` or ``.glb`` file ({} when it cannot be read)."""
    path = Path(path)
    try:
        data = path.read_bytes()
        if data[:4] == b"glTF":
            length, kind = struct.unpack_from("<I4s", data, 12)
            if kind != b"JSON":
                return {}
            return json.loads(data[20 : 20 + length])
        return json.loads(data.decode("utf-8"))
    except (OSError, ValueError, struct.error) as err:
        log.debug("could not read the glTF JSON of %s: %s", path, err)
        return {}


def _same_factor(material: dict, rgba_u8) -> bool:
    pbr = material.get("pbrMetallicRoughness") or {}
    factor = np.asarray(pbr.get("baseColorFactor") or [1.0, 1.0, 1.0, 1.0], dtype=float)
    return rgba_u8 is None or bool(np.all(np.abs(factor * 255.0 - np.asarray(rgba_u8, dtype=float)[:4]) <= 1.0))


def material_transparency(material, gltf: dict | None) -> tuple[bool, float | None]:
    """(transparent, opacity or None) of a trimesh material of a loaded mesh.

    Args:
        material: ``mesh.visual.material`` (a trimesh ``PBRMaterial`` for glTF, a
            ``SimpleMaterial`` for OBJ), or None.
        gltf: the file's glTF JSON (:func:`read_gltf_json`) for glTF files, else None.

    Returns:
        Whether it is see-through, and for OBJ the opacity from the MTL (to become the base
        colour alpha; None when the material gives none, as glTF's alpha is already in its
        base colour).
    """
    if material is None:
        return False, None
    if gltf is not None:
        factor = getattr(material, "baseColorFactor", None)
        alpha = 1.0 if factor is None else float(np.asarray(factor, dtype=float).reshape(-1)[3]) / 255.0
        if getattr(material, "alphaMode", None) == "BLEND" and alpha < OPAQUE_ALPHA:
            return True, None
        name = getattr(material, "name", None)
        for m in gltf.get("materials", []):
            if m.get("name") == name and _same_factor(m, factor) and gltf_material_is_transparent(m):
                return True, None
        return False, None
    keys = getattr(material, "kwargs", None) or {}
    opacity = mtl_opacity(keys)
    if opacity is not None and opacity < OPAQUE_ALPHA:
        return True, opacity
    return False, None
