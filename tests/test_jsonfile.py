"""The one JSON reader (:mod:`markerplace.jsonfile`): a number that is not finite is refused
wherever it is (issue 50 item 6), and the tool never writes one (``null`` instead)."""

from __future__ import annotations

import pytest

from markerplace.errors import UserError
from markerplace.jsonfile import read_json
from markerplace.runtime.atomic_io import write_json


@pytest.mark.parametrize("text, token", [('{"summary": {"q": NaN}}', "NaN"), ('[1, Infinity]', "Infinity"),
                                         ('{"a": [-Infinity]}', "-Infinity"), ('{"x": 1e400}', "1e400")])
def test_a_number_that_is_not_finite_is_refused_anywhere(text, token, tmp_path):
    path = tmp_path / "f.json"
    path.write_text(text)
    with pytest.raises(UserError) as err:
        read_json(path, "--existing f.json")
    assert f"--existing f.json holds {token}, a NaN or infinite number" in str(err.value)


def test_the_tool_writes_null_for_a_value_that_is_not_a_number(tmp_path):
    write_json(tmp_path / "o.json", {"gain": float("nan"), "bound": [1.5, float("inf")], "k": 2})
    assert "NaN" not in (tmp_path / "o.json").read_text() and "Infinity" not in (tmp_path / "o.json").read_text()
    assert read_json(tmp_path / "o.json") == {"gain": None, "bound": [1.5, None], "k": 2}
