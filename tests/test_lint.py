"""The tree passes ruff (``[tool.ruff]`` in pyproject.toml: pycodestyle, pyflakes, import order,
bugbear) over the sources, tests, benchmarks and scripts, and ruff finds what it is there for."""

from __future__ import annotations

import subprocess
import sys

from helpers import REPO

PATHS = ("src", "tests", "benchmarks", "scripts")


def _ruff(*args: str, cwd=REPO) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


def test_the_tree_is_ruff_clean():
    res = _ruff(*PATHS)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]


def test_ruff_finds_an_unsorted_import_and_an_unused_one(tmp_path):
    bad = tmp_path / "src" / "bad.py"
    bad.parent.mkdir()
    bad.write_text("from markerplace.errors import UserError\nimport os\n")
    res = _ruff("--config", str(REPO / "pyproject.toml"), str(bad), cwd=tmp_path)
    assert res.returncode == 1
    assert "I001" in res.stdout and "F401" in res.stdout, res.stdout
