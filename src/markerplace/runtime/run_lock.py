"""One run per folder: the lock file of a run folder (:mod:`markerplace.runtime.run_folder`).

The run holds an exclusive ``flock`` on the lock file for its whole life and writes its pid,
host, command and start time into it. A second run finds the ``flock`` taken and stops with one
line naming that pid (exit 2). A lock file nobody holds was left by a run that ended without
cleaning up (killed): it is stale and taken over with a log line. Where ``flock`` is not
available (some network file systems) the pid decides: a lock whose pid is dead on this host is
stale, one from another host is refused.
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import socket
import stat
import time
from pathlib import Path

from markerplace.errors import UserError, write_error

log = logging.getLogger(__name__)

__all__ = ["RunLock", "pid_alive", "odd_entry", "check_bookkeeping", "lock_for_reading", "release_readers"]

_readers: dict[str, int] = {}  # lock path -> descriptor of a shared (reader's) flock this process holds


def odd_entry(path: Path, links_too: bool = False) -> str | None:
    """What ``path`` is when it is neither missing nor a plain file (a folder, a named pipe, a
    socket, a device; with ``links_too`` also a symbolic link or a file with several hard links,
    whose other names would see every write), else None."""
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return None
    kinds = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"),
             (stat.S_ISCHR, "a device"), (stat.S_ISBLK, "a device"))
    what = next((name for test, name in kinds if test(st.st_mode)), None)
    if what is None and links_too:
        if stat.S_ISLNK(st.st_mode):
            what = "a symbolic link"
        elif st.st_nlink > 1:
            what = f"a hard link (one of {st.st_nlink} names of the same file, which markerplace would overwrite)"
    return what


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


def check_bookkeeping(folder: Path, names, what: str) -> None:
    """Refuse (one line) a folder, pipe, socket or device named like one of the bookkeeping files
    ``names`` in ``folder`` (they are replaced whole, which such an entry does not allow)."""
    for name in names:
        odd = odd_entry(Path(folder) / name)
        if odd is not None:
            raise UserError(f"{what}: {Path(folder) / name} is {odd}, where markerplace keeps its bookkeeping file "
                            f"{name}: remove it, then run again")


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
        _release_reader(self.path)  # this process read the folder first (check PLAN_DIR): it now writes it
        me = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
              "started": time.strftime("%Y-%m-%d %H:%M:%S")}
        for _ in range(20):
            odd = odd_entry(self.path, links_too=True)
            if odd is not None:
                raise self.odd(odd)
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
            except OSError as err:
                odd = odd_entry(self.path, links_too=True)  # made in between
                if odd is not None:
                    raise self.odd(odd) from None
                raise write_error(self.path, err) from None
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_nlink > 1:  # swapped in since the check above
                os.close(fd)
                raise self.odd(odd_entry(self.path, links_too=True) or "not a plain file")
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

    def odd(self, what: str) -> UserError:
        """The one-line refusal of a lock path that is not a plain file of its own."""
        return UserError(f"{self.what}: {self.path} is {what}, where markerplace keeps its lock file; markerplace "
                         "never writes into it: remove it, then run again")

    def busy(self, holder: dict | None) -> UserError:
        """The one-line refusal naming the run that holds the lock."""
        who = (f"pid {holder.get('pid')} on {holder.get('host')}, `markerplace {holder.get('command', '?')}` started "
               f"{holder.get('started', '?')}") if holder else \
            "one reading it (export, check or evaluate --plan) or one just starting"
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


def lock_for_reading(path: Path, what: str) -> None:
    """Hold a shared ``flock`` on the lock file ``path`` while this process reads its run folder
    (``export``, ``evaluate --plan``, ``check``: until :func:`release_readers`): a run writing the
    folder (which holds it exclusively) makes this one line naming it, and no run starts writing
    it meanwhile. Readers never write the file; one that finds it missing creates it empty, and
    the last reader deletes an empty one. A folder that cannot be written (a read-only share) or
    has no ``flock`` is read unlocked, unless a live run on this host is named in the file."""
    path = Path(path)
    key = os.path.realpath(path)  # the writer's RunLock names the real path (links above resolved)
    if key in _readers:
        return
    for _ in range(20):
        odd = odd_entry(path, links_too=True)
        if odd is not None:
            raise RunLock(path, what).odd(odd)
        try:
            fd = os.open(path, os.O_RDONLY | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError:
            return  # cannot be created here: read unlocked
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read(fd)
            os.close(fd)
            who = (f"pid {holder.get('pid')} on {holder.get('host')}, `markerplace {holder.get('command', '?')}` "
                   f"started {holder.get('started', '?')}") if holder else "its pid is not written yet"
            raise UserError(f"{what} is being written by another markerplace run ({who}): wait for it to finish, "
                            "then run again") from None
        except OSError:  # no flock here: a live writer on this host still refuses
            holder = _read(fd)
            os.close(fd)
            if holder and holder.get("host") == socket.gethostname() and pid_alive(holder.get("pid")):
                raise RunLock(path, what).busy(holder) from None
            return
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            _readers[key] = fd
            return
        os.close(fd)  # deleted by its last holder meanwhile: take the new one
    raise UserError(f"{what}: could not take the lock {path}; try again")


def _release_reader(path: Path) -> None:
    fd = _readers.pop(os.path.realpath(path), None)
    if fd is None:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # the last holder: delete the empty file it left
        if os.fstat(fd).st_size == 0 and os.fstat(fd).st_ino == os.stat(path).st_ino:
            os.unlink(path)
    except OSError:
        pass  # another reader (or a writer) holds it: theirs now
    os.close(fd)


def release_readers() -> None:
    """Let go of every shared lock :func:`lock_for_reading` took (the CLI calls it when a command ends)."""
    for key in list(_readers):
        _release_reader(Path(key))
