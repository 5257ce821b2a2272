"""One run per folder: the lock file of a run folder (:mod:`markerplace.runtime.run_folder`).

The run holds an exclusive ``flock`` on the lock file for its whole life and writes its pid,
host, command and start time into it. A second run finds the ``flock`` taken and stops with one
line naming that pid (exit 2). A lock file nobody holds was left by a run that ended without
cleaning up (killed): it is stale and taken over with a log line. Where ``flock`` is not
available (some network file systems) the pid decides: a lock whose pid is dead on this host is
stale, one from another host is refused.
"""

from __future__ import annotations

import errno
import json
import logging
import os
import socket
import time
from pathlib import Path

from markerplace.errors import UserError, write_error
import fcntl

log = logging.getLogger(__name__)

__all__ = ["RunLock", "pid_alive"]


def pid_alive(pid) -> bool:
    """Whether process ``pid`` exists on this host (a pid that is not a positive integer: no)."""
    if not isinstance(pid, int) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _read(fd: int) -> dict | None:
    try:
        data = json.loads(os.pread(fd, 4096, 0).decode() or "null")
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _read_path(lock: Path) -> dict | None:
    for _ in range(10):  # a run that just took the lock writes its pid a moment later
        try:
            fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW)
        except OSError:
            return None
        try:
            holder = _read(fd)
        finally:
            os.close(fd)
        if holder:
            return holder
        time.sleep(0.05)
    return None


class RunLock:
    """The lock file ``path`` of the run folder named ``what`` (for messages).

    :meth:`acquire` raises :class:`UserError` (one line) when another live run holds it or it
    cannot be written; :meth:`release` deletes it.
    """

    def __init__(self, path: Path, what: str):
        self.path, self.what = Path(path), what
        self._fd: int | None = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self, command: str) -> None:
        me = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
              "started": time.strftime("%Y-%m-%d %H:%M:%S")}
        for _ in range(20):
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            except OSError as err:
                if err.errno == errno.ELOOP:
                    raise UserError(f"{self.what}: {self.path} is a symbolic link; remove it") from None
                raise write_error(self.path, err) from None
            holder = _read(fd)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                flocked = True
            except BlockingIOError:
                os.close(fd)
                raise self.busy(_read_path(self.path) or holder) from None
            except OSError:  # no flock on this file system: the pid decides
                flocked = False
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # its holder deleted it while we opened it: take the new one
                os.close(fd)
                continue
            if holder and holder.get("pid") != me["pid"]:
                if not flocked and (holder.get("host") != me["host"] or pid_alive(holder.get("pid"))):
                    os.close(fd)
                    raise self.busy(holder)
                log.warning("%s: taking over the stale lock of markerplace run pid %s on %s (%s, started %s): that "
                            "run has ended", self.what, holder.get("pid"), holder.get("host"),
                            holder.get("command", "?"), holder.get("started", "?"))
            try:
                os.ftruncate(fd, 0)
                os.pwrite(fd, (json.dumps(me) + "\n").encode(), 0)
            except OSError as err:
                os.close(fd)
                raise write_error(self.path, err) from None
            self._fd = fd
            return
        raise UserError(f"{self.what}: could not take the lock {self.path}; try again")

    def busy(self, holder: dict | None) -> UserError:
        """The one-line refusal naming the run that holds the lock."""
        who = (f"pid {holder.get('pid')} on {holder.get('host')}, `markerplace {holder.get('command', '?')}` started "
               f"{holder.get('started', '?')}") if holder else "its pid is not written yet"
        return UserError(f"{self.what} is in use by another markerplace run ({who}): wait for it to finish or choose "
                         f"another folder (a lock left by a crashed run on another host: delete {self.path})")

    def release(self) -> None:
        """Delete the lock file and let go of it."""
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)
        except OSError:
            pass
        os.close(self._fd)
        self._fd = None
