"""GLB export: standard layout, y-up, and a lossless round trip through load_scene; scene CLI."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from markerplace.cli.main import main
from markerplace.scene import load_scene
from markerplace.scene.builtin.catalogue import builtin_names
from markerplace.scene.export import export_glb


def _glb_json(path) -> dict:
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data)
    json_len, kind = struct.unpack_from("<I4s", data, 12)
    assert kind == b"JSON" and json_len % 4 == 0
    bin_len, bin_kind = struct.unpack_from("<I4s", data, 20 + json_len)
    assert bin_kind == b"BIN\0" and 28 + json_len + bin_len == len(data)
    return json.loads(data[20 : 20 + json_len])


def assert_same_scene(a, b):
    """Parts matched by name: vertices within 1 mm, same faces, uv, textures and colours."""
    assert len(a.parts) == len(b.parts)
    by_name = {p.name: p for p in b.parts}
    for p in a.parts:
        q = by_name[p.name]
        assert q.vertices.shape == p.vertices.shape
        assert np.abs(q.vertices.astype(float) - p.vertices.astype(float)).max() < 1e-3
        assert np.array_equal(q.faces, p.faces)
        np.testing.assert_allclose(q.base_color, p.base_color, atol=0.5 / 255)
        if p.texture is None:
            assert q.texture is None
        else:
            assert np.array_equal(q.texture, p.texture)
            np.testing.assert_allclose(q.uv, p.uv, atol=1e-5)
    n_a = len({id(p.texture) for p in a.parts if p.texture is not None})
    n_b = len({id(p.texture) for p in b.parts if p.texture is not None})
    assert n_a == n_b  # shared textures stay shared


@pytest.mark.parametrize("name", ["tiny", "room"])
def test_round_trip(tmp_path, name):
    scene = load_scene(name)
    path = tmp_path / "sub" / f"{name}.glb"
    export_glb(scene, path)
    assert [f.name for f in path.parent.iterdir()] == [path.name]  # atomic: no temporary left
    back = load_scene(str(path))
    assert_same_scene(scene, back)


def test_glb_is_y_up_with_embedded_png(tmp_path):
    scene = load_scene("tiny")
    path = tmp_path / "tiny.glb"
    export_glb(scene, path)
    tree = _glb_json(path)
    assert tree["asset"]["version"] == "2.0"
    assert tree["images"] and all(img["mimeType"] == "image/png" and "bufferView" in img for img in tree["images"])
    assert "uri" not in json.dumps(tree["images"])
    pos = [tree["accessors"][m["primitives"][0]["attributes"]["POSITION"]] for m in tree["meshes"]]
    # height (world z, 0..2.7 m) is glTF +y; world y becomes glTF -z
    assert np.isclose(max(a["max"][1] for a in pos), 2.7, atol=1e-5)
    assert np.isclose(min(a["min"][1] for a in pos), 0.0, atol=1e-5)
    assert np.isclose(max(a["max"][2] for a in pos), -scene.bounds[0, 1], atol=1e-5)


def test_vertex_colour_scene_round_trip(tmp_path):
    import trimesh

    mesh = trimesh.creation.box(extents=[3.0, 3.0, 2.5])
    colors = np.tile(np.array([[200, 30, 60, 255]], np.uint8), (len(mesh.vertices), 1))
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=colors)
    ply = tmp_path / "c.ply"
    mesh.export(ply)
    scene = load_scene(str(ply))
    out = tmp_path / "c.glb"
    export_glb(scene, out)
    back = load_scene(str(out))
    assert back.parts[0].colors is not None
    np.testing.assert_array_equal(back.parts[0].colors[:, :3], scene.parts[0].colors[:, :3])
    np.testing.assert_allclose(back.bounds, scene.bounds, atol=1e-6)


def test_cli_scene_list(capsys):
    assert main(["scene", "list"]) == 0
    out = capsys.readouterr().out
    for name in builtin_names():
        assert name in out
    assert "112.0" in out  # office floor area
    assert "300.0" in out  # apartment floor area


def test_cli_scene_export_then_load(tmp_path):
    out = tmp_path / "out.glb"
    assert main(["scene", "export", "tiny", str(out)]) == 0
    assert_same_scene(load_scene("tiny"), load_scene(str(out)))


def test_cli_scene_export_unknown_name_is_one_line_error(tmp_path, capsys):
    assert main(["scene", "export", "castle", str(tmp_path / "x.glb")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("markerplace: error:") and "\n" not in err and "castle" in err
    assert not (tmp_path / "x.glb").exists()
