"""``plan --config FILE``: every setting of a plan from a TOML file or a plan's ``config.json``.

The file's tables are the sections of :class:`~markerplace.plan.config.PlanConfig`, nested as
the configs are::

    [discretize]
    grid_spacing = 0.7          # metres
    level = "all"               # or a storey index

    [discretize.candidates]
    marker_spacing = 1.5
    allow = ["doors"]

    [placement]
    k = 12
    tag_size = 0.3

A ``config.json`` written by ``plan`` is read the same way (its ``scene``, ``scene_options``,
``existing_markers``, ``exclude`` and ``where`` are the run's inputs, given on the command line again), so
``plan SCENE --config OLD/config.json --out NEW`` plans what OLD planned. Flags on the command
line override the file. A key the config does not have or a value out of its bounds is one
line (exit code 2) naming the key and what to give (:class:`~markerplace.errors.UserError`).
Lengths are metres, angles degrees.
"""

from __future__ import annotations

import argparse
import difflib
import logging
import math
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

import tomllib

from markerplace.errors import UserError
from markerplace.jsonfile import MAX_JSON_DEPTH, read_json
from markerplace.runtime.run_lock import odd_entry
from markerplace.settings import NO_CONST, Leaf, apply, walk

log = logging.getLogger(__name__)

__all__ = ["read_config_file", "checked_value", "RUN_RECORD_KEYS"]

RUN_RECORD_KEYS = ("scene", "scene_options", "existing_markers", "exclude", "where")
"""Top-level keys of a plan's ``config.json`` that record the run's inputs, not settings."""

LEGACY_DISCRETIZE_KEYS = ("marker_spacing", "normal_diff_deg", "tag_border", "flatness_tol", "max_normal_z",
                          "scan_rays", "max_scan_range", "allow")
"""``discretize`` keys of a config.json from before the candidate settings moved to
``discretize.candidates`` (read there); its ``discretize.tag_size`` was ``placement.tag_size``."""


LEGACY_PLACEMENT_KEYS = {"v": "omp", "lazy": "omp", "calibration_poses": "expected_recall"}
"""``placement`` keys of a config from before each method's settings moved to
``placement.methods.<method>`` (read there): key -> method (``-`` as ``_``)."""


def upgrade_legacy(data: dict) -> dict:
    """A config dict with the layouts of older plan folders moved to today's: the flat
    ``discretize`` to the nested one, and the method settings of ``placement``
    (:data:`LEGACY_PLACEMENT_KEYS`) to ``placement.methods`` (a dict of today's layout is
    returned unchanged)."""
    placement = data.get("placement")
    if isinstance(placement, dict) and any(k in placement for k in LEGACY_PLACEMENT_KEYS):
        placement = dict(placement)
        methods = {m: dict(v) for m, v in placement.get("methods", {}).items()} \
            if isinstance(placement.get("methods"), dict) else {}
        for key, method in LEGACY_PLACEMENT_KEYS.items():
            if key in placement:
                methods.setdefault(method, {})[key] = placement.pop(key)
        data = {**data, "placement": {**placement, "methods": methods}}
    disc = data.get("discretize")
    if not isinstance(disc, dict) or "candidates" in disc or not any(k in disc for k in LEGACY_DISCRETIZE_KEYS):
        return data
    disc = dict(disc)
    cand = {k: disc.pop(k) for k in LEGACY_DISCRETIZE_KEYS if k in disc}
    disc.pop("tag_size", None)  # derived from placement.tag_size then
    return {**data, "discretize": {**disc, "candidates": cand}}


def read_config_file(path: str | Path, base: Any) -> Any:
    """``base`` (a config instance, e.g. ``PlanConfig()``) with the settings of the TOML or JSON
    file ``path`` applied.

    Raises:
        UserError: the file is missing or not TOML/JSON, a key is not a setting, a value has the
            wrong type, is not one of the choices or is out of its bounds.
    """
    path = Path(path)
    what = f"--config {path}"
    if path.suffix.lower() == ".toml":
        if not path.is_file():
            odd = odd_entry(path.resolve()) if path.exists() else None  # a folder or a FIFO named x.toml
            raise UserError(f"{what} is {odd}, not a settings file: give a TOML file or a plan's config.json" if odd
                            else f"{what}: no such file: give a TOML file or a plan's config.json")
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise UserError(f"{what} is not valid TOML ({' '.join(str(err).split())}): fix the file") from None
        except OSError as err:
            raise UserError(f"{what}: cannot read it ({err.strerror or err})") from None
        except RecursionError:  # tomllib recurses once per nested array or inline table
            raise UserError(f"{what} nests arrays/tables too deeply (Python's parser gave up): not a settings file; "
                            "fix it") from None
        if _depth(data) > MAX_JSON_DEPTH:
            raise UserError(f"{what} nests arrays/tables more than {MAX_JSON_DEPTH} deep: not a settings file; fix it")
        data = upgrade_legacy(data)  # [placement] v = 80 as before methods had their own tables
    elif path.suffix.lower() == ".json":
        data = read_json(path, what)
        if not isinstance(data, dict):
            raise UserError(f"{what} is not a JSON object of settings: give a plan's config.json")
        records = {k: data.pop(k) for k in RUN_RECORD_KEYS if k in data}
        if records.get("existing_markers") or records.get("exclude") or records.get("where"):
            log.warning("%s: the run it records had --existing, --exclude or --where: give them again (a config "
                        "file holds settings only)", what)
        data = upgrade_legacy(data)
    else:
        raise UserError(f"{what}: give a .toml file or a plan's config.json (the suffix says which)")
    updates: dict[str, Any] = {}
    _collect(data, base, "", updates, what)
    return apply(base, updates)


