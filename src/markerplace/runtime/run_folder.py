"""Run folders markerplace owns: it writes, replaces and deletes only its own files in them.

A run folder (``--out`` of ``plan``, ``evaluate``, ``study``; ``check``'s ``PLAN_DIR`` and
``--out``) holds three bookkeeping files at its top: ``.markerplace-run.json``, the marker,
written when markerplace creates the folder, finds it empty or adopts it (``--adopt``; a
non-empty folder without it is refused, and ``/``, the home folder, the working directory and
the folders above them are never used); ``.markerplace-run.manifest``, every file and folder
markerplace made there (one JSON line each, appended before each write, compacted at each open):
only those are ever replaced or deleted, a write onto any other file is refused with one line;
and ``.markerplace-run.lock`` (:mod:`markerplace.runtime.run_lock`): one run per folder.

Nothing is written or deleted through a symbolic link below the folder: a link to a folder (or
a dangling one) in it is refused at open, and each write or deletion checks the path again.
Files are replaced with ``os.replace`` (:func:`markerplace.runtime.atomic_io.atomic_path` calls
:func:`prepare_write`), which replaces a link itself, never its target. A run that wrote
nothing leaves the folder as it found it (bookkeeping removed; the folder too if it made it).
Outside every open run folder (library use, ``render --out PREFIX``) files are written as
before, and only files this process wrote are deleted.
"""

from __future__ import annotations

import fnmatch
import json
import logging
import os
import threading
import time
from pathlib import Path
from typing import Iterable

from markerplace import __version__
from markerplace.errors import UserError, write_error
from markerplace.output_paths import check_output_dir
from markerplace.runtime.run_lock import RunLock, check_bookkeeping, release_readers

log = logging.getLogger(__name__)

__all__ = ["MARKER", "MANIFEST", "LOCK", "RunFolder", "open_run_folder", "close_all", "find", "prepare_write",
           "make_dirs", "remove", "remove_stale", "remove_tree"]

MARKER = ".markerplace-run.json"
MANIFEST = ".markerplace-run.manifest"
LOCK = ".markerplace-run.lock"
BOOKKEEPING = (MARKER, MANIFEST, LOCK)

_open: list["RunFolder"] = []
_written_here: set[str] = set()  # absolute paths written outside every run folder by this process
_guard = threading.Lock()


def _refused_places() -> list[tuple[str, str]]:
    """(real path, what it is) of the folders never used as a run folder: ``/``, the home folder,
    the working directory and every folder above the last two."""
    out = [("/", "the file-system root")]
    for base, what in ((os.path.expanduser("~"), "the home folder"), (os.getcwd, "the working directory")):
        try:
            real = os.path.realpath(base() if callable(base) else base)
        except OSError:  # the working directory was deleted
            continue
        out.append((real, what))
        out += [(str(p), f"a folder above {what}") for p in Path(real).parents]
    return out


def _links_inside(root: str) -> str | None:
    """The first symbolic link to a folder, or dangling, below ``root`` (links are not followed)."""
    stack = [root]
    while stack:
        try:
            with os.scandir(stack.pop()) as it:
                for entry in it:
                    if entry.is_symlink():
                        if not os.path.isfile(entry.path):
                            return entry.path
                    elif entry.is_dir(follow_symlinks=False):
                        stack.append(entry.path)
        except OSError:
            continue  # a folder that cannot be read: nothing is written there either
    return None


