"""The README's command-line examples parse and pass the checks that come before their output.

Each ``markerplace ...`` line of the README's "Command line" block runs with its outputs moved
under a file (so no folder can be made there): the run must stop with the one-line error of
that output (the first check that touches the disk) or of an input the example names and this
checkout lacks (``my_tags.json``, ``frames/``, a plan folder). Any other error, e.g. an option
default that its own validation rejects, fails the test: ``markerplace study office --out
out/study`` once stopped at ``-k '5,10,15,20' is not a number``. What is checked after the
output (the scene's storeys for ``--level``, a ``--pose`` inside the model) is not reached here;
the scene names are checked against the built-in scenes.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

from helpers import REPO
from markerplace.cli.main import main
from markerplace.scene.builtin.catalogue import builtin_names

README = REPO / "README.md"
FILE_SUFFIXES = (".json", ".ply", ".obj", ".glb", ".gltf", ".toml")
SCENE_COMMANDS = ("render", "plan", "evaluate", "study")


def readme_examples() -> list[list[str]]:
    """Argument lists of the ``markerplace`` lines in the README's "Command line" code block."""
    section = README.read_text().split("## Command line", 1)[1]
    block = re.search(r"```bash\n(.*?)```", section, re.S).group(1)
    lines = [line.split("#", 1)[0].strip() for line in block.splitlines()]
    return [shlex.split(line)[1:] for line in lines if line.startswith("markerplace ")]


def redirect_outputs(args: list[str], blocker: Path) -> list[str]:
    """``args`` with every output (``--out``, ``--gltf``, ``scene export``'s OUT) moved under the
    file ``blocker``, keeping the file name (a ``.ply`` stays a ``.ply``)."""
    args = list(args)
    for i, arg in enumerate(args):
        if arg in ("--out", "--gltf") and i + 1 < len(args):
            args[i + 1] = str(blocker / Path(args[i + 1]).name)
    if args[:2] == ["scene", "export"]:
        args[3] = str(blocker / Path(args[3]).name)
    return args


def missing_inputs(args: list[str], blocker: Path) -> list[str]:
    """The input paths of redirected ``args`` (a mesh or marker file, or a path with a slash)
    that do not exist here, as written and without a trailing slash."""
    paths = [a for a in args if not a.startswith("-") and "://" not in a and not a.startswith(str(blocker))
             and (a.lower().endswith(FILE_SUFFIXES) or "/" in a)]
    missing = [a for a in paths if not Path(a).exists()]
    return missing + [a.rstrip("/") for a in missing]


EXAMPLES = [args for args in readme_examples() if args[:2] != ["scene", "list"]]
IDS = [f"{i:02d} {' '.join(a[:2])}" for i, a in enumerate(EXAMPLES)]


def test_readme_lists_the_subcommands_and_builtin_scenes():
    examples = readme_examples()
    assert {"scene", "render", "plan", "fuse", "export", "check", "evaluate", "study"} <= {a[0] for a in examples}
    for args in examples:
        if args[0] in SCENE_COMMANDS and not args[1].startswith("-") and not args[1].lower().endswith(FILE_SUFFIXES):
            assert args[1] in builtin_names(), args


@pytest.mark.parametrize("args", EXAMPLES, ids=IDS)
def test_readme_example_stops_only_at_its_output_or_a_missing_input(args, tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("no folder can be made under a file")
    run = redirect_outputs(args, blocker)
    assert main(run) == 2, run
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:"), err
    at_output = str(blocker) in err[0] and "is a file" in err[0]
    assert at_output or any(name in err[0] for name in missing_inputs(run, blocker)), (run, err[0])
