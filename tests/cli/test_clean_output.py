"""Small things a user trips on: clean numbers in every JSON file (no -0.0, no binary noise such
as 11.100000000000001), no -0.000 in text, and option values that start with '-' (`--up -x`)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from helpers import negative_zeros
from markerplace.cli.main import join_signed_values, main
from markerplace.runtime.atomic_io import JSON_DIGITS, clean_array, clean_numbers, fixed, write_json

LONG_FLOAT = re.compile(r"-?\d+\.\d{13,}")
"""More decimals than the floats written here can have (all are above 0.1 or zero)."""


def test_write_json_cleans_every_float(tmp_path):
    obj = {"a": 11.100000000000001, "b": -0.0, "c": np.float64(0.1 + 0.2), "d": np.array([[-0.0, 1 / 3]]),
           "e": [np.int64(3), True, None, "x", float("inf")], "f": (2.675, -1e-20)}
    write_json(tmp_path / "x.json", obj)
    text = (tmp_path / "x.json").read_text()
    assert not negative_zeros(text) and not LONG_FLOAT.search(text), text
    back = json.loads(text)
    assert back["a"] == 11.1 and back["b"] == 0.0 and back["c"] == 0.3 and back["d"] == [[0.0, 0.333333333333]]
    assert back["e"] == [3, True, None, "x", None] and back["f"] == [2.675, -1e-20]  # inf: null (JSON has none)
    # exact when asked (values read back where the last bit matters)
    write_json(tmp_path / "y.json", {"v": 1 / 3, "z": -0.0}, digits=None)
    assert json.loads((tmp_path / "y.json").read_text()) == {"v": 1 / 3, "z": 0.0}
    assert clean_numbers(clean_numbers(obj)) == clean_numbers(obj)  # idempotent
    # survey coordinates keep 9 decimals (12 significant digits would drop below a micrometre)
    assert clean_numbers([5412345.123456789, 912345.1234567891]) == [5412345.123456789, 912345.123456789]


def test_negative_zeros_are_numbers_never_parts_of_a_path():
    """The tests' negative-zero finder reads numbers only: pytest's first temporary folder on a
    machine (``pytest-0``) and names like ``scan-0.0`` are no match."""
    text = ('wrote /tmp/pytest-of-root/pytest-0/test_x0/check.csv\n{"dx": -0.0, "dy": -0.057, "p": "a/scan-0.0/b"}\n'
            "moved -0.000 m, at (-0, 1.50), 1e-05,-0.00m,x=-0.0e+00")
    assert negative_zeros(text) == ["-0.0", "-0.000", "-0", "-0.00m", "-0.0e+00"]
    assert negative_zeros("/tmp/pytest-of-root/pytest-0/ -0.5 -10 -0.01 0.0") == []


def test_a_marker_read_from_json_is_the_one_written():
    """Markers read from JSON are kept at the written precision, so a marker written back (the
    plan's config.json keeps --existing markers) and read again is bit for bit the same: the
    cached stages keyed on it are reused by `check`."""
    from markerplace.markers import marker_from_json

    m = marker_from_json({"tag_id": 3, "size": 0.4, "position": [1.234567, -2.5, 1.5], "normal": [1.0, 1.0, 0.0]})
    again = marker_from_json(json.loads(json.dumps(clean_numbers({"tag_id": 3, "size": 0.4,
                                                                   "world_from_marker": m.world_from_marker}))))
    assert again.world_from_marker.tobytes() == m.world_from_marker.tobytes()
    assert np.array_equal(clean_array(m.world_from_marker), m.world_from_marker)
    assert not np.any(np.signbit(m.world_from_marker) & (m.world_from_marker == 0))  # no -0.0
    assert np.allclose(m.normal, [np.sqrt(0.5), np.sqrt(0.5), 0.0], atol=10 ** -JSON_DIGITS)


def test_fixed_never_prints_negative_zero():
    assert fixed(-0.0004, 3) == "0.000" and fixed(-0.0, 1) == "0.0" and fixed(-0.4, 0) == "0"
    assert fixed(-0.0006, 3) == "-0.001" and fixed(2.5, 2) == "2.50" and fixed(None, 2, "-") == "-"


def test_values_that_start_with_a_minus(tmp_path, capsys):
    assert join_signed_values(["plan", "a.obj", "--up", "-x", "--start", "-2.5,1", "-k", "3"]) == \
        ["plan", "a.obj", "--up=-x", "--start=-2.5,1", "-k", "3"]
    assert join_signed_values(["render", "--up", "--help"]) == ["render", "--up", "--help"]
    # argparse accepts them: the run gets as far as the missing file (not "expected one argument")
    code = main(["render", str(tmp_path / "missing.obj"), "--up", "-x", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no such file" in err[0], err
    code = main(["plan", str(tmp_path / "missing.obj"), "--up", "-y", "--start", "-1.5,-2", "-k", "2",
                 "--out", str(tmp_path / "p")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no such file" in err[0], err


@pytest.mark.parametrize("value", ["-z", "-y", "-x"])
def test_up_axis_with_a_minus_parses(value):
    from markerplace.cli.main import build_parser

    args = build_parser().parse_args(join_signed_values(["render", "m.obj", "--up", value, "--out", "o"]))
    assert args.up == value
