"""Scenes: load a mesh file or build a procedural interior, always z up and in metres.

Public entry point: :func:`load_scene`. Built-in scenes are listed by
:func:`markerplace.scene.builtin.catalogue.list_scenes`; :func:`markerplace.scene.export.export_glb`
writes any scene as a standard binary glTF.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

from markerplace.errors import UserError
from markerplace.scene.builtin.catalogue import builtin_names, get_builtin
from markerplace.scene.loader import SUPPORTED_EXTENSIONS, load_mesh_file
from markerplace.scene.types import Scene

log = logging.getLogger(__name__)

__all__ = ["load_scene"]


def load_scene(spec: str, up: str | None = None, unit_scale: float | None = None, seed: int = 0) -> Scene:
    """Return the scene named by ``spec``: a built-in name (e.g. ``"office"``) or a mesh path.

    Args:
        spec: built-in name (see ``markerplace scene list``) or a ``.glb/.gltf/.obj/.ply`` path.
        up: up axis of a mesh file (see :mod:`markerplace.scene.loader`); ignored for built-ins.
        unit_scale: factor from file units to metres; ignored for built-ins.
        seed: seed of the procedural generator (built-ins only). Built-ins are cached per
            (name, seed) in this process; their arrays are read-only and shared.

    Returns:
        A :class:`Scene` in the world frame (z up, metres).

    Raises:
        UserError: unknown name, missing or unreadable file, implausible units.
    """
    key = str(spec).strip()
    if key.lower() in builtin_names() and not Path(key).is_file():
        if (up not in (None, "z")) or (unit_scale not in (None, 1.0)):
            log.warning("--up and --unit-scale apply to mesh files only; ignored for built-in scene %r", key)
        return get_builtin(key.lower(), seed)
    if Path(key).suffix or os.path.lexists(key):  # a link loop or a dangling link too: the loader says what it is
        return load_mesh_file(key, up=up, unit_scale=unit_scale)
    raise UserError(
        f"unknown scene {key!r}: give a built-in name ({', '.join(builtin_names())}) "
        f"or a mesh file ({', '.join(SUPPORTED_EXTENSIONS)})"
    )
