"""Atomic file writes: a crash never leaves a half-written artifact behind; clean numbers in them.

Every write goes through :func:`atomic_path`: inside a run folder it only writes where
:mod:`markerplace.runtime.run_folder` allows (never through a link, never over a file
markerplace did not write) and records the file in the folder's manifest. A write that fails on
a full disk, a quota, a read-only file system or a permission is one line
(:func:`markerplace.errors.write_error`, exit 2) and leaves no temporary file.

Every JSON file the tool writes goes through :func:`write_json`, which writes floats rounded to
:data:`JSON_DIGITS` significant digits (or 9 decimals, when finer) and never ``-0.0``
(:func:`clean_numbers`): ``11.1``, not ``11.100000000000001``. Text tables and messages format
numbers with :func:`fixed` (no ``-0.000``).
"""

from __future__ import annotations

import errno
import json
import math
import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from markerplace.errors import write_error
from markerplace.runtime import run_folder


@contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` only if the block succeeds.

    Raises:
        UserError: ``path`` is in a run folder where markerplace may not write it (see
            :func:`markerplace.runtime.run_folder.prepare_write`), or the write failed for lack
            of space or permission.
    """
    path = run_folder.prepare_write(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    except OSError as err:
        raise write_error(path, err) from None
    os.close(fd)
    tmp_path = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    try:
        os.chmod(tmp_path, 0o666 & ~umask)  # mkstemp makes 0600; give outputs the usual permissions
        yield tmp_path
        os.replace(tmp_path, path)
    except OSError as err:
        raise write_error(path, err) from None
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


JSON_DIGITS = 12
"""Significant digits of every float in the JSON files the tool writes (a relative error of at
most 5e-13), but never coarser than :data:`JSON_DECIMALS` decimals (survey coordinates keep a
nanometre)."""
JSON_DECIMALS = 9


def clean_float(value: float, digits: int | None = JSON_DIGITS) -> float:
    """``value`` rounded to ``digits`` significant digits or :data:`JSON_DECIMALS` decimals,
    whichever is finer (None: unchanged), ``-0.0`` as ``0.0``; NaN and infinities unchanged.
    Idempotent: cleaning a cleaned value changes nothing."""
    v = float(value)
    if not math.isfinite(v):
        return v
    if digits is not None:
        v = round(v, JSON_DECIMALS) if abs(v) >= 10.0 ** (digits - JSON_DECIMALS) else float(f"{v:.{digits}g}")
    return v + 0.0  # -0.0 + 0.0 == +0.0


def clean_numbers(obj: Any, digits: int | None = JSON_DIGITS) -> Any:
    """A copy of a JSON-ready structure (dicts, lists, tuples, numpy arrays and scalars) with
    every float cleaned by :func:`clean_float`, NaN and infinities as None (JSON's ``null``:
    JSON has no NaN, and :func:`markerplace.jsonfile.read_json` refuses one); other values as
    they are."""
    if obj is None or isinstance(obj, (bool, str, int)):
        return obj
    if isinstance(obj, (float, np.floating)):
        value = clean_float(obj, digits)
        return value if math.isfinite(value) else None  # JSON has no NaN: null (read back as "not a number")
    if isinstance(obj, (np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return clean_numbers(obj.tolist(), digits)
    if isinstance(obj, dict):
        return {k: clean_numbers(v, digits) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [clean_numbers(v, digits) for v in obj]
    return obj


def clean_array(array: np.ndarray, digits: int | None = JSON_DIGITS) -> np.ndarray:
    """A float64 copy of ``array`` with every element cleaned by :func:`clean_float`: exactly what
    :func:`write_json` would write, so a value kept in memory equals the one read back."""
    a = np.asarray(array, dtype=float)
    return np.array([clean_float(v, digits) for v in a.ravel()], dtype=float).reshape(a.shape)


def fixed(value: float | None, digits: int, none: str = "") -> str:
    """``value`` with ``digits`` decimals for text (tables, messages): never ``-0.000`` (a value
    that rounds to zero prints as ``0.000``); ``none`` for None."""
    if value is None:
        return none
    text = f"{float(value):.{digits}f}"
    return text[1:] if text.startswith("-") and float(text) == 0.0 else text


def write_json(path: str | os.PathLike, obj: Any, digits: int | None = JSON_DIGITS) -> None:
    """Write ``obj`` as indented JSON, atomically, with clean numbers (:func:`clean_numbers`:
    ``digits`` significant digits, no ``-0.0``; ``digits=None`` keeps every float exact, for
    values read back where the last bit matters)."""
    text = json.dumps(clean_numbers(obj, digits), indent=2, default=_json_default)
    with atomic_path(path) as tmp:
        tmp.write_text(text + "\n")


def write_npz(path: str | os.PathLike, **arrays: np.ndarray) -> None:
    """Write arrays to a compressed ``.npz`` atomically (no pickled objects)."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, **arrays)


def write_npy(path: str | os.PathLike, array: np.ndarray) -> None:
    """Write one array to ``.npy`` atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.save(fh, array, allow_pickle=False)


def link_file(source: str | os.PathLike, path: str | os.PathLike) -> None:
    """Make ``path`` a hard link to ``source`` (a copy where the file system has no links or
    ``source`` is on another one), put in place atomically; ``source`` is only read: every
    later write of ``path`` replaces the link, never the file behind it."""
    with atomic_path(path) as tmp:
        tmp.unlink()
        try:
            os.link(source, tmp)
        except OSError:
            shutil.copyfile(source, tmp)


def write_image(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W[, C]) uint8 image as PNG, atomically."""
    from PIL import Image

    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(image)).save(tmp, format="PNG")


def allocate(path: str | os.PathLike) -> None:
    """Reserve disk blocks for the whole of the file ``path`` (a new memory map is sparse: a
    full disk would otherwise kill the process with SIGBUS while the map is filled); a full
    disk raises ``OSError(ENOSPC)`` here instead. No-op where the file system cannot."""
    size = os.path.getsize(path)
    if size and hasattr(os, "posix_fallocate"):
        with open(path, "r+b") as fh:
            try:
                os.posix_fallocate(fh.fileno(), 0, size)
            except OSError as err:
                if err.errno not in (errno.EOPNOTSUPP, errno.EINVAL, errno.ENOSYS):
                    raise


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")