class RunFolder:
    """One open run folder: its lock, marker and manifest. Made by :func:`open_run_folder`.

    Attributes:
        path: the folder as given (absolute, links not resolved).
        real: the folder with links resolved (where the bookkeeping files are).
        option: the option that named it (for messages).
    """

    def __init__(self, path: Path, option: str):
        self.path = Path(os.path.abspath(path))
        self.real = Path(os.path.realpath(path))
        self.option = option
        self.files: set[str] = set()
        self.dirs: set[str] = set()
        self._made: list[Path] = []  # folders this open created, the run folder's parents first
        self._manifest_fh = None
        self._pristine = False  # this open wrote the marker (a new, empty or adopted folder) and nothing else yet
        self.lock = RunLock(self.real / LOCK, f"{option} {self.path}")

    def relative(self, path) -> str | None:
        """``path`` relative to the folder ('' for the folder itself), or None when outside."""
        p = os.path.abspath(path)
        for base in (str(self.path), str(self.real)):
            if p == base:
                return ""
            if p.startswith(base.rstrip(os.sep) + os.sep):
                return os.path.relpath(p, base)
        return None

    def _checked(self, rel: str) -> Path:
        """The real path of ``rel``; a symbolic link on the way (below the folder) is refused."""
        parts = Path(rel).parts
        if ".." in parts:
            raise UserError(f"{self.option} {self.path}: {rel} leads out of the run folder")
        here = self.real
        for name in parts[:-1]:
            here = here / name
            if here.is_symlink():
                raise self._link_error(here)
        return self.real / rel

    def _link_error(self, link: Path) -> UserError:
        return UserError(f"{self.option} {self.path}: {link} is a symbolic link (to {os.readlink(link)}); markerplace "
                         "never writes or deletes through links in its run folder: remove the link or choose another "
                         "folder")

    def _apply(self, op: str, rel: str) -> None:
        group = self.files if op[1] == "f" else self.dirs
        group.add(rel) if op[0] == "+" else group.discard(rel)

    def _record(self, op: str, rel: str) -> None:
        with _guard:
            try:
                self._manifest_fh.write(json.dumps([op, rel]) + "\n")
                self._manifest_fh.flush()
            except OSError as err:
                raise write_error(self.real / MANIFEST, err) from None
            self._apply(op, rel)
            self._pristine = False

    def _mark(self, command: str) -> None:
        """Write the marker when the folder has none (made now, empty, or adopted)."""
        marker = self.real / MARKER
        if marker.is_file() and not marker.is_symlink():
            return
        foreign = len(set(os.listdir(self.real)) - set(BOOKKEEPING))

        text = json.dumps({"markerplace_run": 1, "version": __version__, "command": command, "adopted": bool(foreign),
                           "created": time.strftime("%Y-%m-%d %H:%M:%S")}, indent=2) + "\n"
        tmp = self.real / f".{MARKER}.{os.getpid()}"
        try:
            tmp.write_text(text)
            os.replace(tmp, marker)
            self._pristine = True
        except OSError as err:
            tmp.unlink(missing_ok=True)
            raise write_error(marker, err) from None
        if foreign:
            log.info("%s: adopted; the %d entries already in it are left alone", self.path, foreign)

    def _load_manifest(self) -> None:
        path = self.real / MANIFEST
        if path.is_file() and not path.is_symlink():
            for line in path.read_text(errors="replace").splitlines():
                try:
                    op, rel = json.loads(line)
                except (ValueError, TypeError):
                    continue  # a line torn by a crash
                if op in ("+f", "-f", "+d", "-d") and isinstance(rel, str):
                    self._apply(op, rel)
        self.files = {f for f in self.files if os.path.lexists(self.real / f)}  # a claim on nothing is dropped
        self.dirs = {d for d in self.dirs if os.path.isdir(self.real / d)}
        tmp = self.real / f".{MANIFEST}.{os.getpid()}"
        try:
            with open(tmp, "w") as fh:
                fh.writelines(json.dumps(["+d", d]) + "\n" for d in sorted(self.dirs))
                fh.writelines(json.dumps(["+f", f]) + "\n" for f in sorted(self.files))
            os.replace(tmp, path)
            self._manifest_fh = open(path, "a")
        except OSError as err:
            tmp.unlink(missing_ok=True)
            raise write_error(path, err) from None

    def make_dirs(self, rel: str) -> Path:
        here, made = self.real, ""
        for name in Path(rel).parts:
            here, made = here / name, os.path.join(made, name)
            if here.is_symlink():
                raise self._link_error(here)
            if not here.exists():
                try:
                    here.mkdir()
                except FileExistsError:
                    pass
                except OSError as err:
                    raise write_error(here, err) from None
                self._record("+d", made)
            elif not here.is_dir():
                raise UserError(f"{self.option} {self.path}: {here} is a file, so markerplace cannot make the folder "
                                f"{made} there: move it away or choose another folder")
        return here

    def prepare_write(self, rel: str) -> Path:
        if rel in BOOKKEEPING or rel == "":
            raise UserError(f"{self.option} {self.path}: {rel or 'the folder'} is not a file markerplace writes")
        target = self._checked(rel)
        self.make_dirs(os.path.dirname(rel))
        if os.path.lexists(target):
            if target.is_dir() and not target.is_symlink():
                raise UserError(f"{self.option} {self.path}: {rel} is a folder where markerplace writes a file: move "
                                "it away or choose another folder")
            if rel not in self.files:
                raise UserError(f"{self.option} {self.path}: {rel} was not written by markerplace (the folder was "
                                "adopted with it in it), so it is not replaced: move it away or choose another folder")
        else:
            self._record("+f", rel)
        return target

    def remove(self, rel: str) -> bool:
        target = self._checked(rel)
        if rel not in self.files:
            if os.path.lexists(target):
                log.debug("%s: %s is not markerplace's; left in place", self.path, rel)
            return False
        try:
            os.unlink(target)  # a link is removed itself, never its target
        except FileNotFoundError:
            pass
        except IsADirectoryError:
            return False
        self._record("-f", rel)
        return True

    def remove_tree(self, rel: str) -> None:
        prefix = rel.rstrip(os.sep) + os.sep
        for f in sorted(f for f in self.files if f.startswith(prefix)):
            self.remove(f)
        for d in sorted((d for d in self.dirs if d == rel or d.startswith(prefix)), key=len, reverse=True):
            try:
                os.rmdir(self._checked(d))
                self._record("-d", d)
            except FileNotFoundError:
                self._record("-d", d)
            except OSError:
                pass  # not empty: it holds files markerplace did not write

    def close(self) -> None:
        """Release the lock; a folder this run wrote nothing into is left as it was found."""
        if self._manifest_fh is not None:
            self._manifest_fh.close()
            self._manifest_fh = None
        if not self.lock.held:
            return
        try:
            if set(os.listdir(self.real)) <= set(BOOKKEEPING) or self._pristine:
                # nothing written: leave it as it was found (an adopted folder a refused run wrote nothing into too)
                for name in (MARKER, MANIFEST):
                    (self.real / name).unlink(missing_ok=True)
        except OSError:
            pass
        self.lock.release()
        for folder in reversed(self._made):
            try:
                folder.rmdir()  # only while empty
            except OSError:
                break


