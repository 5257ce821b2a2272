"""One folder for every cache the tool and its libraries write: ``$MARKERPLACE_CACHE``.

markerplace writes nothing outside the ``--out`` folder it is given and this cache folder.
The libraries it uses keep caches of their own, by default next to their source or under the
home folder (numba's compiled kernels in ``__pycache__`` next to the module or ``~/.cache/numba``,
matplotlib's font list in ``~/.config/matplotlib``, Mesa's shader cache in
``~/.cache/mesa_shader_cache``, Dask's worker folders in ``$TMPDIR/dask-scratch-space``). A
service account with neither the install tree nor its home writable could not even import the
tool (numba: "cannot cache function ...: no locator available").

:func:`setup` (run by ``markerplace/__init__.py``, before numba, matplotlib, Mesa or Dask is
loaded) picks the folder and points each library there through its environment variable
(:data:`LIBRARY_VARIABLES`); child processes (a process pool's workers, a ``LocalCluster``'s)
inherit the variables, and ``MARKERPLACE_CACHE`` itself, so they use the same folder:

1. ``$MARKERPLACE_CACHE`` when set and writable;
2. else the platform's user cache folder (:func:`platformdirs.user_cache_dir`:
   ``$XDG_CACHE_HOME/markerplace`` or ``~/.cache/markerplace`` on Linux,
   ``~/Library/Caches/markerplace`` on macOS, ``%LOCALAPPDATA%\\markerplace\\Cache`` on Windows)
   when it can be created and written;
3. else a new temporary folder (``$TMPDIR/markerplace-cache-*``), removed when the process that
   made it exits: everything works, only the caches are not kept between runs
   (:data:`NOTE` says so; the command line logs it).

A library variable already set in the environment is left as it is (the user chose that place).
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path

import platformdirs

__all__ = ["ENV", "LIBRARY_VARIABLES", "NOTE", "NOTE_IS_WARNING", "setup", "cache_root", "remove_temporary"]

ENV = "MARKERPLACE_CACHE"
"""The environment variable naming the cache folder."""

LIBRARY_VARIABLES = {
    "NUMBA_CACHE_DIR": "numba",  # compiled kernels (cache=True); read when numba is imported
    "MPLCONFIGDIR": "matplotlib",  # font list cache (and matplotlibrc: the user's is not read)
    "MESA_SHADER_CACHE_DIR": "mesa",  # Mesa >= 21 (llvmpipe's compiled shaders)
    "MESA_GLSL_CACHE_DIR": "mesa",  # older Mesa
    "DASK_TEMPORARY_DIRECTORY": "dask",  # dask config ``temporary-directory``: local workers' scratch space
}
"""Environment variable -> its subfolder of the cache folder."""

NOTE: list[str] = []
"""Why the cache folder is not the one asked for (a line for the log), empty when it is."""
NOTE_IS_WARNING: list[bool] = []
"""``[True]`` when :data:`NOTE` is about a ``$MARKERPLACE_CACHE`` the user set (a warning), else
empty (an info line: the default folder is not writable, as for a service account)."""

_root: list[Path] = []
_temporary: list[tuple[int, Path]] = []  # (pid that made it, folder) of a fallback folder


def _writable(folder: Path) -> bool:
    """Create ``folder`` (and its parents) and write a file in it; False when that fails."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, name = tempfile.mkstemp(prefix=".probe-", dir=folder)
        os.close(fd)
        os.unlink(name)
        return True
    except (OSError, ValueError):
        return False


def _default_folder() -> Path | None:
    try:
        return Path(platformdirs.user_cache_dir("markerplace", appauthor=False))
    except Exception:  # no home folder at all (a service account without a passwd entry)
        return None


def remove_temporary() -> None:
    """Remove the fallback temporary cache folder if this process made it (at exit; also called
    by the interrupt watchdog, which ends the process without running ``atexit``)."""
    for pid, folder in list(_temporary):
        if pid == os.getpid():
            shutil.rmtree(folder, ignore_errors=True)
            _temporary.remove((pid, folder))


def setup() -> Path | None:
    """Choose the cache folder (see the module docstring), export it as ``$MARKERPLACE_CACHE``
    and point the libraries' variables at its subfolders. Idempotent.

    Returns:
        The folder, or None when not even a temporary folder can be made (the libraries then
        use their own defaults).
    """
    if _root:
        return _root[0]
    asked = os.environ.get(ENV, "").strip()
    root: Path | None = None
    if asked:
        if _writable(Path(asked)):
            root = Path(asked)
        else:
            NOTE.append(f"{ENV}={asked} cannot be written")
            NOTE_IS_WARNING.append(True)
    if root is None:
        default = _default_folder()
        if default is not None and not asked and _writable(default):
            root = default
        elif not asked:
            NOTE.append(f"the user cache folder {default or '(no home folder)'} cannot be written")
    if root is None:
        try:
            root = Path(tempfile.mkdtemp(prefix="markerplace-cache-"))
        except OSError:
            NOTE.append("no temporary folder can be made either; the libraries use their own cache folders")
            return None
        _temporary.append((os.getpid(), root))
        atexit.register(remove_temporary)
        NOTE[-1] += (f"; caches go to the temporary folder {root}, removed at exit (set {ENV} to a writable "
                     "folder to keep them between runs)")
    root = root.resolve()
    os.environ[ENV] = str(root)
    for var, sub in LIBRARY_VARIABLES.items():
        if not os.environ.get(var):
            os.environ[var] = str(root / sub)
    if "numba" in sys.modules:  # imported before markerplace: its config was read already
        try:
            sys.modules["numba"].config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]
        except Exception:  # pragma: no cover - numba's config moved
            pass
    _root.append(root)
    return root


def cache_root() -> Path | None:
    """The cache folder chosen by :func:`setup` (running it first if needed)."""
    return setup()
