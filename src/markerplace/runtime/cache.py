"""Stage artifacts that know where they came from.

Each stage writes its artifact next to a small ``<artifact>.meta.json`` holding the hash of the
config and inputs it came from, and the size and SHA-256 of the artifact's bytes (of every file
when the artifact is a folder). :func:`is_fresh` tells whether an existing artifact can be
reused: same key, and the bytes on disk still match the stored size and checksum;
:func:`mark_done` records both after a successful (atomic) write. :func:`load_fresh` also
recovers from an artifact that verifies but cannot be read.

Keys are built from content: a stage's key holds the :func:`content_digest` of the artifacts it
was computed from (the checksum their meta files record), so an upstream artifact recomputed or
repaired with other bytes invalidates everything downstream of it.

:func:`adopt` brings a fresh artifact of another run folder (a finished ``plan`` that an
``evaluate --plan`` starts from) into this one as hard links, so the stage that would make it
finds it fresh (when its key matches) instead of computing it again; the other folder is only
read.

A stage interrupted half-way leaves no meta file, so it is simply recomputed next time. A
damaged artifact (truncated by a full disk, a crash while copying the folder, edited by hand)
or one that fails to load is recomputed with a warning naming the file; a meta file without a
checksum (an older version of markerplace) counts as stale.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import logging
import os
from pathlib import Path
from typing import Any, Callable, TypeVar

import numpy as np

from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import link_file, write_json

log = logging.getLogger(__name__)

T = TypeVar("T")

_CHUNK = 1 << 20

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


def file_checksum(path: str | Path) -> dict:
    """``{"size": bytes, "sha256": hex}`` of one file's contents."""
    h = hashlib.sha256()
    size = 0
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            h.update(chunk)
            size += len(chunk)
    return {"size": size, "sha256": h.hexdigest()}


def artifact_checksum(artifact: str | Path) -> dict:
    """Checksum of an artifact: :func:`file_checksum` of a file, or ``{"files": {relative
    path: file checksum}}`` over every file below a folder (sorted, hidden files included)."""
    artifact = Path(artifact)
    if artifact.is_dir():
        files = sorted(p for p in artifact.rglob("*") if p.is_file())
        return {"files": {p.relative_to(artifact).as_posix(): file_checksum(p) for p in files}}
    return file_checksum(artifact)


def _verify(artifact: Path, meta: dict) -> str | None:
    """None when ``artifact`` matches the checksum in ``meta``, else why it does not."""
    stored = {k: meta[k] for k in ("size", "sha256", "files") if k in meta}
    if not stored:
        return "its meta file has no checksum (written by an older version)"
    try:
        actual = artifact_checksum(artifact)
    except OSError as err:
        return f"it cannot be read ({err.__class__.__name__})"
    if "files" in stored:
        want, got = stored["files"], actual.get("files")
        if got is None:
            return "it is no longer a folder"
        missing = sorted(set(want) - set(got))
        if missing:
            return f"{missing[0]} is missing"
        for name, c in want.items():
            if got[name] != c:
                return f"{name} is {got[name]['size']} bytes with checksum {got[name]['sha256'][:12]}, " \
                       f"expected {c['size']} bytes with checksum {c['sha256'][:12]}"
        return None
    if "size" not in actual:
        return "it is a folder, expected a file"
    if actual["size"] != stored.get("size"):
        return f"it is {actual['size']} bytes, expected {stored.get('size')} (truncated or overwritten)"
    if actual["sha256"] != stored.get("sha256"):
        return "its checksum does not match (damaged or overwritten)"
    return None


def is_fresh(artifact: str | Path, key: str) -> bool:
    """True when ``artifact`` exists, was made from inputs hashing to ``key`` and its bytes still
    match the checksum recorded by :func:`mark_done`.

    A key mismatch (other settings) returns False silently; an artifact whose key matches but
    whose bytes do not (damaged, partial) returns False with a warning naming the file.
    """
    artifact = Path(artifact)
    meta_path = _meta_path(artifact)
    if not (artifact.exists() and meta_path.exists()):
        return False
    try:
        meta = json.loads(meta_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError):
        log.warning("cache: %s is unreadable; recomputing %s", meta_path, artifact)
        return False
    if not isinstance(meta, dict) or meta.get("key") != key:
        return False
    problem = _verify(artifact, meta)
    if problem is not None:
        level = logging.INFO if "older version" in problem else logging.WARNING
        log.log(level, "cache: %s is not usable: %s; recomputing it", artifact, problem)
        return False
    return True


