"""``--method-conf [METHOD.]KEY=VALUE``: a placement method's own settings on the command line
(:func:`markerplace.cli.options.method_conf_values`)."""

from __future__ import annotations

import pytest

from markerplace.cli.main import build_parser, plan_config_from_args
from markerplace.cli.options import method_conf_values
from markerplace.errors import UserError
from markerplace.plan.config import PlanConfig


def _plan(*argv):
    return plan_config_from_args(build_parser().parse_args(["plan", "tiny", "--out", "unused", *argv]))


def test_method_conf_writes_into_the_methods_config():
    config = _plan("--method", "expected-recall", "--method-conf", "calibration_runs=5",
                   "--method-conf", "omp.lazy=false", "--method-conf", "calibration_poses=offgrid")
    er = config.placement.methods.expected_recall
    assert (er.calibration_runs, er.calibration_poses) == (5, "offgrid")
    assert config.placement.methods.omp.lazy is False
    assert _plan("-v", "70").placement.methods.omp == _plan("--method-conf", "v=70").placement.methods.omp
    assert _plan("-v", "70", "--method-conf", "v=20").placement.methods.omp.v == 20.0  # the later one wins


@pytest.mark.parametrize("item, command, message", [
    ("w=1", "plan", "--method-conf 'w=1': omp has no setting 'w': its settings are v, lazy"),
    ("random.seed=1", "plan", "random has no setting 'seed': it has no settings of its own"),
    ("v", "plan", "--method-conf 'v': give KEY=VALUE"),
    ("greedy.v=1", "plan", "--method 'greedy' is not known: use one of omp, random"),
    ("v=high", "plan", "--method-conf: placement.methods.omp.v = 'high' must be a finite number (default 90.0)"),
    ("v=150", "plan", "--method-conf: placement.methods.omp.v 150 % is outside [0, 100] %"),
    ("expected-recall.calibration_poses=test", "plan", "calibration_poses = 'test' is not one of map, offgrid"),
    ("v=80", "evaluate", "name the method (METHOD.KEY=VALUE, e.g. omp.v=80): evaluate has no single --method"),
])
def test_a_bad_method_conf_is_one_line_naming_what_to_give(item, command, message):
    with pytest.raises(UserError) as err:
        method_conf_values([item], PlanConfig(), command)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_a_bad_method_conf_exits_2_with_one_line(capsys, tmp_path):
    from markerplace.cli.main import main

    assert main(["plan", "tiny", "--method-conf", "vv=1", "--out", str(tmp_path / "p")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["markerplace: error: --method-conf 'vv=1': omp has no setting 'vv': its settings are v, lazy"]
