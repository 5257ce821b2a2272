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


def _read(tmp_path, text: str, name: str = "c.toml"):
    path = tmp_path / name
    path.write_text(text)
    return read_config_file(path, PlanConfig())


def test_a_methods_settings_are_its_own_table(tmp_path):
    config = _read(tmp_path, '[placement.methods.omp]\nv = 70\n[placement.methods.expected_recall]\n'
                             'calibration_poses = "offgrid"\ncalibration_runs = 5\n')
    methods = config.placement.methods
    assert methods.omp.v == 70.0 and methods.omp.lazy is True
    assert methods.expected_recall.calibration_poses == "offgrid" and methods.expected_recall.calibration_runs == 5
    with pytest.raises(UserError, match=r"unknown setting 'placement.methods.omp.w': known in "
                                        r"\[placement.methods.omp\]: v, lazy"):
        _read(tmp_path, "[placement.methods.omp]\nw = 1\n")
    with pytest.raises(UserError, match=r"calibration_poses = 'test' is not one of map, offgrid"):
        _read(tmp_path, '[placement.methods.expected_recall]\ncalibration_poses = "test"\n')
    with pytest.raises(UserError, match=r"placement.methods.omp.v 150 % is outside \[0, 100\] %"):
        _read(tmp_path, "[placement.methods.omp]\nv = 150\n")


def test_method_settings_of_older_files_move_to_their_method(tmp_path):
    """``[placement] v`` / ``calibration_poses`` (a config.json from before methods had their own
    settings) are read into ``placement.methods``: an older plan folder plans what it planned."""
    for name, text in (("old.toml", '[placement]\nv = 60\nlazy = false\ncalibration_poses = "offgrid"\n'),
                       ("config.json", '{"placement": {"v": 60, "lazy": false, "calibration_poses": "offgrid", '
                                       '"k": 3}}')):
        methods = _read(tmp_path, text, name).placement.methods
        assert (methods.omp.v, methods.omp.lazy, methods.expected_recall.calibration_poses) == (60.0, False, "offgrid")


def test_a_written_config_reads_back_with_its_method_settings(tmp_path):
    import json

    from markerplace.plan.folder import config_from_dict
    from markerplace.runtime.cache import config_dict
    from markerplace.settings import apply

    config = apply(PlanConfig(), {"placement.methods.omp.v": 55.0, "placement.methods.expected_recall.calibration_k": 7})
    doc = config_dict(config)
    assert doc["placement"]["methods"]["omp"] == {"v": 55.0, "lazy": True}
    assert config_from_dict(PlanConfig, json.loads(json.dumps(doc))) == config
    assert _read(tmp_path, json.dumps(doc), "config.json") == config
