"""``scripts/hostile_inputs.py`` (the new-user probe, about 18 minutes, not in the default run) still
builds its hostile inputs and its cases: the cheap part of it, so that a moved test helper or a
renamed option breaks the suite instead of the probe. One case of each kind of its ``probe`` group
(:data:`CHEAP_PROBE`: run folders, ``--out`` paths, TOML, stdout) runs here too, judged as the
script judges it."""

import importlib.util
import sys
import time

import pytest

from helpers import REPO


def _script():
    spec = importlib.util.spec_from_file_location("hostile_inputs", REPO / "scripts" / "hostile_inputs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def probe(tmp_path_factory):
    """The script, its work folder (fixtures made, ``out/`` ready) and its fixtures."""
    module, w = _script(), tmp_path_factory.mktemp("hostile")
    (w / "out").mkdir()
    files = module.make_fixtures(w)
    files["silent"] = files["garbage"] = "tcp://127.0.0.1:9"  # the servers main() starts
    return module, w, files


def test_the_probe_builds_its_inputs_and_cases(probe):
    probe, w, files = probe
    assert files["latin1_mtl"].exists() and files["gltf_missing"].exists()
    cases = probe.cases(w, files)
    assert len(cases) > 50
    every = [c for group in probe.GROUPS.values() for c in group(w, files)]
    assert len({c.name for c in every}) == len(every)  # --only picks cases by name
    assert len(probe.issue50_cases(w, files)) > 30 and len(probe.probe_cases(w, files)) > 90
    assert files["zeros.ply"].stat().st_size == 2 << 30 and files["claims"].exists()


def test_one_probe_case_of_each_kind_ends_as_the_script_expects(probe, capsys, monkeypatch):
    """The cheap representatives run in this process (``main(argv)``), the stdout ones as a
    subprocess; each judged by the script's own ``judge`` (one line and exit 2, or exit 0)."""
    from markerplace.cli.main import main

    probe, w, files = probe
    monkeypatch.chdir(w)  # the script runs its cases there (relative paths)
    cases = {c.name: c for c in probe.probe_cases(w, files)}
    problems = {}
    for name in probe.CHEAP_PROBE:
        case = cases[name]
        if case.extra.get("run"):
            row = probe.run_case(case, w)
            problems[name] = row[4] or None
            continue
        if case.setup:
            case.setup()
        capsys.readouterr()
        t0 = time.perf_counter()
        code = main(case.argv)
        err = capsys.readouterr().err
        problems[name] = probe.judge(case, code, err, time.perf_counter() - t0)
    assert {k: v for k, v in problems.items() if v} == {}
