"""Package layout: no import cycle, no module over MAX_LINES lines except the allow-list below,
and every module docs/design.md names for a pipeline stage exists.

Uses ``scripts/check_layout.py`` (static: :mod:`ast` on the sources, nothing is imported).
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys

import pytest

from helpers import REPO

SCRIPT = REPO / "scripts" / "check_layout.py"

MAX_LINES = 420
"""About 400 lines: one job per module."""

ALLOWED_OVER: dict[str, str] = {
    # module: reason. Scene-data catalogues may be long; anything else here is a debt to pay.
}
"""Modules allowed over :data:`MAX_LINES`, each with its reason. An entry that is no longer over
the limit fails the test: remove it."""


def _load():
    spec = importlib.util.spec_from_file_location("check_layout", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def layout():
    return _load()


def test_no_import_cycle_at_module_level(layout):
    graph = layout.import_graph()
    found = layout.cycles(graph)
    assert not found, "import cycles: " + "; ".join(" -> ".join(layout.cycle_path(graph, c)) for c in found)


def test_no_import_cycle_through_imports_inside_functions(layout):
    graph = layout.import_graph(deferred=True)
    found = layout.cycles(graph)
    assert not found, "import cycles (deferred imports): " + "; ".join(
        " -> ".join(layout.cycle_path(graph, c)) for c in found)


def test_no_import_cycle_behind_type_checking(layout):
    """A type annotation is a dependency too: shared types live in a types module (plan/types.py)."""
    graph = layout.import_graph(deferred=True, type_checking=True)
    found = layout.cycles(graph)
    assert not found, "import cycles (TYPE_CHECKING imports counted): " + "; ".join(
        " -> ".join(layout.cycle_path(graph, c)) for c in found)


def test_no_package_level_cycle(layout):
    """At every level of the package tree (top-level packages, the stage packages of plan, ...)
    the imports between siblings form no cycle, every import counted."""
    found = layout.package_cycles(layout.import_graph(deferred=True, type_checking=True))
    assert not found, "package-level cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_the_checker_finds_package_and_type_checking_cycles(tmp_path, layout):
    pkg = tmp_path / "markerplace"
    for sub in ("plan", "report"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "plan" / "stage.py").write_text("from markerplace.report.page import write\n")
    (pkg / "report" / "page.py").write_text("def write():\n    pass\n")
    (pkg / "report" / "types_user.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                                  "    from markerplace.plan.types import PlanData\n")
    (pkg / "plan" / "types.py").write_text("from markerplace.report.types_user import x\n")
    graph = layout.import_graph(pkg, deferred=True, type_checking=True)
    assert layout.cycles(layout.import_graph(pkg, deferred=True)) == []  # no module cycle without TYPE_CHECKING
    assert layout.cycles(graph) == [["markerplace.plan.types", "markerplace.report.types_user"]]
    assert layout.package_cycles(graph) == [["markerplace.plan", "markerplace.report"]]
    (pkg / "report" / "types_user.py").write_text("x = 1\n")
    graph = layout.import_graph(pkg, deferred=True, type_checking=True)
    assert layout.cycles(graph) == [] and layout.package_cycles(graph) == []  # plan -> report only


def test_imports_at_module_level_except_heavy_optional_ones(layout):
    """Every dependency is visible at the top of a module; only the documented heavy optional
    third-party modules (``HEAVY_OPTIONAL``) may be imported inside a function."""
    found = layout.deferred_imports()
    assert not found, "imports inside functions (move them to module level): " + "; ".join(
        f"{m}:{line}: {mod}" for m, line, mod in found[:20])
    assert all(name.split(".")[0] != "markerplace" for name in layout.HEAVY_OPTIONAL)


def test_one_file_name_per_meaning(layout):
    """No two modules share a file name (``check.py`` three times meant three things), except the
    documented ``SHARED_NAMES``, each the same kind of module in every package that has one."""
    found = layout.repeated_names()
    assert not found, "modules sharing a file name (rename one, or document the name in SHARED_NAMES): " + "; ".join(
        f"{name}.py: {', '.join(paths)}" for name, paths in found.items())
    assert all(reason.strip() for reason in layout.SHARED_NAMES.values())


def test_the_checker_finds_a_repeated_module_name(tmp_path, layout):
    pkg = tmp_path / "markerplace"
    for sub in ("plan", "cli"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
        (pkg / sub / "config.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "plan" / "check.py").write_text("")
    assert layout.repeated_names(pkg) == {}  # __init__ and config repeat by design
    (pkg / "cli" / "check.py").write_text("")
    assert layout.repeated_names(pkg) == {"check": ["markerplace/cli/check.py", "markerplace/plan/check.py"]}
    out = subprocess.run([sys.executable, str(SCRIPT), "--root", str(pkg)], capture_output=True, text=True)
    assert out.returncode == 1 and "check.py: markerplace/cli/check.py, markerplace/plan/check.py" in out.stdout


def test_the_planner_imports_nothing_of_the_testbed(layout):
    """``plan/``, ``pipelines/plan.py`` and ``pipelines/plan_frames.py`` (and all they import)
    never reach ``testbed/``: what plan and evaluate share is in ``simulation/``."""
    found = layout.planner_testbed_imports()
    assert not found, "a plan imports the testbed: " + "; ".join(" -> ".join(c) for c in found)


def test_the_checker_finds_a_planner_import_of_the_testbed(tmp_path, layout):
    pkg = tmp_path / "markerplace"
    for sub in ("plan", "pipelines", "simulation", "testbed"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "simulation" / "fit.py").write_text("x = 1\n")
    (pkg / "testbed" / "ceiling.py").write_text("from markerplace.simulation.fit import x\n")
    (pkg / "pipelines" / "evaluate.py").write_text("from markerplace.testbed import ceiling\n")
    (pkg / "pipelines" / "plan.py").write_text("from markerplace.simulation.fit import x\n")
    assert layout.planner_testbed_imports(pkg) == []  # evaluate may use the testbed, a plan the simulation
    (pkg / "simulation" / "fit.py").write_text("def f():\n    from markerplace.testbed.ceiling import y\n")
    found = layout.planner_testbed_imports(pkg)  # (the testbed's __init__ runs too: reached as well)
    assert ["markerplace.pipelines.plan", "markerplace.simulation.fit", "markerplace.testbed.ceiling"] in found
    out = subprocess.run([sys.executable, str(SCRIPT), "--root", str(pkg)], capture_output=True, text=True)
    assert out.returncode == 1
    assert "markerplace.pipelines.plan -> markerplace.simulation.fit -> markerplace.testbed.ceiling" in out.stdout
    (pkg / "simulation" / "fit.py").write_text("x = 1\n")
    (pkg / "plan" / "stage.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                           "    from markerplace.testbed import ceiling\n")
    assert ["markerplace.plan.stage", "markerplace.testbed.ceiling"] in layout.planner_testbed_imports(pkg)


def _documented_untested() -> dict[str, str]:
    text = (REPO / "docs" / "contributing.md").read_text(encoding="utf-8")
    section = text.split("### Modules no unit test imports", 1)[1].split("\n#", 1)[0]
    rows = [line.split("|") for line in section.splitlines() if line.startswith("| `")]
    return {row[1].strip().strip("`"): row[2].strip() for row in rows}


def test_every_module_is_imported_by_a_test_or_listed_with_its_reason(layout):
    listed = _documented_untested()
    found = set(layout.untested_modules())
    assert listed and all(listed.values())
    missing = sorted(found - set(listed))
    assert not missing, ("modules no test file imports: add a unit test, or list each with its reason in "
                         f"docs/contributing.md (Modules no unit test imports): {missing}")
    stale = sorted(set(listed) - found)
    assert not stale, f"listed in docs/contributing.md as imported by no test, but a test imports them (or gone): {stale}"


def test_the_checker_finds_a_module_no_test_imports(tmp_path, layout):
    pkg, tests = tmp_path / "markerplace", tmp_path / "tests"
    (pkg / "sub").mkdir(parents=True)
    tests.mkdir()
    for name in ("__init__.py", "a.py", "b.py", "c.py", "sub/__init__.py", "sub/d.py"):
        (pkg / name).write_text("")
    (tests / "test_x.py").write_text("import markerplace.a\nfrom markerplace.sub import d\n"
                                     "TARGET = 'markerplace.c'\n")
    (tests / "helper.py").write_text("from markerplace import b\n")  # not a test file
    assert layout.untested_modules(pkg, tests) == ["b.py"]


def test_no_module_over_the_limit(layout):
    sizes = layout.line_counts()
    over = {m: n for m, n in sizes.items() if n > MAX_LINES and m not in ALLOWED_OVER}
    assert not over, f"modules over {MAX_LINES} lines (split them, or allow-list a data catalogue with a reason): {over}"
    stale = [m for m in ALLOWED_OVER if sizes.get(m, 0) <= MAX_LINES]
    assert not stale, f"allow-listed modules now within {MAX_LINES} lines (or gone): remove them from ALLOWED_OVER: {stale}"
    assert all(reason.strip() for reason in ALLOWED_OVER.values())


def test_every_module_of_the_pipeline_table_exists():
    """docs/design.md names each stage's module(s) and artifact; those modules must be in the tree."""
    text = (REPO / "docs" / "design.md").read_text(encoding="utf-8")
    section = text.split("## 1. Pipeline", 1)[1].split("\n## ", 1)[0]
    rows = [line.split("|") for line in section.splitlines() if line.startswith("|") and "`" in line]
    assert rows, "no stage table in docs/design.md, section 1"
    named = [tok for row in rows for tok in row[2].split("`")[1::2]]
    assert named
    missing = [tok for tok in named if not (REPO / "src" / "markerplace" / tok).exists()]
    assert not missing, f"docs/design.md's pipeline table names modules that are not in src/markerplace: {missing}"


