"""Input paths checked before they are read: a file the user names must be a plain file.

:func:`input_kind` says what a path is when it is not one: missing, a folder, a named pipe
(FIFO: reading it would wait for a writer), a device (``/dev/zero`` never ends), a socket, a
symbolic link loop or a link to nothing. :func:`check_input_file` turns that into one
:class:`~markerplace.errors.UserError` line naming the option, so none of these is reported as
"no such file" or read for minutes. Used by the mesh loader (:mod:`markerplace.scene.loader`)
and the JSON reader (:mod:`markerplace.jsonfile`).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from markerplace.errors import UserError

__all__ = ["input_kind", "check_input_file"]


def input_kind(path: str | Path) -> str | None:
    """None when ``path`` is a plain file (links followed), else what it is, as a phrase that
    follows "is": ``"missing"`` (no such file), ``"a folder"``, ``"a named pipe (FIFO)"``,
    ``"a device"``, ``"a socket"``, ``"a symbolic link loop"``, ``"a symbolic link to X, which
    does not exist"``, ``"unreadable (reason)"``."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            return f"a symbolic link to {os.readlink(path)}, which does not exist"
        return "missing"
    except OSError as err:
        if err.errno == errno.ELOOP:
            return "a symbolic link loop (it leads back to itself)"
        return f"unreadable ({err.strerror or err})"
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a named pipe (FIFO), not a file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device, not a file"
    if stat.S_ISSOCK(mode):
        return "a socket, not a file"
    return "not a plain file"


def check_input_file(path: str | Path, what: str, expected: str, missing_hint: str = "") -> None:
    """Raise :class:`UserError` (one line) unless ``path`` is a plain file.

    Args:
        path: the file.
        what: how the user gave it, e.g. ``"--existing hung.json"`` or the path itself.
        expected: what it should be, e.g. ``"a JSON file"``.
        missing_hint: appended to the "no such file" message (e.g. what else may be given).
    """
    kind = input_kind(path)
    if kind is None:
        return
    if kind == "missing":
        raise UserError(f"{what}: no such file{missing_hint}")
    if kind == "a folder":
        raise UserError(f"{what} is a folder, not {expected}")
    raise UserError(f"{what} is {kind}: give {expected}")
