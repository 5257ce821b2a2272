"""Helpers shared by the tests (importable as ``helpers`` from every test folder: ``pythonpath``
in pyproject.toml puts ``tests/`` on the path), and the places the tests read from.

The modules: :mod:`helpers.consumers` (the robots' tag-map readers), :mod:`helpers.hostile_meshes`
(the hostile mesh corpus), :mod:`helpers.interrupts` (process-group SIGINT), :mod:`helpers.loopback`
(silent and garbage servers on 127.0.0.1), :mod:`helpers.official_tags` (the official tag36h11
images), :mod:`helpers.printed_tags` (tags.pdf rasterized) and :mod:`helpers.atlas_scenes` (a
scan-like room of several texture atlases).
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
"""The repository root (README.md, docs/, scripts/, benchmarks/, src/)."""

SRC = REPO / "src"
"""The package's source folder (``PYTHONPATH`` of the commands the tests start)."""

TESTS = REPO / "tests"

DATA = TESTS / "data"
"""The tests' data files (``apriltag_imgs``)."""

FAST = ["--grid-spacing", "1.0", "--yaws", "4", "--workers", "1", "--quiet"]
"""Options of a quick ``plan``/``evaluate`` on ``tiny`` in this process: a 1 m lattice, 4 yaws."""

FAST_2_YAWS = ["--grid-spacing", "1.0", "--yaws", "2", "--workers", "1", "--quiet"]
""":data:`FAST` with 2 yaws: quicker still, for tests that look at the outputs, not the scores."""

_TOKEN_SEPARATORS = re.compile(r"""[\s,;:()\[\]{}=<>|"']+""")
_NEGATIVE_ZERO = re.compile(r"-0(\.0+)?(e[+-]?\d+)?(m|%)?")


def negative_zeros(text: str) -> list[str]:
    """The numbers of ``text`` (printed output, CSV, JSON, YAML) that read as a negative zero
    (``-0``, ``-0.0``, ``-0.000 m``, ``-0.0e+00``); not ``-0.057``, and never part of a path or
    name: the text is cut at white space and punctuation, and only whole pieces count, so a
    temporary folder such as ``pytest-of-user/pytest-0/`` (pytest's first run on a machine) is
    no match."""
    return [t for t in _TOKEN_SEPARATORS.split(text) if _NEGATIVE_ZERO.fullmatch(t)]


def undeclared_outputs(folder: Path, patterns) -> list[str]:
    """The files a run wrote into its run folder ``folder`` (its manifest says) that none of
    ``patterns`` declares (``fnmatch`` patterns, ``/`` at the end: everything below that folder;
    see :mod:`markerplace.runtime.claims`): a new output must be declared to be checked before
    any work in an adopted folder."""
    import fnmatch
    import json

    from markerplace.runtime.run_folder import MANIFEST

    written = {json.loads(line)[1] for line in (folder / MANIFEST).read_text().splitlines()}
    return sorted(rel for rel in written if (folder / rel).is_file() and not any(
        fnmatch.fnmatchcase(rel, p) or p.endswith("/") and rel.startswith(p) for p in patterns))
