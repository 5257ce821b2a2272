"""Atomic file writes: a crash never leaves a half-written artifact behind.

Every write goes through :func:`atomic_path`: inside a run folder it only writes where
:mod:`markerplace.runtime.run_folder` allows (never through a link, never over a file
markerplace did not write) and records the file in the folder's manifest. A write that fails on
a full disk, a quota, a read-only file system or a permission is one line
(:func:`markerplace.errors.write_error`, exit 2) and leaves no temporary file.
"""

from __future__ import annotations

import errno
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from .errors import write_error
from .runtime import run_folder


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


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2, default=_json_default) + "\n")


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
