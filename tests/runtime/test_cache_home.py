"""Nothing is written outside ``--out`` and the cache folder (``runtime/cache_home.py``).

* Which folder: ``$MARKERPLACE_CACHE``, else the user cache folder (``$XDG_CACHE_HOME``), else a
  temporary folder removed at exit; the libraries' variables point into it (a fresh interpreter
  each, as the variables are read when numba and matplotlib are imported).
* A writable home: Mesa, matplotlib, numba and a ``LocalCluster`` write under
  ``~/.cache/markerplace`` alone.
* A service account: the CLI run as uid 65534 (``setpriv``) with an unwritable home and install
  tree (it died at import: numba "no locator available"), ``--version``, ``scene list`` and a
  small plan; no file of that user appears outside ``--out`` and the cache folder (the home,
  ``/tmp``, ``/var/tmp``, ``/dev/shm``, this checkout and the Python installation searched).
"""

from __future__ import annotations

import glob
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

import markerplace
from markerplace.runtime.cache_home import ENV, LIBRARY_VARIABLES

SRC = Path(markerplace.__file__).resolve().parents[1]
CHECKOUT = SRC.parent
NOBODY = 65534
PROBE = ("import json, os, markerplace\n"
         "from markerplace.runtime import cache_home\n"
         "print(json.dumps({'root': os.environ.get('MARKERPLACE_CACHE'), 'note': cache_home.NOTE,\n"
         "                  'vars': {v: os.environ.get(v) for v in cache_home.LIBRARY_VARIABLES}}))\n")


def _clean_env(**extra: str) -> dict:
    """This environment without the cache variables this test process got when it imported
    markerplace, plus ``extra``."""
    env = {k: v for k, v in os.environ.items()
           if k not in (ENV, *LIBRARY_VARIABLES, "XDG_CACHE_HOME", "XDG_CONFIG_HOME", "PYTHONPATH")}
    env["PYTHONPATH"] = str(SRC)
    env.update(extra)
    return env


