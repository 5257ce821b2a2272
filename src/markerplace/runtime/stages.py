"""Stages as functions over artifacts (hloc's ``main(conf, ...) -> Path``): one helper runs a
stage or reuses its artifact.

:func:`cached` looks for ``path`` made from inputs hashing to ``key`` (checksum verified, see
:mod:`markerplace.runtime.cache`); when it is there and loads, the stage is skipped; otherwise
``compute()`` runs, ``save(result, path)`` writes the artifact (atomically, or as a folder that
is only marked done once complete) and the key is recorded. An interrupted stage leaves no
record and runs again (stages that stream to disk resume from their parts).

Keys come from content: a stage computed from upstream artifacts puts their
:func:`~markerplace.runtime.cache.content_digest` in its key. A stage whose upstream artifacts
are only made inside ``compute`` (so their digests are unknown when the key is built) names
them in ``upstream``: their digests are recorded with the artifact, and it is reused only while
every one of them that exists still has the recorded digest.
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Callable, Sequence, TypeVar

from markerplace.runtime import cache
from markerplace.runtime.interrupt import raise_if_stopping

log = logging.getLogger(__name__)

T = TypeVar("T")

__all__ = ["cached"]


def cached(name: str, path: str | Path, key: str, compute: Callable[[], T], save: Callable[[T, Path], None] | None,
           load: Callable[[Path], T], timings: dict | None = None, upstream: Sequence[str | Path] = (), **meta) -> T:
    """The artifact of stage ``name`` at ``path``: reused when fresh, else computed and saved.

    Args:
        name: stage name for the log and ``timings``.
        path: artifact file or folder.
        key: hash of everything the artifact depends on (:func:`~markerplace.runtime.cache.hash_of`).
        compute: runs the stage; returns the result.
        save: writes the result to ``path`` (None: ``compute`` wrote it itself).
        load: reads the artifact back.
        timings: if given, ``timings[name]`` gets the stage's seconds.
        upstream: artifacts ``compute`` makes or reads whose digests are not in ``key`` (see
            the module docstring).
        meta: extra fields recorded in the artifact's ``.meta.json``.
    """
    path = Path(path)
    raise_if_stopping()
    t0 = time.perf_counter()
    result = cache.load_fresh(path, key, load)
    if result is not None and upstream:
        changed = _changed_upstream(path, upstream)
        if changed:
            log.info("%s: %s changed since %s was made; recomputing it", name, changed, path)
            result = None
    if result is not None:
        log.info("%s: reusing %s", name, path)
    else:
        result = compute()
        if save is not None:
            save(result, path)
        if upstream:
            meta["upstream"] = {_name(path, p): cache.content_digest(p) for p in map(Path, upstream) if p.exists()}
        cache.mark_done(path, key, **meta)
    if timings is not None:
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - t0
    return result


def _name(artifact: Path, upstream: Path) -> str:
    return os.path.relpath(upstream, artifact.parent)


def _changed_upstream(artifact: Path, upstream: Sequence[str | Path]) -> str | None:
    """The first of ``upstream`` that exists with a digest other than the one recorded with
    ``artifact`` (or none recorded), else None."""
    recorded = cache.recorded_upstream(artifact)
    for p in map(Path, upstream):
        if p.exists() and recorded.get(_name(artifact, p)) != cache.content_digest(p):
            return str(p)
    return None
