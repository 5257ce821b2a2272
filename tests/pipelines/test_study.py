"""`markerplace study`: the parameter and sensitivity study of one scene, end to end on tiny."""

from __future__ import annotations

import csv

from helpers import undeclared_outputs
from markerplace.cli.main import main
from markerplace.pipelines.study import study_outputs

SMALL = ["--grid-spacing", "1.0", "--yaws", "4", "--workers", "1", "--quiet"]


def test_study_tiny_writes_every_group_with_paired_differences(tmp_path, capsys):
    out = tmp_path / "study"
    args = ["study", "tiny", "--out", str(out), "--tests", "10", "--k", "2", "--vs", "50", "--shifts", "0.25",
            "--scales", "0.5", *SMALL]
    assert main(args) == 0
    md = (out / "study.md").read_text()
    for heading in ("## v", "## detection", "## test data", "## similarity", "## shift", "## size"):
        assert heading in md, heading
    for row in ("v = 50", "tag detection off", "uniform test data", "similarity analysis off", "shifted +-0.25 m",
                "printed x0.5"):
        assert f"| {row} |" in md, row
    assert md.count("| (minus default) |") == 5  # every paired row; uniform test data has other images
    rows = list(csv.DictReader((out / "study.csv").open()))
    assert {r["group"] for r in rows} == {"v", "detection", "test data", "similarity", "shift", "size"}
    assert all(0.0 <= float(r["recall"]) <= 1.0 and r["n_tests"] == "10" for r in rows)
    for group in ("v", "detection", "test_data", "similarity", "shift", "size"):
        assert (out / f"study_{group}.png").stat().st_size > 0
    # one work folder: the plan and the marker-free images are computed once for every run
    assert (out / "work" / "plan" / "observations").is_dir() and not (out / "runs" / "default" / "plan").exists()
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["default", "no-detection", "shift-0.25", "size-0.5"]
    assert "# Parameter and sensitivity study" in capsys.readouterr().out
    outputs = study_outputs(["default", "no-detection", "shift-0.25", "size-0.5"])
    assert undeclared_outputs(out, outputs) == []  # what --adopt checks before any work


def test_default_budgets_of_study_and_evaluate_build_a_valid_plan_config(tmp_path):
    """`--k` of study/evaluate is a list that shares plan's `k`: the default list must plan
    max(ks) markers (the README's `markerplace study office --out out/study` once failed here)."""
    from markerplace.cli.bounds import field_bound
    from markerplace.cli.evaluate_command import evaluate_config_from_args
    from markerplace.cli.main import build_parser
    from markerplace.cli.options import plan_config_for_budgets
    from markerplace.plan.config import validate
    from markerplace.validation import parse_int_list

    for command in ("study", "evaluate"):
        args = build_parser().parse_args([command, "tiny", "--out", str(tmp_path / command)])
        # (evaluate's --k has no argparse default, so that --plan knows whether it was given; the
        # field's default applies)
        ks = parse_int_list(args.k, "--k", field_bound("evaluate", "study.ks")) if command == "study" else evaluate_config_from_args(args).study.ks
        assert ks == (5, 10, 15, 20)
        config = plan_config_for_budgets(args, ks)
        validate(config)
        assert config.placement.k == 20 and args.k == ("5,10,15,20" if command == "study" else None)  # args left alone


def test_study_with_default_budgets_gets_past_its_settings(tmp_path, capsys):
    """The default `--k` list passes the settings checks: the run stops only at the unwritable
    `--out`, the next check (not at `-k '5,10,15,20' is not a number`)."""
    blocker = tmp_path / "a_file"
    blocker.write_text("x")
    assert main(["study", "tiny", "--out", str(blocker / "study")]) == 2
    err = capsys.readouterr().err
    assert "is a file" in err and "not a number" not in err and "5,10,15,20" not in err  # not "-k" not in err: a printed path may hold "-k" (pytest-of-kate)


def test_study_runs_leave_the_diagnostics_out_and_are_checked_first():
    """A caller's `--ceiling`/`--calibration` must not reach the shifted or rescaled runs (the
    ceiling refuses them: the study stopped after its first, longest evaluation); every run's
    settings are checked before anything runs."""
    import pytest

    from markerplace.errors import UserError
    from markerplace.pipelines.study import StudyPlan, study_runs
    from markerplace.testbed.config import DiagnosticsConfig, EvaluateConfig

    config = EvaluateConfig(diagnostics=DiagnosticsConfig(ceiling=True, calibration=True))
    runs = study_runs(config, StudyPlan(shifts=(0.25,), scales=(0.5,)))
    assert list(runs) == ["default", "no-detection", "shift-0.25", "size-0.5"]
    assert all(cfg.diagnostics == DiagnosticsConfig() for cfg in runs.values())
    assert runs["shift-0.25"].study.shift == 0.25 and runs["size-0.5"].study.tag_scale == 0.5
    assert runs["default"].test.sets == ("weighted", "uniform") and runs["no-detection"].localization.use_tags is False
    with pytest.raises(UserError, match="shift"):
        study_runs(config, StudyPlan(shifts=(-1.0,)))
