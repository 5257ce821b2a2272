"""Stage artifacts that know where they came from.

Each stage writes its artifact next to a small ``<artifact>.meta.json`` holding the hash of the
config and inputs it came from. :func:`is_fresh` tells whether an existing artifact can be
reused; :func:`mark_done` records the hash after a successful (atomic) write. A stage
interrupted half-way leaves no meta file, so it is simply recomputed next time.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path
from typing import Any

import numpy as np

from .io_utils import write_json


def config_dict(obj: Any) -> Any:
    """A JSON-ready dict of a (nested) frozen dataclass config."""
    if dataclasses.is_dataclass(obj):
        return {f.name: config_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, (list, tuple)):
        return [config_dict(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer)):
        return obj.item()
    return obj


def hash_of(*items: Any) -> str:
    """Stable SHA-256 (hex, 16 chars) of configs, strings, numbers and numpy arrays."""
    h = hashlib.sha256()
    for item in items:
        _update(h, item)
    return h.hexdigest()[:16]


def _update(h: "hashlib._Hash", item: Any) -> None:
    if isinstance(item, np.ndarray):
        arr = np.ascontiguousarray(item)
        h.update(f"nd{arr.dtype.str}{arr.shape}".encode())
        h.update(arr.tobytes())
    elif dataclasses.is_dataclass(item):
        h.update(json.dumps(config_dict(item), sort_keys=True).encode())
    elif isinstance(item, (list, tuple)):
        h.update(b"[")
        for v in item:
            _update(h, v)
        h.update(b"]")
    elif isinstance(item, dict):
        h.update(json.dumps(item, sort_keys=True, default=str).encode())
    else:
        h.update(repr(item).encode())


def scene_hash(scene) -> str:
    """Hash of a scene's geometry, UVs, colours and textures (identical scenes -> identical hash)."""
    h = hashlib.sha256()
    seen_textures: dict[int, str] = {}
    for part in scene.parts:
        for arr in (part.vertices, part.faces, part.uv, part.colors):
            _update(h, np.zeros(0) if arr is None else arr)
        if part.texture is not None:
            key = id(part.texture)
            if key not in seen_textures:
                seen_textures[key] = hashlib.sha256(np.ascontiguousarray(part.texture).tobytes()).hexdigest()
            h.update(seen_textures[key].encode())
        h.update(repr(tuple(part.base_color)).encode())
    return h.hexdigest()[:16]


def _meta_path(artifact: Path) -> Path:
    return artifact.with_name(artifact.name + ".meta.json")


def is_fresh(artifact: str | Path, key: str) -> bool:
    """True when ``artifact`` exists and was made from inputs hashing to ``key``."""
    artifact = Path(artifact)
    meta = _meta_path(artifact)
    if not (artifact.exists() and meta.exists()):
        return False
    try:
        return json.loads(meta.read_text()).get("key") == key
    except (OSError, json.JSONDecodeError):
        return False


def mark_done(artifact: str | Path, key: str, **info: Any) -> None:
    """Record that ``artifact`` was written from inputs hashing to ``key``."""
    write_json(_meta_path(Path(artifact)), {"key": key, **info})
