"""Output paths checked before any work starts: ``--out`` folders and output files.

:func:`check_output_dir` (``--out`` of ``plan``/``evaluate``/``study``) and :func:`check_output_file`
(``render --out PREFIX``, ``scene export OUT``, ``fuse --out``, ``export --gltf``) prove the place is writable with a real test
write in it or in the nearest existing folder above it (``os.access`` says yes to root even on
read-only folders); they create nothing, so a refused run leaves no empty folder behind. Both
raise :class:`~markerplace.errors.UserError` (one line, exit code 2).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Sequence

from markerplace.errors import UserError

__all__ = ["check_output_dir", "check_output_file"]


def _first_file_above(path: Path) -> Path | None:
    """The nearest existing ancestor of ``path`` (itself included) when it is not a folder."""
    for p in (path, *path.parents):
        if p.exists() or p.is_symlink():
            return None if p.is_dir() else p
    return None


def _nearest_existing(path: Path) -> Path:
    """``path`` or its nearest existing ancestor."""
    for p in (path, *path.parents):
        if p.exists():
            return p
    return Path(".")


def _probe_write(path: Path, option: str) -> None:
    """Create and delete a file in ``path``'s nearest existing folder (``path`` itself when it
    exists): what is missing below it can then be created by the run itself."""
    folder = _nearest_existing(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=".markerplace-write-test-", dir=folder)
    except OSError as err:
        where = "" if folder == path else f" ({folder} is where it would be created)"
        raise UserError(f"{option} {path}: cannot write there{where}: {err.strerror or err.__class__.__name__}; "
                        "choose a writable folder") from None
    os.close(fd)
    try:
        os.unlink(tmp)
    except OSError:
        pass


def check_output_dir(path: str | os.PathLike, option: str = "--out") -> Path:
    """Make sure ``path`` is, or can be created as, a writable folder (nothing is created).

    Raises:
        UserError: ``path`` or one of its parents is a file, or a test write into it (or into
            the nearest existing folder above it) fails: read-only folder or file system, no
            permission, disk full.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(f"{option} {path} is an existing file, not a folder: give a folder path")
    blocker = _first_file_above(path.parent)
    if blocker is not None:
        raise UserError(f"{option} {path}: {blocker} is a file, so no folder can be made under it; give another path")
    _probe_write(path, option)
    return path


def check_output_file(path: str | os.PathLike, option: str, suffixes: Sequence[str] = ("",)) -> Path:
    """Make sure files ``str(path) + suffix`` can be written: their folder is, or can be created
    as, a writable folder, and none of them is an existing folder (nothing is created).

    Raises:
        UserError: a parent is a file, the folder cannot be written, or a target is a folder.
    """
    path = Path(path)
    if str(path).endswith(("/", os.sep)) or path.name in ("", ".", ".."):
        raise UserError(f"{option} {path}: give a file name (or prefix), not a folder")
    for suffix in suffixes:
        target = Path(str(path) + suffix)
        if target.is_dir():
            raise UserError(f"{option}: {target} is an existing folder; give a file name (or prefix)")
    folder = path.parent
    blocker = _first_file_above(folder)
    if blocker is not None:
        raise UserError(f"{option} {path}: {blocker} is a file, so it cannot hold {path.name}; give another path")
    _probe_write(folder, option)
    return path