def _depth(value: Any) -> int:
    """Deepest nesting of lists and dicts in ``value`` (0 for a scalar), without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, (list, dict)):
            deepest = max(deepest, d + 1)
            stack.extend((x, d + 1) for x in (v.values() if isinstance(v, dict) else v))
    return deepest


def _collect(data: dict, config: Any, prefix: str, updates: dict, what: str) -> None:
    """Checked leaf values of the table ``data`` of ``config`` into ``updates`` (path -> value)."""
    names = {f.name: f for f in fields(config)}
    leaves = {leaf.path: leaf for leaf in walk(config, prefix)}
    for key, value in data.items():
        path = f"{prefix}{key}"
        if key not in names:
            close = difflib.get_close_matches(key, names, n=1)
            hint = f"did you mean {prefix}{close[0]}?" if close else \
                f"known in {'[' + prefix[:-1] + ']' if prefix else 'the top level'}: {', '.join(names)}"
            raise UserError(f"{what}: unknown setting {path!r}: {hint} (see docs/cli.md, 'plan --config')")
        current = getattr(config, key)
        if is_dataclass(current):
            if not isinstance(value, dict):
                raise UserError(f"{what}: {path} is a table of settings ([{path}]), not a value")
            _collect(value, current, path + ".", updates, what)
            continue
        updates[path] = checked_value(leaves[path], value, what)


def checked_value(leaf: Leaf, value: Any, what: str) -> Any:
    """The field value of ``value`` (as a TOML or JSON file holds it) for ``leaf``, checked:
    its type, choices and bounds, else one line starting with ``what``.

    Raises:
        UserError: a value of the wrong type, not one of the choices or out of its bounds.
    """
    s, key, ann = leaf.setting, leaf.path, leaf.annotation

    def bad(expected: str) -> UserError:
        return UserError(f"{what}: {key} = {value!r} must be {expected} (default {leaf.value!r})")

    if value is None:
        if "None" in ann:
            return None
        raise bad("a value (null only where the default is)")
    if s.convert is not None or (s.type is not None and s.type not in (int, float, str)):
        text = ",".join(str(v) for v in value) if isinstance(value, list) else str(value)
        try:
            out = (s.convert or s.type)(text)
        except (UserError, argparse.ArgumentTypeError) as err:
            raise UserError(f"{what}: {key}: {err}") from None
    else:
        out = _typed(value, leaf.value, ann, bad)
    if s.choices is not None and s.const is NO_CONST and out not in tuple(s.choices()):
        raise UserError(f"{what}: {key} = {value!r} is not one of {', '.join(s.choices())}")
    bound = s.bound(key)
    if bound is not None and out is not None:
        try:
            for v in out if isinstance(out, tuple) else (out,):
                bound.check(v)
        except UserError as err:
            raise UserError(f"{what}: {err}") from None
    return out


def _typed(value: Any, default: Any, ann: str, bad) -> Any:
    """``value`` as the type of ``default`` (a bool, int, float, str or tuple of them)."""
    head = ann.split("|")[0].strip()
    if isinstance(default, bool) or head == "bool":
        if not isinstance(value, bool):
            raise bad("true or false")
        return value
    if isinstance(default, tuple) or head.startswith("tuple"):
        if not isinstance(value, (list, tuple)):
            raise bad("a list")
        inner = head[len("tuple["):-1] if head.startswith("tuple[") else ""
        item_ann = inner.split(",")[0].strip() if inner else ""
        if item_ann.startswith("tuple"):
            item_ann = inner[:inner.rindex("]") + 1]
        item_default = default[0] if isinstance(default, tuple) and default else None
        return tuple(_typed(v, item_default, item_ann, bad) for v in value)
    if isinstance(default, float) or head == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise bad("a finite number")
        return float(value)
    if isinstance(default, int) or head == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad("a whole number")
        return value
    if isinstance(default, str) or head == "str":
        if not isinstance(value, str):
            raise bad("a text")
        return value
    return value
