"""The command line's edge (:mod:`markerplace.cli.edge`, issue 50 item 4): standard output on a full
device or in ASCII, a deleted working directory, ``ulimit -n`` and out-of-memory errors end in
one line ``markerplace: error: ...`` with exit code 2, never a traceback."""

from __future__ import annotations

import errno
import importlib
import os
import resource
import subprocess
import sys

import pytest

from helpers import SRC
from markerplace.cli.edge import resource_error

cli_main = importlib.import_module("markerplace.cli.main")  # the module (``markerplace.cli.main`` is also the function)
ENV = {**os.environ, "PYTHONPATH": str(SRC) + (os.pathsep + os.environ["PYTHONPATH"] if os.environ.get("PYTHONPATH")
                                               else "")}


def _cli(args, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "markerplace.cli", *args], capture_output=kw.pop("capture", True),
                          text=True, env={**ENV, **kw.pop("env", {})}, timeout=300, **kw)


def _one_line(res, needle: str) -> str:
    lines = [ln for ln in res.stderr.strip().splitlines() if ln.strip()]
    assert res.returncode == 2 and len(lines) == 1 and lines[0].startswith("markerplace: error: "), \
        (res.returncode, res.stderr)
    assert needle in lines[0]
    return lines[0]


def test_stdout_on_a_full_device_is_one_line():
    with open("/dev/full", "w") as full:
        res = subprocess.run([sys.executable, "-m", "markerplace.cli", "scene", "list"], stdout=full,
                             stderr=subprocess.PIPE, text=True, env=ENV, timeout=120)
    _one_line(res, "cannot write to standard output: No space left on device")


def test_a_non_ascii_out_on_an_ascii_stdout_is_printed_escaped(tmp_path):
    res = _cli(["--quiet", "render", "tiny", "--out", str(tmp_path / "été" / "v"), "--width", "64", "--height", "48"],
               env={"PYTHONIOENCODING": "ascii"})
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    assert "\\xe9t\\xe9" in res.stdout and (tmp_path / "été" / "v_rgb.png").is_file()


def test_a_deleted_working_directory_is_one_line(tmp_path):
    gone = tmp_path / "gone"
    gone.mkdir()
    res = subprocess.run(["sh", "-c", f"cd '{gone}' && rmdir '{gone}' && exec '{sys.executable}' -m markerplace.cli "
                          "plan tiny --out o"], capture_output=True, text=True, env=ENV, timeout=120)
    _one_line(res, "the working directory cannot be read")


def test_too_few_file_descriptors_for_the_workers_is_one_line(tmp_path):
    def limit():
        resource.setrlimit(resource.RLIMIT_NOFILE, (16, 16))

    res = _cli(["plan", "tiny", "-k", "2", "--out", str(tmp_path / "o"), "--grid-spacing", "1.0", "--yaws", "2",
                "--workers", "2", "--quiet"], preexec_fn=limit)
    _one_line(res, "too many open files (`ulimit -n` is 16)")


@pytest.mark.parametrize("error, needle", [
    (MemoryError(), "out of memory"),
    (OSError(errno.ENOMEM, "Cannot allocate memory"), "out of memory"),
    (ImportError("libscipy_openblas.so: failed to map segment from shared object"), "out of memory"),
    (OSError(errno.EMFILE, "Too many open files"), "too many open files"),
])
def test_resource_errors_anywhere_in_a_command_are_one_line(error, needle, monkeypatch, capsys):
    def fail(args):
        raise error

    monkeypatch.setattr(cli_main, "cmd_scene_list", fail)
    assert cli_main.main(["scene", "list"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("markerplace: error: ") and err.count("\n") == 1 and needle in err, err


def test_other_errors_are_not_disguised():
    assert resource_error(OSError(errno.EIO, "Input/output error"), False) is None
    assert resource_error(ImportError("No module named x"), False) is None


def test_an_out_path_with_a_name_too_long_for_the_file_system_is_one_line(tmp_path, capsys):
    out = tmp_path / ("x" * 300)
    assert cli_main.main(["plan", "tiny", "-k", "2", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("markerplace: error: ") and err.count("\n") == 1 and "File name too long" in err, err
    assert "give a shorter path" in err and list(tmp_path.iterdir()) == []


def test_a_closed_stdout_is_one_line():
    res = subprocess.run([sys.executable, "-m", "markerplace.cli", "--version"], stderr=subprocess.PIPE, text=True,
                         env=ENV, timeout=300, preexec_fn=lambda: os.close(1))  # the shell's `>&-`
    assert "Traceback" not in res.stderr
    _one_line(res, "cannot write to standard output: it is closed")
