"""Keep memory freed by one image's work in the process for the next image (glibc's malloc).

Why: SIFT (OpenCV) builds a scale-space pyramid of some 65 MB for a 640x480 image and frees it
when done. With glibc's defaults that memory goes back to the kernel after every image (large
blocks are ``mmap``-ed and unmapped; the free top of the heap is trimmed), so the next image
faults about 16,000 fresh, zeroed pages in again: on the 7-Scenes kitchen frames, 62 ms of
system time on top of 68 ms of user time per SIFT call (``benchmarks/sift_heap.py``), the
"system time" share that plan profiles showed. With ``M_MMAP_THRESHOLD`` at 32 MiB (blocks below
it come from the heap) and ``M_TRIM_THRESHOLD`` at 256 MiB (that much free memory is kept at the
top of the heap), the next image reuses the same pages: about one fault and no system time per
call. Nothing computed changes (the allocator's policy only); the price is that a process keeps
up to :data:`TRIM_THRESHOLD` bytes of freed memory, so its resident size stays near its peak.

Applied to every executor's worker state (:func:`markerplace.runtime.workers.single_threaded_libraries`,
run by :mod:`markerplace.runtime.executor` for pools, Dask and in-process runs alike: renders,
frames, photographs) and by the fusion of frames (:mod:`markerplace.scan.fuse`).
Measured: on textured built-in scenes the render workers fault as much as the photograph paths
(``room``: 13,600 faults and 48 ms of system time per SIFT call before, 1 ms after; ``plan house
-k 8``: 211 -> 188 CPU s, the same plan); on the 1.1-million-triangle scan-like house the
renderer's own large buffers already kept glibc's adaptive threshold high (1-3 faults per pose),
so there it changes nothing but the peak memory (1944 -> 2223 MiB).
Hand-written with ``ctypes``: ``mallopt`` is a C library call no Python package wraps. On a C
library other than glibc (musl, macOS) nothing is changed.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging

log = logging.getLogger(__name__)

__all__ = ["MMAP_THRESHOLD", "TRIM_THRESHOLD", "keep_freed_memory"]

MMAP_THRESHOLD = 32 * 2**20
"""Bytes: blocks smaller than this come from the heap (glibc's largest allowed value on 64-bit)."""

TRIM_THRESHOLD = 256 * 2**20
"""Bytes of free memory at the top of the heap kept in the process rather than given back."""

_M_TRIM_THRESHOLD = -1  # glibc's malloc.h
_M_MMAP_THRESHOLD = -3
_applied: bool | None = None


def keep_freed_memory() -> bool:
    """Set glibc's thresholds (module docstring) once per process; True when they are in effect
    (False on another C library or when glibc refuses them)."""
    global _applied
    if _applied is not None:
        return _applied
    _applied = False
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018 - glibc only (AttributeError elsewhere)
        ok = libc.mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
        ok = libc.mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1 and ok
    except (OSError, AttributeError):
        return False
    _applied = ok
    if not ok:
        log.debug("mallopt refused the heap thresholds; freed memory goes back to the kernel as before")
    return ok
