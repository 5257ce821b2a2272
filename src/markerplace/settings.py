"""One home per setting: a config field carries its flag, help, bounds and units.

A field of a frozen config dataclass made with :func:`setting` holds a :class:`Setting` in its
metadata. From it come

* the command-line option (:func:`add_setting_args`: flag, type, choices, ``--help`` text with
  the default),
* the bounds check with its one-line message (:meth:`Setting.bound`, a :class:`Bound`;
  :mod:`markerplace.cli.bounds` gathers them per subcommand, :func:`check_bounds` checks a config),
* the option tables of ``docs/cli.md`` (:mod:`markerplace.cli.option_docs`, rewritten by
  ``scripts/cli_docs.py``),
* the keys of ``plan --config FILE.toml`` (:mod:`markerplace.config_file`).

Options that are no config field (the scene argument, ``--out``, ``--force``, ...) are listed in
:data:`markerplace.cli.run_options.RUN_OPTIONS`; config fields deliberately without a flag in :data:`NO_FLAG`, with the
reason. ``tests/test_settings.py`` fails when a flag has no field or a field no flag.
Lengths are metres, angles degrees.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import math
from dataclasses import MISSING, dataclass, field, fields, is_dataclass, replace
from typing import Any, Callable, Iterator, Sequence

from markerplace.errors import UserError

log = logging.getLogger(__name__)

__all__ = ["Setting", "setting", "walk", "add_setting_args", "values_from_args", "apply", "NO_FLAG"]


SEED_MAX = 2**32 - 1


@dataclass(frozen=True)
class Bound:
    """Allowed values of one numeric option.

    Attributes:
        option: the flag as the user types it (``--grid-spacing``).
        lo, hi: inclusive range.
        unit: unit printed after the numbers (``m``, ``px``, ``deg``, ``%``), or ``""``.
        hint: what to give instead, e.g. ``"the camera grid spacing in metres, e.g. 0.5"``.
        integer: the option is an integer (messages say "at least"/"at most").
    """

    option: str
    lo: float
    hi: float
    unit: str
    hint: str
    integer: bool = False

    def check(self, value: Any) -> Any:
        """Return ``value`` unchanged, or raise :class:`UserError` naming the option, the value,
        the range with its unit and what to give instead."""
        unit = f" {self.unit}" if self.unit else ""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise UserError(f"{self.option} {value!r} is not a number: give {self.hint}") from None
        if isinstance(value, float) and not math.isfinite(value):
            raise UserError(f"{self.option} {value} is not a finite number: give {self.hint}")
        if self.integer and value != int(value):
            raise UserError(f"{self.option} {value} must be a whole number: give {self.hint}")
        if self.integer:
            if value < self.lo:
                raise UserError(f"{self.option} {_fmt(value)} must be at least {_fmt(self.lo)}{unit}: give {self.hint}")
            if value > self.hi:
                raise UserError(f"{self.option} {_fmt(value)} must be at most {_fmt(self.hi)}{unit}: give {self.hint}")
        elif not self.lo <= value <= self.hi:
            raise UserError(f"{self.option} {_fmt(value)}{unit} is outside [{_fmt(self.lo)}, {_fmt(self.hi)}]{unit}: "
                            f"give {self.hint}")
        return value


def _fmt(v: float) -> str:
    """A short text of a number (huge integers abbreviated)."""
    if isinstance(v, int):
        text = str(v)
        return text if len(text) <= 15 else f"{text[:4]}...({len(text.lstrip('-'))} digits)"
    if v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return f"{v:g}"


OCCUPANCY_CELL = 0.05
"""Occupancy cell size of the discretization, metres: finer camera or marker spacing means nothing."""

class _NoConst:
    def __repr__(self) -> str:
        return "NO_CONST"


NO_CONST = _NoConst()
"""``Setting.const`` of an option that takes a value."""


@dataclass(frozen=True)
class Setting:
    """What a config field needs on the command line.

    Attributes:
        flag: the option (``--grid-spacing``, ``-k``), or None (no option; list it in :data:`NO_FLAG`).
        help: ``--help`` text without the default (a str, or a callable for texts built from
            registries); the default is appended.
        doc: the ``docs/cli.md`` text when longer than ``help`` (str or callable), else None.
        bounds: inclusive (lo, hi) of a number (each item of a tuple of numbers), or None.
        units: unit of the bounds (``m``, ``px``, ``deg``, ``%``) or ``""``.
        hint: what to give instead, in the bound's error message (``"the camera grid spacing in
            metres, e.g. 0.5"``).
        integer: a whole number (also inferred from an ``int`` annotation).
        type: argparse type of the value (default: float/int from the annotation, else str).
        choices: a callable giving the allowed names, or None.
        metavar: argparse metavar.
        const: the option takes no value and sets the field to this (``--no-similarity``:
            False); :data:`NO_CONST` for an option with a value.
        convert: option text (or a config file's value joined with commas) -> field value,
            raising :class:`~markerplace.errors.UserError`; None: the typed value as is.
        shown_default: the default as ``--help`` and the docs show it (None: the field's).
        commands: the subcommands that have the option (None: every one given the config).
    """

    flag: str | None = None
    help: str | Callable[[], str] = ""
    doc: str | Callable[[], str] | None = None
    bounds: tuple[float, float] | None = None
    units: str = ""
    hint: str = ""
    integer: bool = False
    type: Callable[[str], Any] | None = None
    choices: Callable[[], Sequence[str]] | None = None
    metavar: str | None = None
    const: Any = NO_CONST
    convert: Callable[[Any], Any] | None = None
    shown_default: str | None = None
    commands: tuple[str, ...] | None = None

    def help_text(self) -> str:
        return self.help() if callable(self.help) else self.help

    def doc_text(self) -> str:
        doc = self.doc() if callable(self.doc) else self.doc
        return doc or self.help_text()

    def bound(self, option: str | None = None):
        """The :class:`Bound` of the value (None without bounds)."""
        if self.bounds is None:
            return None
        return Bound(option or self.flag or "?", self.bounds[0], self.bounds[1], self.units, self.hint, self.integer)


def setting(default: Any = MISSING, *, default_factory: Any = MISSING, **kwargs) -> Any:
    """A dataclass field with a :class:`Setting` (keyword arguments) in its metadata."""
    meta = {"setting": Setting(**kwargs)}
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata=meta)
    return field(default=default, metadata=meta)


@dataclass(frozen=True)
class Leaf:
    """One config field that is not itself a config: ``path`` (``discretize.grid_spacing``),
    the dataclass ``field``, its :class:`Setting` (a bare one when the field has none), and
    ``value`` in the config walked."""

    path: str
    field: dataclasses.Field
    setting: Setting
    value: Any

    @property
    def annotation(self) -> str:
        return str(self.field.type)

    @property
    def integer(self) -> bool:
        return self.setting.integer or self.annotation.split("|")[0].strip() == "int"


def _setting_of(f: dataclasses.Field) -> Setting:
    s = f.metadata.get("setting")
    if s is None:
        return Setting()
    if not s.integer and str(f.type).split("|")[0].strip() == "int":
        s = replace(s, integer=True)
    return s


def walk(config: Any, prefix: str = "") -> Iterator[Leaf]:
    """Every leaf field of the config instance ``config`` (nested configs entered), in field order."""
    for f in fields(config):
        value = getattr(config, f.name)
        path = f"{prefix}{f.name}"
        if is_dataclass(value) and not isinstance(value, type):
            yield from walk(value, path + ".")
        else:
            yield Leaf(path, f, _setting_of(f), value)


def apply(config: Any, updates: dict[str, Any]) -> Any:
    """``config`` with the leaf values of ``updates`` (path -> value) replaced, nested configs
    rebuilt with :func:`dataclasses.replace`."""
    if not updates:
        return config
    own, nested = {}, {}
    for path, value in updates.items():
        head, _, rest = path.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            own[head] = value
    for head, sub in nested.items():
        own[head] = apply(getattr(config, head), sub)
    return replace(config, **own)


def shown_default(leaf: Leaf) -> str:
    """The default of a leaf as help and docs show it."""
    s = leaf.setting
    if s.shown_default is not None:
        return s.shown_default
    if s.const is not NO_CONST:
        return "off"  # a switch: the field's default holds while it is not given
    v = leaf.value
    if v is None:
        return "none"
    if isinstance(v, bool):
        return "on" if v else "off"
    if isinstance(v, (tuple, list)):
        return ",".join(str(x) for x in v) or "none"
    return f"{v:g}" if isinstance(v, float) else str(v)


def flagged(config: Any, command: str) -> list[Leaf]:
    """The leaves of ``config`` that have an option in ``command``."""
    return [leaf for leaf in walk(config) if leaf.setting.flag
            and (leaf.setting.commands is None or command in leaf.setting.commands)]


def add_setting_args(parser, config: Any, command: str, groups: dict[str, Any] | None = None,
                     defaults: bool = False) -> None:
    """Add an option for every flagged leaf of ``config`` (an instance: its values are the
    defaults shown) to ``parser``, in the argparse group ``groups[top-level section]`` when
    given. ``defaults``: argparse defaults are the field's (as option text); otherwise None, so
    that a flag the user gave can be told from one left out (``plan --config``)."""
    for leaf in flagged(config, command):
        s = leaf.setting
        target = (groups or {}).get(leaf.path.split(".")[0], parser)
        shown = shown_default(leaf)
        text = s.help_text()
        text = f"{text} (default {shown})" if text else f"default {shown}"
        kw: dict[str, Any] = {"help": text.replace("%", "%%"), "dest": _dest(s.flag)}
        if s.const is not NO_CONST:
            kw.update(action="store_const", const=s.const, default=None)
        else:
            kw["type"] = s.type or (None if s.convert else int if leaf.integer else
                                    float if leaf.annotation.split("|")[0].strip() == "float" else None)
            if s.choices is not None:
                kw["choices"] = list(s.choices())
            if s.metavar:
                kw["metavar"] = s.metavar
            kw["default"] = _cli_default(leaf) if defaults else None
        target.add_argument(s.flag, **kw)


def _dest(flag: str) -> str:
    return flag.lstrip("-").replace("-", "_")


def _cli_default(leaf: Leaf) -> Any:
    v = leaf.value
    if leaf.setting.convert is not None and isinstance(v, (tuple, list)):
        return ",".join(str(x) for x in v)
    return v


def values_from_args(args: argparse.Namespace, config: Any, command: str) -> dict[str, Any]:
    """path -> field value of every flagged leaf whose option is in ``args`` and not None
    (given, or defaulted by :func:`add_setting_args` with ``defaults``); ``convert`` applied."""
    out = {}
    for leaf in flagged(config, command):
        value = getattr(args, _dest(leaf.setting.flag), None)
        if value is None:
            continue
        if leaf.setting.convert is not None and leaf.setting.const is NO_CONST:
            value = leaf.setting.convert(value)
        out[leaf.path] = value
    return out


def bounds_by_dest(config: Any, command: str) -> dict:
    """argparse dest -> :class:`Bound` of the numeric options of ``config``."""
    return {_dest(leaf.setting.flag): leaf.setting.bound() for leaf in flagged(config, command)
            if leaf.setting.bounds is not None and leaf.setting.const is NO_CONST and leaf.setting.convert is None}


def check_bounds(config: Any, prefix: str = "") -> None:
    """Check every bounded leaf of ``config`` (items of a tuple each; None skipped), raising the
    bound's one-line :class:`~markerplace.errors.UserError` named by its flag (else its path)."""
    for leaf in walk(config, prefix):
        s = leaf.setting
        b = s.bound(s.flag if s.flag and s.const is NO_CONST else leaf.path)
        if b is None or leaf.value is None:
            continue
        for v in leaf.value if isinstance(leaf.value, (tuple, list)) else (leaf.value,):
            b.check(v)


NO_FLAG: dict[str, str] = {
    "placement.recall_model": "the calibrated method whose success model predicts recall; set it in a --config file",
    "placement.first_tag_id": "the tag ids of a plan start at 0; set it in a --config file",
    "placement.k@evaluate": "evaluate places max(--k) markers (its --k is the study's list of budgets)",
    "placement.method@evaluate": "evaluate runs every method of --methods",
    "placement.target_recall@evaluate": "evaluate places its --k budgets (a recall target is a plan's)",
    "placement.recall_curve@evaluate": "evaluate measures recall on test images (the predicted curve is a plan's)",
    "placement.target_recall@study": "a study places its --k budgets (a recall target is a plan's)",
    "placement.recall_curve@study": "a study measures recall on test images (the predicted curve is a plan's)",
    "evaluate.seed": "the scene argument's --seed (a run option) seeds it",
    "evaluate.thresholds": "the paper's recall thresholds",
    "evaluate.test.min_clearance": "a property of the test-pose sampler, not of an experiment",
    "evaluate.localization.vlad_clusters": "the localizer's codebook size, as published",
    "placement.k@study": "a study places max(--k) markers (its --k is the list of budgets)",
    "placement.method@study": "a study evaluates OMP",
    **{f"evaluate.{path}@study": "a study fixes it (OMP against no markers, the published localizer, no "
                                  "diagnostics) or varies it itself (--vs, --shifts, --scales, --no-detection-study)"
       for path in ("test.tests", "test.sets", "test.conditions", "study.methods", "study.runs", "study.tag_scale", "study.shift",
                    "study.tag_ids", "localization.localizer", "localization.use_tags", "localization.tag_corners",
                    "diagnostics.ceiling", "diagnostics.calibration", "diagnostics.predicted")},
}
"""Config fields of ``plan``/``evaluate`` that have no flag, with the reason (``path@command``:
only in that command). Every field not listed here and not listed by :data:`NO_FLAG_SECTIONS`
has a flag."""

NO_FLAG_SECTIONS: dict[str, str] = {
    "discretize.": "the discretization's internals (resolution, slices, storeys, the candidate rules' geometry): "
                   "set them in a --config file",
    "imaging.": "the camera and the feature preset of the paper: set them in a --config file",
    "similarity.": "the look-alike search's internals: set them in a --config file",
    "noise.": "the scoring's noise model, as published: set it in a --config file",
    "runtime.batch": "a throughput knob of the executor (results do not depend on it)",
    "placement.methods.": "a placement method's own settings: --method-conf KEY=VALUE, or the table "
                          "[placement.methods.NAME] of a --config file",
}
"""Config sections (path prefixes) whose fields have no flag unless a field says otherwise."""
