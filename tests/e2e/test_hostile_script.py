"""``scripts/hostile_inputs.py`` (the new-user probe, about 8 minutes, not in the default run) still
builds its hostile inputs and its cases: the cheap part of it, so that a moved test helper or a
renamed option breaks the suite instead of the probe."""

import importlib.util
import sys

from helpers import REPO


def _script():
    spec = importlib.util.spec_from_file_location("hostile_inputs", REPO / "scripts" / "hostile_inputs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_the_probe_builds_its_inputs_and_cases(tmp_path):
    probe = _script()
    files = probe.make_fixtures(tmp_path)
    assert files["latin1_mtl"].exists() and files["gltf_missing"].exists()
    files["silent"] = files["garbage"] = "tcp://127.0.0.1:9"  # the servers main() starts
    cases = probe.cases(tmp_path, files)
    assert len(cases) > 50
    every = [*cases, *probe.checked_input_cases(tmp_path, files), *probe.interrupt_cases(tmp_path, files),
             *probe.folder_cases(tmp_path, files), *probe.issue50_cases(tmp_path, files)]
    assert len({c.name for c in every}) == len(every)  # --only picks cases by name
    assert len(probe.issue50_cases(tmp_path, files)) > 30
    assert files["zeros.ply"].stat().st_size == 2 << 30 and files["claims"].exists()