def open_run_folder(path, command: str, *, adopt: bool = False, option: str = "--out") -> RunFolder:
    """Open ``path`` as this process's run folder for the subcommand ``command``: checked,
    created when missing, marked, locked; every write below it goes through it until
    :func:`close_all`. A path inside a run folder already open returns that one. ``adopt``: use
    a non-empty folder without the marker (its files are left alone); ``option`` names the
    folder in messages.

    Raises:
        UserError: one line, before anything is written: ``/``, the home folder, the working
            directory or a folder above them; a dangling link; a file; a non-empty folder
            without the marker (and not ``adopt``); a link to a folder inside it; a folder that
            cannot be written; a folder another run holds (naming its pid).
    """
    given = Path(path)
    if given.is_symlink() and not given.exists():
        raise UserError(f"{option} {given} is a symbolic link to {os.readlink(given)}, which does not exist: give a "
                        "real folder or fix the link")
    real = os.path.realpath(given)
    marked = os.path.isfile(os.path.join(real, MARKER)) and not os.path.islink(os.path.join(real, MARKER))
    for place, what in _refused_places():
        if real == place and not (marked and "working directory" in what):  # `check .` in a plan folder
            raise UserError(f"{option} {given} is {what}; markerplace writes a run into a folder of its own: give a "
                            "new folder, e.g. {}".format(os.path.join(str(given), "markerplace_run")))
    owner = find(given)
    if owner is not None:
        return owner
    if given.exists() and given.is_dir():
        try:
            names = set(os.listdir(given)) - set(BOOKKEEPING)
        except OSError as err:
            raise UserError(f"{option} {given}: cannot read the folder ({err.strerror}); choose another") from None
        if names and not marked and not adopt:
            raise UserError(f"{option} {given} is not empty and was not made by markerplace (no {MARKER}): give a new "
                            "or empty folder, or pass --adopt to add the run's files to it (the files already there "
                            "are never replaced or deleted)")
    link = _links_inside(real) if given.is_dir() else None
    if link is not None:
        raise RunFolder(given, option)._link_error(Path(link))
    check_output_dir(given, option)
    check_bookkeeping(Path(real), (MARKER, MANIFEST), f"{option} {given}")  # the lock: RunLock.acquire
    made = [Path(os.path.abspath(p)) for p in (given, *given.parents) if not os.path.lexists(p)][::-1]
    try:
        given.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise write_error(given, err) from None
    folder = RunFolder(given, option)
    folder._made = made
    try:
        folder.lock.acquire(command)
        folder._mark(command)
        folder._load_manifest()
    except BaseException:
        folder.close()
        raise
    _open.append(folder)
    return folder


