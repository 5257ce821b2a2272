"""Transparent materials end to end: OBJ/MTL and glTF rules on load, BLEND materials on export,
and the renderer's glass pass (blended colour, depth and normals of what lies behind)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from markerplace.geometry import world_from_cam_pose
from markerplace.scene import load_scene
from markerplace.scene.export import export_glb, scene_to_glb_bytes
from markerplace.scene.transparency import GLASS_ALPHA, mtl_opacity
from markerplace.scene.types import MeshPart, Scene

CAM = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)  # looks along +x


def _quad(x: float, half: float, color, transparent=False, name="q") -> MeshPart:
    """A square in the plane x = ``x``, centred on the camera axis, normal -x (towards the camera)."""
    v = np.array([[x, half, 1.5 - half], [x, -half, 1.5 - half], [x, -half, 1.5 + half], [x, half, 1.5 + half]], np.float32)
    return MeshPart(name, v, np.array([[0, 1, 2], [0, 2, 3]], np.int32), base_color=color, transparent=transparent)


def _glb_tree(data: bytes) -> tuple[dict, bytes]:
    n, _ = struct.unpack_from("<I4s", data, 12)
    return json.loads(data[20 : 20 + n]), data[20 + n + 8 :]


def _glb(tree: dict, binary: bytes) -> bytes:
    text = json.dumps(tree).encode()
    text += b" " * ((-len(text)) % 4)
    head = struct.pack("<4sII", b"glTF", 2, 28 + len(text) + len(binary))
    return head + struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\0") + binary


def _box_scene() -> Scene:
    """Four opaque-coloured unit-ish walls of a 4 m room (distinct colours so materials stay apart)."""
    parts = tuple(_quad(2.0 + i, 2.0, (0.2 * i + 0.1, 0.5, 0.5, 1.0), name=f"w{i}") for i in range(4))
    return Scene("box", parts)


def test_obj_mtl_dissolve_and_transparency_load_as_glass(tmp_path):
    (tmp_path / "m.mtl").write_text(
        "newmtl glass\nKd 0.8 0.9 1.0\nd 0.3\n"
        "newmtl tinted\nKd 0.5 0.5 0.6\nTr 0.6\n"
        "newmtl wall\nKd 0.6 0.6 0.6\nd 1.0\n"
        "newmtl nearly\nKd 0.6 0.5 0.6\nTr 0.05\n"
    )
    lines = ["mtllib m.mtl"]
    for i, mat in enumerate(("glass", "tinted", "wall", "nearly")):
        lines += [f"v {i} 0 0", f"v {i} 3 0", f"v {i} 3 2.5", f"v {i} 0 2.5", f"usemtl {mat}", f"f {4 * i + 1} {4 * i + 2} {4 * i + 3} {4 * i + 4}"]
    (tmp_path / "m.obj").write_text("\n".join(lines) + "\n")
    parts = {p.name: p for p in load_scene(str(tmp_path / "m.obj")).parts}
    assert parts["glass"].transparent and parts["glass"].base_color[3] == pytest.approx(0.3)
    assert parts["tinted"].transparent and parts["tinted"].base_color[3] == pytest.approx(0.4)
    assert not parts["wall"].transparent and parts["wall"].base_color[3] == 1.0
    assert not parts["nearly"].transparent and parts["nearly"].base_color[3] == 1.0
    assert parts["glass"].base_color[:3] == pytest.approx((0.8, 0.9, 1.0), abs=1 / 255)


def test_mtl_opacity_rules():
    assert mtl_opacity({"d": ["0.25"]}) == 0.25
    assert mtl_opacity({"d": ["-halo", "0.5"]}) == 0.5
    assert mtl_opacity({"d": ["1"], "tr": ["0.9"]}) == 1.0  # d wins over Tr
    assert mtl_opacity({"tr": ["0.8"]}) == pytest.approx(0.2)
    assert mtl_opacity({"tr": ["0.05"]}) == 1.0
    assert mtl_opacity({"kd": [0.5, 0.5, 0.5]}) is None


@pytest.mark.parametrize(
    "edit, transparent",
    [
        ({"alphaMode": "BLEND", "alpha": 0.3}, True),
        ({"alphaMode": "BLEND", "alpha": 0.95}, False),  # nearly opaque
        ({"alphaMode": "OPAQUE", "alpha": 0.3}, False),  # alpha ignored by the specification
        ({"alphaMode": "MASK", "alpha": 0.3}, False),
        ({"transmission": 0.9}, True),  # KHR_materials_transmission (trimesh drops it)
        ({"transmission": 0.0}, False),
    ],
)
def test_gltf_material_rules(tmp_path, edit, transparent):
    tree, binary = _glb_tree(scene_to_glb_bytes(_box_scene()))
    mat = tree["materials"][1]
    if "alphaMode" in edit:
        mat["alphaMode"] = edit["alphaMode"]
        mat["pbrMetallicRoughness"]["baseColorFactor"][3] = edit["alpha"]
    if "transmission" in edit:
        mat["extensions"] = {"KHR_materials_transmission": {"transmissionFactor": edit["transmission"]}}
        tree["extensionsUsed"] = ["KHR_materials_transmission"]
    path = tmp_path / "t.glb"
    path.write_bytes(_glb(tree, binary))
    flags = {p.name: p.transparent for p in load_scene(str(path)).parts}
    assert flags == {"w0": False, "w1": transparent, "w2": False, "w3": False}


def test_export_writes_blend_materials_and_round_trips(tmp_path):
    parts = _box_scene().parts + (
        _quad(1.0, 0.5, (0.7, 0.8, 0.9, 0.25), transparent=True, name="glass"),
        _quad(1.5, 0.5, (0.7, 0.8, 0.9, 1.0), transparent=True, name="clear"),  # glass without an alpha
        _quad(1.7, 0.5, (0.7, 0.8, 0.9, 1.0), name="opaque_twin"),  # same colour, opaque
    )
    scene = Scene("glassy", parts)
    tree, _ = _glb_tree(scene_to_glb_bytes(scene))
    mats = {tree["meshes"][i]["name"]: tree["materials"][m["primitives"][0]["material"]] for i, m in enumerate(tree["meshes"])}
    for name in ("glass", "clear"):
        assert mats[name]["alphaMode"] == "BLEND" and mats[name]["doubleSided"] is True
    assert mats["glass"]["pbrMetallicRoughness"]["baseColorFactor"][3] == pytest.approx(0.25)
    assert mats["clear"]["pbrMetallicRoughness"]["baseColorFactor"][3] == pytest.approx(GLASS_ALPHA)
    assert all("alphaMode" not in mats[n] for n in ("w0", "w1", "w2", "w3", "opaque_twin"))
    # the clear glass and the opaque part of the same colour do not share a material
    assert mats["clear"] is not mats["opaque_twin"]
    path = tmp_path / "glassy.glb"
    export_glb(scene, path)
    back = {p.name: p for p in load_scene(str(path)).parts}
    assert {n for n, p in back.items() if p.transparent} == {"glass", "clear"}
    assert back["glass"].base_color[3] == pytest.approx(0.25, abs=0.5 / 255)


def test_renderer_blends_glass_and_keeps_depth_of_what_is_behind():
    from markerplace.render.renderer import Renderer

    wall = _quad(3.0, 5.0, (0.8, 0.1, 0.1, 1.0), name="wall")
    glass = _quad(2.0, 0.4, (0.2, 0.9, 0.2, 0.3), transparent=True, name="glass")
    hidden = _quad(4.0, 0.4, (0.1, 0.1, 0.9, 0.3), transparent=True, name="behind_wall")
    with Renderer(Scene("w", (wall,))) as r:
        plain = r.render(CAM)
    with Renderer(Scene("wg", (glass, wall, hidden))) as r:
        assert len(r._glass_draws) == 2
        seen = r.render(CAM)
        depth_only = r.render(CAM, rgb=False, normal=False)
    c = (slice(215, 235), slice(290, 310))
    # depth and normals: the wall behind the glass, as without it
    np.testing.assert_array_equal(seen.depth, plain.depth)
    np.testing.assert_array_equal(seen.normal, plain.normal)
    np.testing.assert_array_equal(depth_only.depth, plain.depth)
    # colour: 0.7 x wall + 0.3 x glass (head-on, so both lit by ambient + full headlight = 1)
    expected = 0.7 * plain.rgb[c].astype(float) + 0.3 * np.array([0.2, 0.9, 0.2]) * 255
    assert np.abs(seen.rgb[c] - expected).max() <= 2.0
    # outside the glass (and over the glass behind the wall) the wall is unchanged
    np.testing.assert_array_equal(seen.rgb[20:60, 20:60], plain.rgb[20:60, 20:60])


def test_glass_with_nothing_behind_blends_over_black_with_no_depth():
    from markerplace.render.renderer import Renderer

    glass = _quad(2.0, 0.4, (0.2, 0.9, 0.2, 1.0), transparent=True)  # alpha 1: drawn at GLASS_ALPHA
    with Renderer(Scene("g", (glass,))) as r:
        res = r.render(CAM)
    c = res.rgb[215:235, 290:310].astype(float)
    np.testing.assert_allclose(c, np.broadcast_to(GLASS_ALPHA * np.array([0.2, 0.9, 0.2]) * 255, c.shape), atol=2.0)
    assert (res.depth == 0).all() and (res.normal == 0).all()
