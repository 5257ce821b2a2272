"""User-facing errors.

Anything the user can fix (bad path, bad option, bad mesh) raises :class:`UserError` with a
one-line message that says what is wrong and how to fix it. The CLI prints it on one line and
exits with code 2; it never shows a traceback for these.
"""

import errno
import os


class UserError(Exception):
    """An error caused by input the user can fix. ``str(err)`` is a one-line message."""

    exit_code = 2

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


def write_error(path, err: OSError) -> Exception:
    """A :class:`UserError` (one line) for a write that failed on a full disk, a quota, a
    read-only file system or a permission; ``err`` itself for any other error."""
    if err.errno not in (errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM, errno.EFBIG):
        return err
    hint = "free some space" if err.errno in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG) else "make it writable"
    return UserError(f"cannot write {path}: {os.strerror(err.errno)}; {hint} or choose another folder, then run "
                     "again (the stages already done are reused)")
