"""The run folder's lock and bookkeeping files when something else sits under their names
(:mod:`markerplace.runtime.run_lock`, issue 50 item 4): a folder, a named pipe or, for the lock
file, a hard link to another file is refused with one line, and nothing is written into it."""

from __future__ import annotations

import os

import pytest

from helpers import FAST
from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import write_json


def _make(kind: str, path, target) -> None:
    path.unlink(missing_ok=True)  # the manifest of the run
    if kind == "folder":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    else:
        os.link(target, path)


@pytest.fixture
def run(tmp_path):
    """A run folder markerplace made (marked, closed), and a file of the user's outside it."""
    folder = tmp_path / "run"
    run_folder.open_run_folder(folder, "test")
    write_json(folder / "kept.json", {"x": 1})  # something written: the folder stays marked
    run_folder.close_all()
    target = tmp_path / "precious.txt"
    target.write_text("the user's own text")
    return folder, target


@pytest.mark.parametrize("name, kind, needle", [
    (run_folder.LOCK, "folder", "is a folder, where markerplace keeps its lock file"),
    (run_folder.LOCK, "fifo", "is a named pipe (FIFO), where markerplace keeps its lock file"),
    (run_folder.LOCK, "hard link", "is a hard link (one of 2 names of the same file"),
    (run_folder.MANIFEST, "folder", "is a folder, where markerplace keeps its bookkeeping file"),
])
def test_an_odd_entry_under_a_bookkeeping_name_is_refused_and_left_alone(name, kind, needle, run):
    folder, target = run
    _make(kind, folder / name, target)
    try:
        with pytest.raises(UserError, match="remove it, then run again") as err:
            run_folder.open_run_folder(folder, "test")
    finally:
        run_folder.close_all()
    assert needle in str(err.value) and "\n" not in str(err.value)
    assert target.read_text() == "the user's own text"  # the hard link's file is not overwritten
    assert os.path.lexists(folder / name)


def test_a_marker_named_folder_in_an_adopted_folder_is_one_line(tmp_path, capsys):
    out = tmp_path / "theirs"
    (out / run_folder.MARKER).mkdir(parents=True)
    assert main(["plan", "tiny", "-k", "2", "--out", str(out), "--adopt", *FAST]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is a folder, where markerplace keeps its bookkeeping file" in err, err


def test_a_lock_named_folder_in_a_plan_folder_is_one_line(run, capsys):
    folder, _ = run
    (folder / run_folder.LOCK).mkdir()
    assert main(["plan", "tiny", "-k", "2", "--out", str(folder), *FAST]) == 2
    err = capsys.readouterr().err
    assert err.startswith("markerplace: error: ") and err.count("\n") == 1 and "lock file" in err, err
