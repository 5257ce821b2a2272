"""`evaluate` rejects unusable settings up front, with one line and exit code 2."""

import pytest

from markerplace.cli import main


@pytest.mark.parametrize("args, message", [
    (["--methods", ","], "--methods is empty"),
    (["--methods", "omp,best"], "--methods"),
    (["--yaws", "0"], "--yaws"),
    (["--tests", "0"], "--tests"),
])
def test_evaluate_bad_settings(args, message, tmp_path, capsys):
    assert main(["evaluate", "tiny", "--out", str(tmp_path / "e"), "--quiet", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:") and message in err[0], err
