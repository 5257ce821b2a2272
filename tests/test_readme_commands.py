"""The README's command-line examples pass their settings checks as written.

Each ``markerplace ...`` line of the README's "Command line" block runs with its output moved
to an unwritable folder: the run must stop with the one-line error of that folder (the first
check that touches the disk) or of an input file the example names and this checkout lacks
(``my_tags.json``, ``frames/``, ...). Anything else, e.g. an option default that its own
validation rejects, fails the test: ``markerplace study office --out out/study`` once stopped at
``-k '5,10,15,20' is not a number``.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from markerplace.cli.main import main

README = Path(__file__).resolve().parents[1] / "README.md"
UNWRITABLE = "/proc/markerplace-readme"


def readme_examples() -> list[list[str]]:
    """Argument lists of the ``markerplace`` lines in the README's "Command line" code block."""
    text = README.read_text()
    section = text.split("## Command line", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    lines = [line.split("#", 1)[0].strip() for line in block.splitlines()]
    return [shlex.split(line)[1:] for line in lines if line.startswith("markerplace ")]


def redirect_outputs(args: list[str]) -> list[str]:
    """``args`` with every output (``--out``, ``--gltf``, ``scene export``'s OUT) moved under
    :data:`UNWRITABLE`, keeping the file name (a ``.ply`` stays a ``.ply``)."""
    args = list(args)
    for i, arg in enumerate(args):
        if arg in ("--out", "--gltf") and i + 1 < len(args):
            args[i + 1] = f"{UNWRITABLE}/{Path(args[i + 1]).name}"
    if args[:2] == ["scene", "export"]:
        args[3] = f"{UNWRITABLE}/{Path(args[3]).name}"
    return args


FILE_SUFFIXES = (".json", ".ply", ".obj", ".glb", ".gltf")


def missing_inputs(args: list[str]) -> list[str]:
    """The example's input paths (a mesh or marker file, or a folder path with a slash) that do
    not exist in this checkout, as written and without a trailing slash."""
    paths = [a for a in args if not a.startswith("-") and "://" not in a and not a.startswith(UNWRITABLE)
             and (a.lower().endswith(FILE_SUFFIXES) or "/" in a)]
    missing = [a for a in paths if not Path(a).exists()]
    return missing + [a.rstrip("/") for a in missing]


EXAMPLES = [args for args in readme_examples() if args[:2] != ["scene", "list"]]


def test_readme_lists_the_subcommands():
    names = {args[0] for args in readme_examples()}
    assert {"scene", "render", "plan", "fuse", "export", "check", "evaluate", "study"} <= names


@pytest.mark.parametrize("args", EXAMPLES, ids=[" ".join(a[:2]) for a in EXAMPLES])
def test_readme_example_stops_only_at_its_output_or_a_missing_input(args, capsys):
    run = redirect_outputs(args)
    assert main(run) == 2, run
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:"), err
    at_output = "cannot write there" in err[0] and "/proc" in err[0]
    assert at_output or any(name in err[0] for name in missing_inputs(args)), (run, err[0])
