"""Mesh loading: axis conventions, units, materials, and one-line errors for bad input."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import trimesh
from PIL import Image

from markerplace.errors import UserError
from markerplace.scene import load_scene
from markerplace.scene.loader import UP_CHOICES, up_rotation


def _box(extents, center) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(center)
    return m


def _textured(mesh: trimesh.Trimesh, seed: int = 0):
    rng = np.random.default_rng(seed)
    img = (rng.random((8, 16, 3)) * 255).astype(np.uint8)
    uv = rng.random((len(mesh.vertices), 2))
    mat = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.fromarray(img), baseColorFactor=[255, 128, 64, 255])
    mesh.visual = trimesh.visual.TextureVisuals(uv=uv, material=mat)
    return img, uv


def _error(tmp_path, *args, **kwargs) -> str:
    with pytest.raises(UserError) as info:
        load_scene(*args, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg and msg
    return msg


def test_gltf_is_converted_from_y_up(tmp_path):
    # a room-sized box, 3 m tall along glTF +y, lying at glTF z in [1, 3]
    mesh = _box([4.0, 3.0, 2.0], [0.0, 1.5, 2.0])
    img, uv = _textured(mesh)
    path = tmp_path / "box.glb"
    mesh.export(path)
    scene = load_scene(str(path))
    lo, hi = scene.bounds
    np.testing.assert_allclose(lo, [-2.0, -3.0, 0.0], atol=1e-6)  # glTF (x, y, z) -> world (x, -z, y)
    np.testing.assert_allclose(hi, [2.0, -1.0, 3.0], atol=1e-6)
    part = scene.parts[0]
    assert part.texture.shape == (8, 16, 3) and part.texture.dtype == np.uint8
    np.testing.assert_array_equal(part.texture, img)
    np.testing.assert_allclose(part.uv, uv, atol=1e-6)
    np.testing.assert_allclose(part.base_color, [1.0, 128 / 255, 64 / 255, 1.0], atol=1e-6)
    assert part.vertices.dtype == np.float32 and part.faces.dtype == np.int32
    assert scene.source == str(path)


def test_gltf_scene_graph_transforms_are_applied(tmp_path):
    sc = trimesh.Scene()
    T = np.eye(4)
    T[:3, 3] = [10.0, 0.0, 0.0]
    sc.add_geometry(_box([2.0, 2.0, 2.0], [0.0, 1.0, 0.0]), node_name="a")
    sc.add_geometry(_box([2.0, 2.0, 2.0], [0.0, 1.0, 0.0]), node_name="b", transform=T)
    path = tmp_path / "two.glb"
    sc.export(path)
    scene = load_scene(str(path))
    assert len(scene.parts) == 2
    xs = sorted(float(p.vertices[:, 0].mean()) for p in scene.parts)
    np.testing.assert_allclose(xs, [0.0, 10.0], atol=1e-5)
    np.testing.assert_allclose(scene.bounds[:, 2], [0.0, 2.0], atol=1e-6)


def test_obj_with_up_y(tmp_path):
    path = tmp_path / "room.obj"
    _box([4.0, 2.5, 3.0], [0.0, 1.25, 0.0]).export(path)
    upright = load_scene(str(path), up="y")
    np.testing.assert_allclose(upright.bounds[:, 2], [0.0, 2.5], atol=1e-6)
    default = load_scene(str(path))  # OBJ default is z up: unchanged
    np.testing.assert_allclose(default.bounds[:, 1], [0.0, 2.5], atol=1e-6)


@pytest.mark.parametrize("up", UP_CHOICES)
def test_up_axis_maps_to_world_z(up):
    axis = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}[up[-1]]
    v = np.array(axis, dtype=float) * (-1.0 if up.startswith("-") else 1.0)
    R = up_rotation(up)
    np.testing.assert_allclose(R @ v, [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0)


def test_ply_vertex_colours(tmp_path):
    mesh = _box([3.0, 3.0, 2.5], [0.0, 0.0, 1.25])
    colors = np.zeros((len(mesh.vertices), 4), dtype=np.uint8)
    colors[:, 0] = np.arange(len(mesh.vertices)) * 20
    colors[:, 3] = 255
    mesh.visual = trimesh.visual.ColorVisuals(mesh, vertex_colors=colors)
    path = tmp_path / "colored.ply"
    mesh.export(path)
    part = load_scene(str(path)).parts[0]
    assert part.texture is None and part.colors is not None
    assert part.colors.shape == (len(part.vertices), 4) and part.colors.dtype == np.uint8
    # every loaded vertex keeps the colour of the same position in the file
    lookup = {tuple(np.round(v, 4)): c for v, c in zip(mesh.vertices, colors)}
    for v, c in zip(part.vertices, part.colors):
        np.testing.assert_array_equal(c, lookup[tuple(np.round(v.astype(float), 4))])


def test_unit_scale(tmp_path):
    path = tmp_path / "cm.obj"
    _box([500.0, 400.0, 270.0], [0.0, 0.0, 135.0]).export(path)
    scene = load_scene(str(path), unit_scale=0.01)
    np.testing.assert_allclose(scene.bounds[1] - scene.bounds[0], [5.0, 4.0, 2.7], atol=1e-6)


def test_untextured_mesh_is_grey_with_warning(tmp_path, caplog, monkeypatch):
    """Warned once: the size guard, each stage and every worker load the scene again."""
    from markerplace.scene import sanity

    monkeypatch.setattr(logging.getLogger("markerplace"), "propagate", True)
    monkeypatch.setattr(sanity, "_WARNED", set())  # another test's load must not have used it up
    path = tmp_path / "plain.obj"
    _box([3.0, 3.0, 2.5], [0.0, 0.0, 1.25]).export(path)
    def grey():
        return [r for r in caplog.records if "grey" in r.getMessage() and r.levelno == logging.WARNING]

    with caplog.at_level(logging.WARNING, logger="markerplace.scene.loader"):
        scene = load_scene(str(path))
        first = len(grey())
        load_scene(str(path))
    part = scene.parts[0]
    assert part.texture is None and part.colors is None
    assert part.base_color == (0.7, 0.7, 0.7, 1.0)
    assert first >= 1 and len(grey()) == first  # the second load adds no warning


def test_missing_file(tmp_path):
    msg = _error(tmp_path, str(tmp_path / "nope.glb"))
    assert "no such file" in msg and "nope.glb" in msg


def test_unknown_format_lists_extensions(tmp_path):
    path = tmp_path / "model.stl"
    path.write_text("solid x\nendsolid x\n")
    msg = _error(tmp_path, str(path))
    for ext in (".glb", ".gltf", ".obj", ".ply"):
        assert ext in msg


def test_unknown_builtin_name(tmp_path):
    msg = _error(tmp_path, "castle")
    assert "office" in msg and ".glb" in msg


def test_no_faces(tmp_path):
    path = tmp_path / "points.obj"
    path.write_text("v 0 0 0\nv 5 0 0\nv 0 5 0\nv 0 0 3\n")
    msg = _error(tmp_path, str(path))
    assert "no triangle faces" in msg


def test_corrupt_file(tmp_path):
    path = tmp_path / "broken.glb"
    path.write_bytes(b"glTF\x02\x00\x00\x00garbage" + bytes(range(50)))
    msg = _error(tmp_path, str(path))
    assert "valid binary glTF" in msg  # refused by its header (scene.preflight) before trimesh reads it


@pytest.mark.parametrize(
    "extents, scale, needle",
    [([5000.0, 4000.0, 2700.0], None, "--unit-scale 0.01"), ([0.5, 0.4, 0.27], None, "--unit-scale"), ([5.0, 4.0, 2.7], 1000.0, "too big")],
)
def test_absurd_units(tmp_path, extents, scale, needle):
    path = tmp_path / "units.obj"
    _box(extents, [0.0, 0.0, extents[2] / 2]).export(path)
    msg = _error(tmp_path, str(path), unit_scale=scale)
    assert needle in msg


@pytest.mark.parametrize("kwargs, needle", [({"up": "w"}, "--up"), ({"unit_scale": -1.0}, "--unit-scale"), ({"unit_scale": 0.0}, "--unit-scale")])
def test_bad_options(tmp_path, kwargs, needle):
    path = tmp_path / "ok.obj"
    _box([3.0, 3.0, 2.5], [0.0, 0.0, 1.25]).export(path)
    assert needle in _error(tmp_path, str(path), **kwargs)


def test_face_colours_become_vertex_colours(tmp_path):
    mesh = _box([3.0, 3.0, 2.5], [0.0, 0.0, 1.25])
    face_colors = np.zeros((len(mesh.faces), 4), dtype=np.uint8)
    face_colors[:, 1] = np.arange(len(mesh.faces)) * 10
    face_colors[:, 3] = 255
    mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=face_colors)
    path = tmp_path / "faces.ply"
    mesh.export(path)
    part = load_scene(str(path)).parts[0]
    assert part.colors.shape == (3 * len(mesh.faces), 4)
    # each face's three vertices carry that face's colour
    per_face = part.colors[part.faces]
    assert np.all(per_face == per_face[:, :1])
    assert sorted(per_face[:, 0, 1].tolist()) == sorted(face_colors[:, 1].tolist())
