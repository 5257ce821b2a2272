"""The one reader of JSON files a user gives (``--existing``, ``check --installed``,
``render --markers``, ``evaluate --placements``, a plan folder's ``config.json`` and
``placement.json``, ``fuse``'s intrinsics).

Every problem is a :class:`~markerplace.errors.UserError` with one line naming the file and the
option: missing, a folder, larger than ``max_bytes``, not UTF-8, nested deeper than
``max_depth`` (checked on the text before parsing, so ``[`` x 100000 gives one line instead of
Python's ``RecursionError``), not valid JSON (with line and column), or holding a number that
is not finite: Python's ``NaN``, ``Infinity`` and ``-Infinity`` (no JSON, but Python writes
them) and numbers beyond a float (``1e400``) are refused wherever they are, so a plan folder
whose placement.json was edited to hold one is refused by every reader (the tool itself writes
``null`` for a value that is not a number, :func:`markerplace.runtime.atomic_io.write_json`).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from markerplace.errors import UserError
from markerplace.input_paths import check_input_file

__all__ = ["read_json", "json_depth", "MAX_JSON_BYTES", "MAX_JSON_DEPTH"]

MAX_JSON_BYTES = 64 * 1024 * 1024
"""Largest JSON file read (64 MiB; a placement.json of 10,000 tags is about 6 MB)."""
MAX_JSON_DEPTH = 32
"""Deepest nesting of arrays and objects read (a marker file needs 4, config.json 3)."""

_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)


def json_depth(data: bytes) -> int:
    """Deepest nesting of ``[``/``{`` in JSON text ``data`` (brackets inside strings do not
    count), without parsing it; 0 for a bare value. Unbalanced text gives the deepest point
    reached (the parser reports the syntax error)."""
    stripped = _STRING.sub(b'""', data)
    a = np.frombuffer(stripped, dtype=np.uint8)
    step = np.isin(a, (ord("["), ord("{"))).astype(np.int64) - np.isin(a, (ord("]"), ord("}")))
    return int(np.cumsum(step).max()) if len(step) else 0


def _non_finite(what: str):
    def refuse(token: str):
        raise UserError(f"{what} holds {token}, a NaN or infinite number, which JSON does not have: every number "
                        "must be finite; fix or re-export it")
    return refuse


def _finite(what: str):
    def number(text: str) -> float:
        value = float(text)
        if not math.isfinite(value):  # 1e400
            raise UserError(f"{what} holds {text[:40]}, a NaN or infinite number (too large for a float): every "
                            "number must be finite; fix or re-export it")
        return value
    return number


def read_json(path: str | Path, what: str | None = None, max_bytes: int = MAX_JSON_BYTES,
              max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse the JSON file ``path`` under the guards of the module docstring.

    Args:
        path: the file.
        what: how the user gave it, path included, for messages, e.g. ``"--existing hung.json"``
            (default: the path).
        max_bytes: size limit in bytes.
        max_depth: nesting limit (arrays and objects).

    Returns:
        The parsed value (dict, list, str, number, bool or None).
    """
    path = Path(path)
    what = what or str(path)
    check_input_file(path, what, "a JSON file")  # a folder, a FIFO, a device, a link loop: one line each
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise UserError(f"{what} is {size / 2**20:.0f} MiB, more than the {max_bytes / 2**20:.0f} MiB a JSON "
                            "input may have: is it the right file?")
        data = path.read_bytes()
    except OSError as err:
        raise UserError(f"{what}: cannot read it ({err.strerror or err})") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise UserError(f"{what} is not UTF-8 text (byte {err.start}): JSON files are UTF-8; fix or re-export it") \
            from None
    depth = json_depth(data)
    if depth > max_depth:
        raise UserError(f"{what} nests arrays/objects {depth} deep, more than {max_depth}: not a file this tool "
                        "writes or reads; fix or re-export it")
    try:
        return json.loads(text, parse_constant=_non_finite(what), parse_float=_finite(what))
    except json.JSONDecodeError as err:
        raise UserError(f"{what} is not valid JSON ({err.msg} at line {err.lineno}, column {err.colno}); "
                        "fix or re-export it") from None
    except RecursionError:  # pragma: no cover - the depth guard comes first
        raise UserError(f"{what} nests too deeply: fix or re-export it") from None
