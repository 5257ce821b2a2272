"""``plan --config FILE`` (:mod:`markerplace.config_file`): a folder or a named pipe named like a
TOML file is named for what it is (not "no such file"), and reading it never blocks."""

from __future__ import annotations

import os

import pytest

from markerplace.config_file import read_config_file
from markerplace.errors import UserError
from markerplace.plan.config import PlanConfig


@pytest.mark.parametrize("kind, said", [("folder", "is a folder"), ("fifo", "is a named pipe (FIFO)"),
                                        ("missing", "no such file")])
def test_a_config_path_that_is_no_file_is_named_for_what_it_is(kind, said, tmp_path):
    path = tmp_path / "settings.toml"
    if kind == "folder":
        path.mkdir()
    elif kind == "fifo":
        os.mkfifo(path)
    with pytest.raises(UserError, match=r"^--config .*settings\.toml") as err:
        read_config_file(path, PlanConfig())
    assert said in str(err.value) and "give a TOML file" in str(err.value)