def test_the_checker_finds_a_cycle_and_a_big_module(tmp_path, layout):
    pkg = tmp_path / "markerplace"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .sub import b\n")
    (pkg / "sub" / "b.py").write_text("from .. import c\n")
    (pkg / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import d\n"
                              "def f():\n    from .a import x\n" + "\n" * 500)
    (pkg / "d.py").write_text("from .c import f\n")
    assert layout.cycles(layout.import_graph(pkg)) == []
    assert layout.cycles(layout.import_graph(pkg, deferred=True)) == [
        ["markerplace.a", "markerplace.c", "markerplace.sub.b"]]
    assert layout.line_counts(pkg)["markerplace.c"] > 500
    out = subprocess.run([sys.executable, str(SCRIPT), "--root", str(pkg)], capture_output=True, text=True)
    assert out.returncode == 1, out.stderr  # a cycle through a deferred import is a cycle too
    assert "markerplace/c.py" in out.stdout and "cycles through imports inside functions: 1" in out.stdout
    assert "imports inside functions (other than" in out.stdout and "markerplace.c:5: .a" in out.stdout
    (pkg / "d.py").write_text("from .a import y\n")
    (pkg / "a.py").write_text("from .d import z\n")
    out = subprocess.run([sys.executable, str(SCRIPT), "--root", str(pkg)], capture_output=True, text=True)
    assert out.returncode == 1 and "markerplace.a -> markerplace.d -> markerplace.a" in out.stdout