def close_all() -> None:
    """Close every run folder this process opened (the CLI calls it when a command ends)."""
    while _open:
        _open.pop().close()
    release_readers()  # export, evaluate --plan: the plan folders read


def find(path) -> RunFolder | None:
    """The innermost open run folder holding ``path``, or None."""
    holding = (f for f in _open if f.relative(path) is not None)
    return max(holding, key=lambda f: len(str(f.path)), default=None)


def _mkdirs_outside(folder: Path) -> None:
    """``folder.mkdir(parents=True)``, remembering the folders it made (outside run folders)."""
    missing = [p for p in (folder, *folder.parents) if not os.path.lexists(p)]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise write_error(folder, err) from None
    _written_here.update(os.path.abspath(p) for p in missing)


def _locate(path) -> tuple[RunFolder | None, str]:
    folder = find(path)
    return (folder, folder.relative(path)) if folder is not None else (None, os.path.abspath(path))


def prepare_write(path) -> Path:
    """Make ``path``'s folder and claim ``path`` before a write (called by
    :func:`markerplace.runtime.atomic_io.atomic_path`). Inside a run folder: refuses links on the way, a
    folder at ``path`` and a file markerplace did not write, and records ``path`` in the
    manifest. Returns the path to write (links above the run folder resolved)."""
    folder, rel = _locate(path)
    if folder is None:
        _mkdirs_outside(Path(rel).parent)
        _written_here.add(rel)
        return Path(path)
    return folder.prepare_write(rel)


def make_dirs(path) -> Path:
    """Create the folder ``path`` (and its parents), recorded in the run folder's manifest."""
    folder, rel = _locate(path)
    if folder is None:
        _mkdirs_outside(Path(rel))
        return Path(path)
    return folder.make_dirs(rel)


def remove(path) -> bool:
    """Delete the file ``path`` if markerplace wrote it (in a run folder: it is in the manifest;
    elsewhere: this process wrote it). Returns whether it was deleted."""
    folder, rel = _locate(path)
    if folder is not None:
        return folder.remove(rel)
    if rel not in _written_here or os.path.isdir(rel) and not os.path.islink(rel):
        return False
    Path(rel).unlink(missing_ok=True)
    _written_here.discard(rel)
    return True


def remove_stale(folder, keep: Iterable, pattern: str = "*") -> list[Path]:
    """Delete the files markerplace wrote directly in ``folder`` whose names match ``pattern``
    and which are not in ``keep`` (an earlier run's outputs). Returns the deleted paths."""
    folder, keep_names = Path(folder), {Path(p).name for p in keep}
    present = sorted(folder.iterdir()) if folder.is_dir() else []
    return [p for p in present if p.name not in keep_names and fnmatch.fnmatchcase(p.name, pattern) and remove(p)]


def remove_tree(path) -> None:
    """Delete the files markerplace wrote below the folder ``path``, then its folders that are
    empty; anything else stays."""
    folder, rel = _locate(path)
    if folder is not None:
        folder.remove_tree(rel)
        return
    prefix = rel.rstrip(os.sep) + os.sep
    mine = sorted((p for p in _written_here if p == rel or p.startswith(prefix)), key=len, reverse=True)
    for p in mine:  # files first (deepest paths first), then the folders once empty
        if os.path.isdir(p) and not os.path.islink(p):
            try:
                os.rmdir(p)
            except OSError:
                continue
        else:
            Path(p).unlink(missing_ok=True)
        _written_here.discard(p)
