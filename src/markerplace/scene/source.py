"""What a scene argument names: a built-in scene or a mesh file, and the file's axes.

Used where a plan folder is read back (``export``, ``check``) and where outputs in the file's
own axes are written (tag maps, glTF export).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplace.scene.builtin.catalogue import builtin_names
from markerplace.scene.loader import up_rotation

__all__ = ["is_builtin", "file_up_axis", "world_from_file_rotation"]

GLTF_EXTENSIONS = (".glb", ".gltf")


def is_builtin(spec: str) -> bool:
    """True when ``spec`` names a built-in scene (the rule of :func:`markerplace.scene.load_scene`)."""
    key = str(spec).strip()
    return key.lower() in builtin_names() and not Path(key).is_file()


def file_up_axis(spec: str, up: str | None) -> str | None:
    """The up axis the loader used for ``spec`` (``--up``, else ``y`` for glTF, ``z`` for OBJ/PLY);
    None for a built-in scene (its world is z up)."""
    if is_builtin(spec):
        return None
    if up is not None:
        return str(up).strip().lower().lstrip("+")
    return "y" if Path(str(spec)).suffix.lower() in GLTF_EXTENSIONS else "z"


def world_from_file_rotation(spec: str, up: str | None) -> np.ndarray | None:
    """(3, 3) the loader's ``world_from_file`` rotation for ``spec`` (None for built-ins)."""
    axis = file_up_axis(spec, up)
    return None if axis is None else np.asarray(up_rotation(axis), dtype=float)
