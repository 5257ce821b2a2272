"""One home per setting: flags, bounds, help and docs come from the config fields; ``plan
--config`` reads TOML and a plan's config.json (markerplace.settings, markerplace.config_file)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from markerplace.cli.main import build_parser, main
from markerplace.cli.options import plan_config_from_args
from markerplace.cli.run_options import RUN_OPTIONS
from markerplace.pipelines.study import StudyPlan
from markerplace.plan.config import PlanConfig
from markerplace.settings import NO_FLAG, NO_FLAG_SECTIONS, flagged, walk
from markerplace.testbed.config import EvaluateConfig

ROOT = Path(__file__).resolve().parents[1]


def _subparser(command: str) -> argparse.ArgumentParser:
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return action.choices[command]


def _configs(command: str) -> dict[str, object]:
    """prefix -> root config of a command (evaluate's own settings under ``evaluate.``, the
    study's under ``study_plan.``)."""
    return {"": PlanConfig(), **({"evaluate.": EvaluateConfig()} if command in ("evaluate", "study") else {}),
            **({"study_plan.": StudyPlan()} if command == "study" else {})}


@pytest.mark.parametrize("command", ["plan", "evaluate", "study"])
def test_every_flag_has_a_field_and_every_field_a_flag(command):
    flags = {a.option_strings[0] if a.option_strings else a.dest for a in _subparser(command)._actions
             if not isinstance(a, argparse._HelpAction)}
    field_flags = {leaf.setting.flag for config in _configs(command).values() for leaf in flagged(config, command)}
    assert not field_flags - flags, f"config fields whose flag is missing from {command}: {field_flags - flags}"
    orphans = flags - field_flags - set(RUN_OPTIONS[command])
    assert not orphans, (f"{command} options that are neither a config field's (markerplace.settings.setting) nor a "
                         f"run option (markerplace.cli.run_options.RUN_OPTIONS): {sorted(orphans)}")
    assert not set(RUN_OPTIONS[command]) & field_flags, "a run option that is a config field's too"
    without = []
    for prefix, config in _configs(command).items():
        for leaf in walk(config, prefix):
            s = leaf.setting
            if s.flag and (s.commands is None or command in s.commands):
                continue
            path = leaf.path
            if path in NO_FLAG or f"{path}@{command}" in NO_FLAG or any(path.startswith(p) for p in NO_FLAG_SECTIONS):
                continue
            without.append(path)
    assert not without, f"config fields without a flag in {command} and not listed in settings.NO_FLAG: {without}"


def test_study_options_come_from_fields(capsys):
    """study's own options (StudyPlan) and the evaluation settings it shares (--k, --test-seed)
    are generated; its --tests keeps the study's own default (300), evaluate's stays 200."""
    args = build_parser().parse_args(["study", "tiny", "--out", "unused", "--vs", "80", "--k", "2,3"])
    from markerplace.settings import apply, values_from_args

    plan = apply(StudyPlan(), values_from_args(args, StudyPlan(), "study"))
    assert plan.vs == (80.0,) and plan.tests == 300 and plan.shifts == (0.1, 0.25, 0.5)
    assert values_from_args(args, EvaluateConfig(), "study") == {"study.ks": (2, 3)}
    assert build_parser().parse_args(["evaluate", "tiny", "--out", "unused"]).tests == 200
    assert main(["study", "tiny", "--out", "unused", "--vs", "120"]) == 2
    assert "--vs" in capsys.readouterr().err


def test_no_flag_lists_only_real_fields():
    paths = {leaf.path for leaf in walk(PlanConfig())} | {leaf.path for leaf in walk(EvaluateConfig(), "evaluate.")}
    for entry in NO_FLAG:
        assert entry.split("@")[0] in paths, entry


def test_docs_option_tables_are_up_to_date():
    from markerplace.cli.option_docs import rewrite

    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    assert rewrite(text) == text, "docs/cli.md's option tables are out of date: run python scripts/cli_docs.py"


def test_help_shows_the_field_default(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["plan", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "camera grid spacing, metres (the paper used 0.5-0.7) (default 0.5)" in out
    assert "--config FILE" in out


def _plan(args: list[str]):
    return plan_config_from_args(build_parser().parse_args(["plan", "tiny", "--out", "unused", *args]))


def test_toml_sets_nested_fields_and_flags_override(tmp_path):
    f = tmp_path / "site.toml"
    f.write_text('[discretize]\ngrid_spacing = 1\nlevel = "all"\nstart = [1, 2]\n'
                 '[discretize.candidates]\nmarker_spacing = 1.5\nallow = ["doors"]\nopen_front = 0.5\n'
                 '[placement]\nk = 7\ntag_size = 0.3\n[noise]\npixel_sigma = 2.0\n')
    config = _plan(["--config", str(f), "-k", "3", "--grid-spacing", "0.7"])
    d, c, p = config.discretize, config.discretize.candidates, config.placement
    assert (d.grid_spacing, d.level, d.start) == (0.7, None, (1.0, 2.0))  # the flag wins
    assert (c.marker_spacing, c.allow, c.open_front) == (1.5, ("doors",), 0.5)
    assert (p.k, p.tag_size, config.noise.pixel_sigma) == (3, 0.3, 2.0)
    assert isinstance(_plan(["--config", str(f)]).discretize.grid_spacing, float)  # 1 -> 1.0: same cache key
    # a file that sets only defaults gives the default config (and its cache keys)
    g = tmp_path / "defaults.toml"
    g.write_text("[discretize]\ngrid_spacing = 0.5\n[placement]\nk = 20\n")
    assert _plan(["--config", str(g)]) == PlanConfig()


@pytest.mark.parametrize("text, needle", [
    ("[discretize]\ngrid_spacin = 0.5\n", "unknown setting 'discretize.grid_spacin': did you mean discretize.grid_spacing?"),
    ("[placment]\nk = 3\n", "unknown setting 'placment': did you mean placement?"),
    ("[discretize]\ngrid_spacing = 0.01\n", "discretize.grid_spacing 0.01 m is outside [0.05, 50] m"),
    ("[discretize]\ngrid_spacing = \"wide\"\n", "discretize.grid_spacing = 'wide' must be a finite number"),
    ("[placement]\nk = 2.5\n", "placement.k = 2.5 must be a whole number"),
    ("[placement]\nmethod = \"best\"\n", "placement.method = 'best' is not one of omp"),
    ("[discretize.candidates]\nallow = [\"roofs\"]\n", "discretize.candidates.allow: --allow 'roofs': unknown 'roofs'"),
    ("discretize = 3\n", "discretize is a table of settings"),
    ("[discretize\n", "is not valid TOML"),
    ("a = " + "[" * 3000 + "]" * 3000 + "\n", "nests arrays/tables too deeply"),  # issue 50: RecursionError
    ("a = " + "{b = " * 3000 + "1" + "}" * 3000 + "\n", "nests arrays/tables too deeply"),
    ("[placement]\nk = " + "[" * 40 + "1" + "]" * 40 + "\n", "more than 32 deep"),
])
def test_config_file_errors_are_one_line(tmp_path, capsys, text, needle):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    assert main(["plan", "tiny", "--config", str(f), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"markerplace: error: --config {f}") and needle in err and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


def test_missing_or_unknown_kind_of_file(tmp_path, capsys):
    for name in ("nothere.toml", "settings.yaml"):
        assert main(["plan", "tiny", "--config", str(tmp_path / name), "--out", str(tmp_path / "out")]) == 2
        assert capsys.readouterr().err.count("\n") == 1


def test_old_flat_config_json_is_read(tmp_path):
    from markerplace.runtime.cache import config_dict

    old = config_dict(PlanConfig())
    cand = old["discretize"].pop("candidates")
    old["discretize"].update(marker_spacing=2.0, allow=["doors"], tag_size=0.4,
                             **{k: cand[k] for k in ("normal_diff_deg", "tag_border", "flatness_tol", "max_normal_z",
                                                     "scan_rays", "max_scan_range")})
    f = tmp_path / "config.json"
    f.write_text(json.dumps({"scene": "tiny", **old, "scene_options": {}, "existing_markers": [], "exclude": None}))
    c = _plan(["--config", str(f)]).discretize.candidates
    assert (c.marker_spacing, c.allow) == (2.0, ("doors",))


def test_plan_config_json_reproduces_the_plan(tmp_path, capsys):
    """``plan --config A/config.json`` plans byte for byte what A planned (non-default settings
    given as flags to A come back from its config.json)."""
    a, b = tmp_path / "A", tmp_path / "B"
    assert main(["--quiet", "plan", "tiny", "-k", "2", "--grid-spacing", "1.0", "--yaws", "4",
                 "--marker-spacing", "1.5", "--out", str(a)]) == 0
    assert main(["--quiet", "plan", "tiny", "--config", str(a / "config.json"), "--out", str(b)]) == 0
    assert (a / "placement.json").read_bytes() == (b / "placement.json").read_bytes()
    assert json.loads((a / "config.json").read_text()) == json.loads((b / "config.json").read_text())
    keys = [json.loads((d / "discretization.npz.meta.json").read_text())["key"] for d in (a, b)]
    assert keys[0] == keys[1]