def load_fresh(artifact: str | Path, key: str, loader: Callable[[Path], T]) -> T | None:
    """``loader(artifact)`` when :func:`is_fresh`, else None.

    An artifact that verifies but fails to load (any exception from ``loader``) also gives
    None, with a warning naming the file, so the caller recomputes it.
    """
    artifact = Path(artifact)
    if not is_fresh(artifact, key):
        return None
    try:
        return loader(artifact)
    except Exception as err:  # noqa: BLE001 - any unreadable artifact is recomputed
        reason = " ".join(str(err).split())[:160] or err.__class__.__name__
        log.warning("cache: could not read %s (%s: %s); recomputing it", artifact, err.__class__.__name__, reason)
        return None


def content_digest(artifact: str | Path) -> str:
    """Hash (hex, 16 chars) of an artifact's bytes, for the keys of the stages computed from it:
    from the checksum its ``.meta.json`` records (which :func:`is_fresh` has verified or
    :func:`mark_done` has just written), else computed from the bytes."""
    artifact = Path(artifact)
    try:
        meta = json.loads(_meta_path(artifact).read_text())
        stored = {k: meta[k] for k in ("size", "sha256", "files") if k in meta}
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, TypeError, RecursionError):
        stored = {}
    return hash_of(stored or artifact_checksum(artifact))


def recorded_upstream(artifact: str | Path) -> dict:
    """The ``upstream`` digests ``artifact``'s meta file records ({} when none)."""
    try:
        up = json.loads(_meta_path(Path(artifact)).read_text()).get("upstream", {})
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError, RecursionError):
        return {}
    return up if isinstance(up, dict) else {}


def mark_done(artifact: str | Path, key: str, **info: Any) -> None:
    """Record that ``artifact`` (a file or a folder) was written from inputs hashing to ``key``,
    with its size and SHA-256 (see :func:`artifact_checksum`)."""
    artifact = Path(artifact)
    write_json(_meta_path(artifact), {"key": key, **artifact_checksum(artifact), **info})


def recorded_key(artifact: str | Path) -> str | None:
    """The key ``artifact``'s meta file records (None: none, or unreadable)."""
    try:
        key = json.loads(_meta_path(Path(artifact)).read_text()).get("key")
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError, RecursionError):
        return None
    return key if isinstance(key, str) else None


def adopt(source: str | Path, artifact: str | Path, moved: dict | None = None) -> bool:
    """Make ``artifact`` the fresh artifact ``source`` is (another run folder's, verified by its
    checksum): every file hard-linked (copied across file systems,
    :func:`~markerplace.runtime.atomic_io.link_file`), its meta file last, so an interrupted
    adoption leaves a stale artifact, never a fresh-looking partial one. ``artifact`` is left
    alone when ``source`` is missing or not fresh, and when it is itself fresh (for any key:
    this folder's own work wins). Returns whether ``artifact`` is now the same artifact as
    ``source``. ``source`` is never written.

    ``moved``: source-side path -> artifact-side path of upstream artifacts adopted alongside
    (see :mod:`markerplace.runtime.stages`): the meta file then names them where they are now,
    so the adopted artifact stays fresh while they are unchanged."""
    source, artifact = Path(source), Path(artifact)
    key = recorded_key(source)
    if key is None or not is_fresh(source, key):
        return False
    own = recorded_key(artifact)
    if own is not None and is_fresh(artifact, own):  # this folder's own work (or an earlier adoption) stays
        return own == key and content_digest(artifact) == content_digest(source)
    run_folder.remove(_meta_path(artifact))
    if source.is_dir():
        if artifact.is_dir():
            run_folder.remove_tree(artifact)
        for p in sorted(q for q in source.rglob("*") if q.is_file()):
            link_file(p, artifact / p.relative_to(source))
    else:
        link_file(source, artifact)
    up = recorded_upstream(source)
    if not up or not moved:
        link_file(_meta_path(source), _meta_path(artifact))
        return True
    where = {os.path.normpath(str(src)): Path(dst) for src, dst in moved.items()}
    renamed = {}
    for name, digest in up.items():
        now = where.get(os.path.normpath(str(source.parent / name)))
        renamed[os.path.relpath(now, artifact.parent) if now is not None else name] = digest
    write_json(_meta_path(artifact), {**json.loads(_meta_path(source).read_text()), "upstream": renamed})
    return True