def _probe(**env: str) -> dict:
    res = subprocess.run([sys.executable, "-c", PROBE], env=_clean_env(**env), capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_markerplace_cache_names_the_folder_of_every_library_cache(tmp_path):
    got = _probe(MARKERPLACE_CACHE=str(tmp_path / "c"), HOME=str(tmp_path / "home"))
    root = (tmp_path / "c").resolve()
    assert got["root"] == str(root) and got["note"] == []
    assert got["vars"] == {v: str(root / sub) for v, sub in LIBRARY_VARIABLES.items()}
    assert got["vars"]["NUMBA_CACHE_DIR"].endswith("/numba") and got["vars"]["MPLCONFIGDIR"].endswith("/matplotlib")


def test_the_default_is_the_user_cache_folder_and_a_variable_set_by_the_user_is_kept(tmp_path):
    got = _probe(XDG_CACHE_HOME=str(tmp_path / "xdg"), HOME=str(tmp_path / "home"),
                 NUMBA_CACHE_DIR=str(tmp_path / "mine"))
    root = (tmp_path / "xdg" / "markerplace").resolve()
    assert got["root"] == str(root) and root.is_dir()
    assert got["vars"]["NUMBA_CACHE_DIR"] == str(tmp_path / "mine")
    assert got["vars"]["MPLCONFIGDIR"] == str(root / "matplotlib")


def test_an_unwritable_cache_folder_falls_back_to_a_temporary_one_removed_at_exit(tmp_path):
    (tmp_path / "file").write_text("not a folder")
    (tmp_path / "tmp").mkdir()
    got = _probe(MARKERPLACE_CACHE=str(tmp_path / "file" / "cache"), TMPDIR=str(tmp_path / "tmp"),
                 HOME=str(tmp_path / "home"))
    root = Path(got["root"])
    assert root.parent == (tmp_path / "tmp").resolve() and root.name.startswith("markerplace-cache-")
    assert not root.exists() and list((tmp_path / "tmp").iterdir()) == []  # removed at exit
    assert len(got["note"]) == 1 and f"{ENV}={tmp_path / 'file' / 'cache'} cannot be written" in got["note"][0]
    assert "removed at exit" in got["note"][0]


LIBRARIES = """
import sys
from markerplace.cli.main import main  # markerplace first, as the command line does
from markerplace.runtime.executor import DaskExecutor, WorkerJob
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
out = sys.argv[1]
assert main(["--quiet", "render", "tiny", "--out", out + "/r"]) == 0  # Mesa (and numba on import)
plt.plot([1, 2]); plt.savefig(out + "/f.png")  # matplotlib's font list
with DaskExecutor("local:1") as ex:  # a LocalCluster's worker folders
    assert sorted(ex.map(pow, [1, 2], WorkerJob(build=len, spec="abc", key="k"))) == [(0, 3), (1, 9)]
"""


def test_a_writable_home_gets_only_the_cache_folder(tmp_path):
    """Mesa, matplotlib, numba and a LocalCluster used with a writable home and no XDG variables:
    everything under ``~/.cache/markerplace`` (not ``~/.config/matplotlib``,
    ``~/.cache/mesa_shader_cache``, ``$TMPDIR/dask-scratch-space``)."""
    home, tmp, out = tmp_path / "home", tmp_path / "tmp", tmp_path / "out"
    for folder in (home, tmp, out):
        folder.mkdir()
    res = subprocess.run([sys.executable, "-c", LIBRARIES, str(out)], env=_clean_env(HOME=str(home), TMPDIR=str(tmp)),
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert [p.name for p in home.iterdir()] == [".cache"] and [p.name for p in (home / ".cache").iterdir()] == \
        ["markerplace"]
    cache = home / ".cache" / "markerplace"
    assert {p.name for p in cache.iterdir()} == {"numba", "matplotlib", "mesa", "dask"}
    assert (cache / "dask" / "dask-scratch-space").is_dir()
    assert list(tmp.iterdir()) == []


# --- as a service account ----------------------------------------------------------------------


def _as_nobody(argv: list[str], env: dict, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups", "--", *argv],
                          env=env, cwd="/", capture_output=True, text=True, timeout=timeout)


def _files_of_nobody(roots: list[str]) -> set[str]:
    """Every path under ``roots`` owned by uid 65534 (``find -user``; unreadable folders skipped)."""
    res = subprocess.run(["find", *[r for r in roots if os.path.exists(r)], "-user", str(NOBODY)],
                         capture_output=True, text=True, timeout=300)
    return set(res.stdout.split())


@pytest.fixture
def sandbox():
    """A folder uid 65534 can reach (the pytest temporary folder is root's alone): ``home`` (not
    writable by it), ``tmp`` (its TMPDIR), ``out`` and ``cache`` (writable by it). Removed after."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv (util-linux) to run the CLI as uid 65534")
    root = Path(tempfile.mkdtemp(prefix="markerplace-unpriv-"))
    try:
        root.chmod(0o755)
        (root / "home").mkdir(mode=0o755)
        for name in ("tmp", "out", "cache"):
            (root / name).mkdir()
            os.chown(root / name, NOBODY, NOBODY)
        yield root
    finally:
        shutil.rmtree(root, ignore_errors=True)


def test_a_service_account_runs_it_and_writes_only_to_out_and_the_cache(sandbox):
    env = _clean_env(HOME=str(sandbox / "home"), TMPDIR=str(sandbox / "tmp"), LC_ALL="C.UTF-8")
    cli = [sys.executable, "-m", "markerplace.cli"]
    readable = _as_nobody([sys.executable, "-c", f"import numpy, os; os.listdir({str(SRC / 'markerplace')!r})"], env)
    if readable.returncode != 0:
        pytest.skip(f"uid {NOBODY} cannot run {sys.executable} or read {SRC}: {readable.stderr.strip()[-200:]}")
    # a venv whose interpreter sits under root's home can be started by setpriv but not by a child
    # of the unprivileged process: then the plan runs in this process (--workers 1)
    spawn = _as_nobody([sys.executable, "-c", "import subprocess, sys; subprocess.run([sys.executable, '-c', '0'], "
                                              "check=True)"], env)
    workers = "2" if spawn.returncode == 0 else "1"
    roots = ["/tmp", "/var/tmp", "/dev/shm", str(CHECKOUT), sys.prefix, sys.base_prefix, str(sandbox / "home")]
    sandboxes = os.path.join(tempfile.gettempdir(), "markerplace-unpriv-")
    before = _files_of_nobody(roots)

    version = _as_nobody([*cli, "--version"], env)
    assert version.returncode == 0 and version.stdout.strip() == f"markerplace {markerplace.__version__}", \
        version.stderr[-3000:]
    assert version.stderr == ""

    listing = _as_nobody([*cli, "scene", "list"], env)
    assert listing.returncode == 0 and "tiny" in listing.stdout, listing.stderr[-3000:]
    # the home folder's cache cannot be written: a temporary one, said in one info line
    assert "cannot be written; caches go to the temporary folder " in listing.stderr, listing.stderr
    assert "Traceback" not in listing.stderr

    plan = _as_nobody([*cli, "plan", "tiny", "-k", "1", "--out", str(sandbox / "out" / "p"), "--grid-spacing", "1.5",
                       "--yaws", "1", "--paper", "none", "--workers", workers, "--quiet"],
                      {**env, ENV: str(sandbox / "cache")})
    assert plan.returncode == 0, plan.stderr[-3000:]
    assert json.loads((sandbox / "out" / "p" / "placement.json").read_text())["markers"]
    cache = sandbox / "cache"
    assert glob.glob(str(cache / "numba" / "**" / "*.nbi"), recursive=True)  # the compiled kernels
    assert list((cache / "matplotlib").glob("fontlist-*.json"))
    assert {p.name for p in cache.iterdir()} <= set(LIBRARY_VARIABLES.values())

    new = {p for p in _files_of_nobody(roots) - before if not p.startswith(sandboxes)}
    assert new == set(), sorted(new)[:20]
    assert list((sandbox / "home").iterdir()) == []
    assert list((sandbox / "tmp").iterdir()) == []  # the temporary caches were removed at exit
