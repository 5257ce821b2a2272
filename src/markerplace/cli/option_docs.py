"""The option tables of ``docs/cli.md``, generated from the parser and the config fields.

Each table sits between ``<!-- options:COMMAND -->`` and ``<!-- /options:COMMAND -->`` in
docs/cli.md; ``scripts/cli_docs.py`` rewrites them (:func:`rewrite`), and
``tests/test_settings.py`` fails when the file is out of date. An option of a config field takes
its default and text from the field (:mod:`markerplace.settings`); a run option
(:data:`~markerplace.cli.run_options.RUN_OPTIONS`) its docs text from there or its ``--help``.
``evaluate``'s and ``study``'s tables list only the options ``plan`` does not have.
"""

from __future__ import annotations

import argparse
import re

from markerplace.cli.main import build_parser
from markerplace.cli.run_options import RUN_OPTIONS
from markerplace.pipelines.study import StudyPlan
from markerplace.plan.config import PlanConfig
from markerplace.settings import flagged, shown_default
from markerplace.testbed.config import EvaluateConfig

__all__ = ["option_table", "rewrite", "COMMANDS"]

COMMANDS = ("plan", "evaluate", "study")


def _subparser(parser: argparse.ArgumentParser, command: str) -> argparse.ArgumentParser:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action.choices[command]
    raise KeyError(command)


def _configs(command: str) -> list:
    if command == "evaluate":
        return [EvaluateConfig(), PlanConfig()]
    if command == "study":
        return [StudyPlan(), EvaluateConfig(), PlanConfig()]
    return [PlanConfig()]


def _rows(command: str) -> list[tuple[str, str, str]]:
    """(option, default, meaning) of every option of ``command`` in parser order."""
    leaves = {leaf.setting.flag: leaf for config in _configs(command) for leaf in flagged(config, command)}
    rows = []
    for action in _subparser(build_parser(), command)._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        flag = action.option_strings[0] if action.option_strings else action.dest
        if flag in leaves:
            leaf = leaves[flag]
            meaning, default = leaf.setting.doc_text(), shown_default(leaf)
            metavar = leaf.setting.metavar
        else:
            default, meaning = RUN_OPTIONS.get(command, {}).get(flag) or (None, None)
            meaning = meaning or re.sub(r"\s*\(default[^()]*\)\s*$", "", (action.help or "").replace("%%", "%"))
            if default is None:
                default = "off" if isinstance(action, argparse._StoreTrueAction) else \
                    "required" if action.required else "none" if action.default is None else str(action.default)
            metavar = action.metavar if isinstance(action.metavar, str) else None
        shown = f"{flag} {metavar}" if metavar and action.option_strings else flag
        rows.append((f"`{shown}`".replace("|", "\\|"), default.replace("|", "\\|"), meaning.replace("|", "\\|")))
    return rows


def option_table(command: str) -> str:
    """The markdown table of ``command``'s options."""
    rows = _rows(command)
    if command in ("evaluate", "study"):
        plan = set(_rows("plan"))
        rows = [r for r in rows if r not in plan]
    lines = ["| option | default | meaning |", "|---|---|---|"]
    lines += [f"| {o} | {d} | {m} |" for o, d, m in rows]
    return "\n".join(lines)


def rewrite(text: str) -> str:
    """``text`` (docs/cli.md) with every generated table replaced by the current one."""
    for command in COMMANDS:
        start, end = f"<!-- options:{command} -->", f"<!-- /options:{command} -->"
        if start not in text or end not in text:
            raise ValueError(f"docs/cli.md has no {start} ... {end} markers")
        head, rest = text.split(start, 1)
        _, tail = rest.split(end, 1)
        text = f"{head}{start}\n{option_table(command)}\n{end}{tail}"
    return text
