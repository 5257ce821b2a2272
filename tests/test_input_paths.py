"""Input files checked before they are read: what a path is when it is not a plain file, and the
one-line error that says so."""

from __future__ import annotations

import os
import socket

import pytest

from markerplace.errors import UserError
from markerplace.input_paths import check_input_file, input_kind


def test_input_kind_names_each_kind_of_path(tmp_path):
    (tmp_path / "f.json").write_text("{}")
    (tmp_path / "d").mkdir()
    os.mkfifo(tmp_path / "pipe")
    os.symlink(tmp_path / "nowhere", tmp_path / "dangling")
    os.symlink(tmp_path / "loop", tmp_path / "loop")
    os.symlink(tmp_path / "f.json", tmp_path / "link")
    assert input_kind(tmp_path / "f.json") is None and input_kind(tmp_path / "link") is None
    assert input_kind(tmp_path / "missing") == "missing"
    assert input_kind(tmp_path / "d") == "a folder"
    assert input_kind(tmp_path / "pipe") == "a named pipe (FIFO), not a file"
    assert input_kind("/dev/null") == "a device, not a file"
    assert input_kind(tmp_path / "dangling") == f"a symbolic link to {tmp_path / 'nowhere'}, which does not exist"
    assert input_kind(tmp_path / "loop").startswith("a symbolic link loop")
    with socket.socket(socket.AF_UNIX) as s:
        s.bind(str(tmp_path / "sock"))
        assert input_kind(tmp_path / "sock") == "a socket, not a file"


def test_check_input_file_is_one_line_per_kind(tmp_path):
    (tmp_path / "ok.json").write_text("{}")
    check_input_file(tmp_path / "ok.json", "--existing ok.json", "a JSON file")
    (tmp_path / "d").mkdir()
    os.mkfifo(tmp_path / "pipe")
    cases = [("missing.json", " (or a scene name)", "--x missing.json: no such file (or a scene name)"),
             ("d", "", "--x d is a folder, not a JSON file"),
             ("pipe", "", "--x pipe is a named pipe (FIFO), not a file: give a JSON file")]
    for name, hint, message in cases:
        with pytest.raises(UserError) as info:
            check_input_file(tmp_path / name, f"--x {name}", "a JSON file", hint)
        assert str(info.value) == message
