"""`evaluate` rejects unusable settings up front, with one line and exit code 2."""

import pytest

from markerplace.cli.main import main


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


def test_test_seed_defaults_to_seed_and_overrides_it():
    import argparse

    from markerplace.cli.evaluate_command import add_evaluate_parser, evaluate_config_from_args

    parser = argparse.ArgumentParser()
    add_evaluate_parser(parser.add_subparsers(dest="command"))
    from markerplace.simulation.map_setup import localizer_spec

    base = ["evaluate", "tiny", "--out", "x", "--seed", "7"]
    assert evaluate_config_from_args(parser.parse_args(base)).pose_seed == 7
    config = evaluate_config_from_args(parser.parse_args(base + ["--test-seed", "3"]))
    assert config.pose_seed == 3
    # the localizer (RANSAC) and the VLAD codebook keep --seed
    assert config.seed == 7 and dict(localizer_spec(config.localization, config.seed)[1])["seed"] == 7
