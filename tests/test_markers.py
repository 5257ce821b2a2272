"""Marker JSON parsing and stage-artifact hashing."""

import json

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.markers import load_markers
from markerplace.runtime import cache


def test_marker_file_round_trip(tmp_path):
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"markers": [{"tag_id": 3, "size": 0.3, "position": [1, 2, 1.5], "normal": [0, -1, 0]}]}))
    (m,) = load_markers(path)
    assert m.tag_id == 3 and np.allclose(m.position, [1, 2, 1.5]) and np.allclose(m.normal, [0, -1, 0])
    path.write_text(json.dumps([m.to_json()]))
    (m2,) = load_markers(path)
    assert np.allclose(m2.world_from_marker, m.world_from_marker)
    assert np.allclose(m2.corners_world()[:, 2], [1.35, 1.35, 1.65, 1.65])  # BL, BR, TR, TL


@pytest.mark.parametrize("content, message", [
    ("not json", "not valid JSON"),
    ('{"foo": 1}', "must hold a list"),
    ('[{"size": 0.4, "position": [0,0,0], "normal": [1,0,0]}]', "tag_id"),
    ('[{"tag_id": 1, "size": 40, "position": [0,0,0], "normal": [1,0,0]}]', "in 0.01-5"),
    ('[{"tag_id": 1}]', "position"),
    ('["x"]', "entry 0"),
    ('[{"tag_id": "a", "size": 0.4, "position": [0,0,0], "normal": [1,0,0]}]', "not an integer"),
    ('[{"tag_id": 1, "size": "big", "position": [0,0,0], "normal": [1,0,0]}]', "not a number of metres"),
    ('[{"tag_id": 1, "size": 0.4, "position": [0,0], "normal": [1,0,0]}]', "3 numbers"),
    ('[{"tag_id": 1, "size": 0.4, "position": [0,0,0], "normal": [0,0,0]}]', "zero or vertical"),
    ('[{"tag_id": 1, "world_from_marker": [[1,0],[0]]}]', "4x4"),
])
def test_bad_marker_files(tmp_path, content, message):
    path = tmp_path / "m.json"
    path.write_text(content)
    with pytest.raises(UserError, match=message):
        load_markers(path)
    with pytest.raises(UserError, match="no such file"):
        load_markers(tmp_path / "missing.json")


def test_hash_and_freshness(tmp_path):
    a = cache.hash_of("x", np.arange(3), {"k": 1})
    assert a == cache.hash_of("x", np.arange(3), {"k": 1})
    assert a != cache.hash_of("x", np.arange(4), {"k": 1})
    art = tmp_path / "a.npz"
    assert not cache.is_fresh(art, a)
    art.write_bytes(b"data")
    assert not cache.is_fresh(art, a)  # no meta yet: treated as interrupted
    cache.mark_done(art, a)
    assert cache.is_fresh(art, a) and not cache.is_fresh(art, "other")
