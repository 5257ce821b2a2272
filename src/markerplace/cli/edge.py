"""The command line's edge: what the machine, not the input, can make fail, caught once for every
command and turned into one line ``markerplace: error: ...`` with exit code 2.

* Standard output: :class:`StdoutGuard` wraps ``sys.stdout`` for the command's life. A character
  its encoding cannot hold (``--out été`` printed to an ASCII terminal, ``LC_ALL=C``) is written
  as a backslash escape instead of raising ``UnicodeEncodeError`` after all the work; a write or
  flush that fails (``> /dev/full``, or standard output closed: ``>&-``) becomes
  :class:`StdoutError`, and the stream is pointed at ``/dev/null`` so that Python's own flush at
  exit stays quiet. A pipe closed by its reader
  (``| head -1``) ends the command quietly with exit code 141, as SIGPIPE ends shell tools.
* The working directory deleted under the shell: refused before anything is read
  (:func:`check_working_directory`); relative paths cannot be resolved there and some native
  libraries abort with a line of their own.
* Resource limits (``ulimit -n``, ``ulimit -v``, a machine out of memory): :func:`resource_error`
  names the limit and what to change; a path the file system finds too long (``--out`` with a
  300-character name) is one line too.
"""

from __future__ import annotations

import errno
import os
import resource
import sys

from markerplace.errors import UserError

__all__ = ["StdoutError", "StdoutGuard", "check_working_directory", "resource_error"]


class StdoutError(UserError):
    """Standard output could not be written (a full device, a closed pipe). A pipe whose reader
    stopped reading (``markerplace scene list | head -1``) is no error to report: ``quiet``, and
    exit code 141 (128 + SIGPIPE) as a shell tool killed by SIGPIPE."""

    def __init__(self, message: str, quiet: bool = False):
        super().__init__(message)
        self.quiet = quiet
        self.exit_code = 141 if quiet else 2


def _failed(err: OSError) -> StdoutError:
    return StdoutError(f"cannot write to standard output: {err.strerror or err}; redirect it elsewhere and run "
                       "again", quiet=err.errno == errno.EPIPE)


class _GuardedStream:
    """``stream`` with writes that escape unencodable characters and raise :class:`StdoutError`
    on an ``OSError``; every other attribute is the stream's."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        try:
            try:
                return self._stream.write(text)
            except UnicodeEncodeError:
                encoding = getattr(self._stream, "encoding", None) or "ascii"
                return self._stream.write(text.encode(encoding, "backslashreplace").decode(encoding))
        except OSError as err:
            raise _failed(err) from None

    def flush(self) -> None:
        try:
            self._stream.flush()
        except OSError as err:
            raise _failed(err) from None

    def __getattr__(self, name):
        return getattr(self._stream, name)


class _ClosedStream:
    """Standard output closed by the shell (``markerplace --version >&-``): Python then has no
    ``sys.stdout`` at all; here every write fails as on a closed descriptor (one line, exit 2)."""

    encoding = "utf-8"

    def write(self, text: str) -> int:
        raise OSError(errno.EBADF, "it is closed")

    def flush(self) -> None:
        pass

    def fileno(self) -> int:
        raise OSError(errno.EBADF, "it is closed")

    def isatty(self) -> bool:
        return False


class StdoutGuard:
    """Context manager: ``sys.stdout`` guarded (see the module docstring) inside, restored after.
    :meth:`silence` points the real stream at ``/dev/null`` after a failure."""

    def __enter__(self) -> "StdoutGuard":
        self._saved = sys.stdout
        sys.stdout = _GuardedStream(sys.stdout if sys.stdout is not None else _ClosedStream())
        return self

    def silence(self) -> None:
        """Send what is still buffered for standard output to ``/dev/null`` (it cannot be written)."""
        try:
            fd = self._saved.fileno()
        except (AttributeError, OSError, ValueError):
            return  # not a file (a test's capture): nothing is flushed at exit
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)

    def __exit__(self, *exc) -> None:
        sys.stdout = self._saved


def check_working_directory() -> None:
    """Refuse to run in a working directory that was deleted (one line)."""
    try:
        os.getcwd()
    except (FileNotFoundError, PermissionError) as err:
        raise UserError(f"the working directory cannot be read ({err.strerror}): it was deleted or moved; cd to an "
                        "existing folder and run again") from None


def _limit(which: int) -> str:
    soft, _ = resource.getrlimit(which)
    return "unlimited" if soft == resource.RLIM_INFINITY else str(soft)


def resource_error(err: BaseException, resumable: bool) -> UserError | None:
    """The one-line error for running out of memory or of file descriptors (``err`` a
    ``MemoryError``, an ``OSError`` or the ``ImportError`` of a native library that could not be
    mapped), naming the limit in force, or for a path longer than the file system allows; None
    for any other error."""
    again = " (the stages already done are reused)" if resumable else ""
    mapped = isinstance(err, ImportError) and "failed to map segment" in str(err)  # a native library under ulimit -v
    if isinstance(err, MemoryError) or getattr(err, "errno", None) == errno.ENOMEM or mapped:
        limit = _limit(resource.RLIMIT_AS)
        where = "" if limit == "unlimited" else f" (`ulimit -v` limits this process to {int(limit) // 1024} KiB)"
        return UserError(f"out of memory{where}: raise the limit, close other programs or use a machine with more "
                         f"memory, or plan a coarser run (--grid-spacing, --yaws), then run again{again}")
    if getattr(err, "errno", None) == errno.ENAMETOOLONG:  # --out x*300: found by the first stat under it
        return UserError(f"{err.filename}: {os.strerror(errno.ENAMETOOLONG)}: give a shorter path (a file or folder "
                         "name has at most 255 bytes on most file systems)")
    if getattr(err, "errno", None) in (errno.EMFILE, errno.ENFILE):
        return UserError(f"too many open files (`ulimit -n` is {_limit(resource.RLIMIT_NOFILE)}): raise it (e.g. "
                         f"`ulimit -n 4096`) or use fewer --workers, then run again{again}")
    return None
