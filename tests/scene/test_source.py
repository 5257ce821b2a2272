"""What a scene argument names (a built-in or a file) and the up axis the loader gave the file."""

from __future__ import annotations

import numpy as np

from markerplace.scene.source import file_up_axis, is_builtin, world_from_file_rotation


def test_builtin_names_unless_a_file_of_that_name_is_there(tmp_path, monkeypatch):
    assert is_builtin("office") and is_builtin(" Office ") and not is_builtin("model.glb")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "office").write_text("a file named like a built-in scene")
    assert not is_builtin("office")


def test_up_axis_from_the_option_else_from_the_format():
    assert file_up_axis("office", "y") is None and world_from_file_rotation("office", None) is None
    assert file_up_axis("m.glb", None) == "y" and file_up_axis("m.GLTF", None) == "y"
    assert file_up_axis("m.obj", None) == "z" and file_up_axis("m.ply", None) == "z"
    assert file_up_axis("m.obj", " +Y ") == "y"
    R = world_from_file_rotation("m.glb", None)  # y up in the file -> z up in the world
    np.testing.assert_allclose(R @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(world_from_file_rotation("m.obj", None), np.eye(3), atol=1e-12)
