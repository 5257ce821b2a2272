"""`plan` writes tags.pdf and tagmaps/; `export PLAN_DIR --gltf` writes the model with its tags as
textured quads in the model's original axes and units (built-in z-up world, y-up glTF, a
centimetre OBJ far from the origin), reloaded with trimesh."""

from __future__ import annotations

import json
import shutil
import subprocess
from types import SimpleNamespace

import numpy as np
import pytest
import trimesh

from helpers import FAST
from markerplace.cli.main import main
from markerplace.report.tagged_export import TAG_LIFT_M
from markerplace.scene.export import GLTF_FROM_WORLD
from markerplace.tagfamily import outer_size


@pytest.fixture(scope="module")
def tiny_plan(run_plan):
    return run_plan(3, folder="deliver")


def pdf_pages(path) -> int:
    text = subprocess.run(["pdfinfo", str(path)], check=True, capture_output=True, text=True).stdout
    return int(next(line.split()[1] for line in text.splitlines() if line.startswith("Pages:")))


def tag_nodes(glb):
    """{tag id: (local (4, 3) vertices, (4, 4) world_from_local, texture image, faces)} of a reloaded file."""
    s = trimesh.load(str(glb), force="scene", process=False)
    out = {}
    for node in s.graph.nodes_geometry:
        T, g = s.graph[node]
        if node.startswith("tag_"):
            m = s.geometry[g]
            out[int(node[4:])] = (np.asarray(m.vertices, float), np.asarray(T, float), m.visual.material.baseColorTexture,
                                  np.asarray(m.faces))
    return s, out


def detect_texture(img) -> list[int]:
    from markerplace.localization.tags import make_detector

    gray = np.asarray(img.convert("L"))
    return [d.tag_id for d in make_detector().detect(np.pad(gray, 40, constant_values=255))]


def test_plan_writes_pdf_and_tag_maps(tiny_plan, tmp_path):
    plan = json.loads((tiny_plan / "placement.json").read_text())
    assert pdf_pages(tiny_plan / "tags.pdf") == 3 * 13  # a 0.4 m tag: page map + 12 A4 tiles
    layout = json.loads((tiny_plan / "tagmaps" / "wpilib_field_layout.json").read_text())
    assert [t["ID"] for t in layout["tags"]] == [m["tag_id"] for m in plan["markers"]]
    for t, m in zip(layout["tags"], plan["markers"]):
        tr = t["pose"]["translation"]
        assert np.allclose([tr["x"], tr["y"], tr["z"]], m["position"], atol=1e-4)
    assert not list((tiny_plan / "tagmaps").glob("*_yup*"))  # built-in: z-up only
    config = json.loads((tiny_plan / "config.json").read_text())
    assert config["scene_options"] == {"up": None, "unit_scale": None, "seed": 0} and config["existing_markers"] == []
    copy = tmp_path / "again"
    shutil.copytree(tiny_plan, copy)
    assert main(["plan", "tiny", "-k", "3", "--paper", "none", "--out", str(copy), *FAST]) == 0
    assert pdf_pages(copy / "tags.pdf") == 3


def test_deliverables_of_a_gltf_scene_have_y_up_maps(tmp_path):
    from markerplace.geometry import world_from_marker_pose
    from markerplace.markers import Marker
    from markerplace.report.deliverables import write_deliverables

    m = Marker(4, 0.1, world_from_marker_pose(np.array([1.0, 2.0, 1.5]), np.array([0.0, -1.0, 0.0])))
    rec = {"order": 1, "tag_id": 4, "family": "tag36h11", "size": 0.1, "position": [1.0, 2.0, 1.5], "yaw_deg": -90.0}
    disc = SimpleNamespace(occupancy=np.zeros((30, 40), np.int8), grid_origin=(-1.0, -0.5), grid_resolution=0.1)
    write_deliverables(tmp_path, [rec], [m], [], disc, "scan.glb", {"up": None}, "letter")
    names = sorted(p.name for p in (tmp_path / "tagmaps").iterdir())
    assert names == ["apriltag_ros_bundle.yaml", "apriltag_ros_bundle_yup.yaml", "ros2_apriltag_params.yaml",
                     "ros2_apriltag_params_yup.yaml", "ros2_tag_transforms.launch.yaml",
                     "ros2_tag_transforms_yup.launch.yaml", "tagslam_tags.yaml", "tagslam_tags_yup.yaml",
                     "wpilib_field_layout.json", "wpilib_field_layout_yup.json"]
    yup = json.loads((tmp_path / "tagmaps" / "wpilib_field_layout_yup.json").read_text())
    tr = yup["tags"][0]["pose"]["translation"]
    assert np.allclose([tr["x"], tr["y"], tr["z"]], [1.0, 1.5, -2.0])  # glTF (x, z-up height, -y)
    assert yup["field"] == {"length": 3.0, "width": 2.5}
    assert pdf_pages(tmp_path / "tags.pdf") == 1


def test_export_builtin_plan_in_the_z_up_world(tiny_plan, tmp_path):
    out = tmp_path / "tiny.glb"
    assert main(["export", str(tiny_plan), "--gltf", str(out)]) == 0
    plan = json.loads((tiny_plan / "placement.json").read_text())
    s, tags = tag_nodes(out)
    assert sorted(tags) == sorted(m["tag_id"] for m in plan["markers"])
    for m in plan["markers"]:
        local, T, tex, faces = tags[m["tag_id"]]
        centre = np.array(m["position"]) + TAG_LIFT_M * np.array(m["normal"])
        assert np.allclose(local.mean(axis=0), centre, atol=2e-4)  # vertex data: z-up world, metres
        assert np.allclose(T[:3, :3], GLTF_FROM_WORLD)  # root node: upright in glTF viewers
        edge = np.linalg.norm(local[0] - local[1])
        assert edge == pytest.approx(outer_size(m["size"]), abs=1e-5)
        assert detect_texture(tex) == [m["tag_id"]]  # the texture is the tag with its quiet zone
        for f in faces:  # both triangles face out of the wall (counter-clockwise seen from the room)
            n = np.cross(local[f[1]] - local[f[0]], local[f[2]] - local[f[0]])
            assert np.dot(n, m["normal"]) > 0
    world = s.to_geometry()
    assert world.bounds[1][1] > 2.0  # the scene graph stands the model up: glTF y is the height


def _fake_plan(folder, scene_path, options, markers):
    """A plan folder as `plan` leaves it (config.json + placement.json) for `export`."""
    folder.mkdir()
    (folder / "config.json").write_text(json.dumps({"scene": str(scene_path), "scene_options": options,
                                                    "existing_markers": []}))
    (folder / "placement.json").write_text(json.dumps({"scene": str(scene_path), "markers": markers}))


def test_export_of_a_y_up_gltf_plan_is_in_y_up_coordinates(tiny_plan, tmp_path):
    glb = tmp_path / "tiny_in.glb"
    assert main(["scene", "export", "tiny", str(glb)]) == 0
    markers = json.loads((tiny_plan / "placement.json").read_text())["markers"]
    _fake_plan(tmp_path / "p", glb, {"up": None, "unit_scale": None, "seed": 0}, markers)
    out = tmp_path / "out.glb"
    assert main(["export", str(tmp_path / "p"), "--gltf", str(out)]) == 0
    s, tags = tag_nodes(out)
    for m in markers:
        local, T, _, _ = tags[m["tag_id"]]
        z_up = np.array(m["position"]) + TAG_LIFT_M * np.array(m["normal"])
        assert np.allclose(local.mean(axis=0), GLTF_FROM_WORLD @ z_up, atol=2e-4)  # y-up file coordinates
        assert np.allclose(T, np.eye(4))  # no root transform: already the file's frame
    original = trimesh.load(str(glb), force="scene", process=False).to_geometry()
    model = [s.geometry[s.graph[n][1]] for n in s.graph.nodes_geometry if not n.startswith("tag_")]
    assert np.allclose(np.concatenate([g.vertices for g in model]).min(axis=0), original.bounds[0], atol=1e-5)
    assert np.allclose(np.concatenate([g.vertices for g in model]).max(axis=0), original.bounds[1], atol=1e-5)


def test_export_of_a_far_centimetre_obj_keeps_its_units_and_origin(tiny_plan, tmp_path):
    from markerplace.scene import load_scene

    offset_m = np.array([512000.0, 5412000.0, 300.0])  # survey coordinates: recentred on load
    mesh = load_scene("tiny").to_trimesh()
    mesh.vertices = mesh.vertices * 100.0 + offset_m * 100.0  # centimetres, z up
    obj = tmp_path / "far_cm.obj"
    mesh.export(str(obj))
    markers = json.loads((tiny_plan / "placement.json").read_text())["markers"]
    for m in markers:  # user frame = file axes scaled to metres, recentring undone
        m["position"] = (np.array(m["position"]) + offset_m).tolist()
        T = np.array(m["world_from_marker"])
        T[:3, 3] += offset_m
        m["world_from_marker"] = T.tolist()
    _fake_plan(tmp_path / "p", obj, {"up": "z", "unit_scale": 0.01, "seed": 0}, markers)
    out = tmp_path / "out.glb"
    assert main(["export", str(tmp_path / "p"), "--gltf", str(out)]) == 0
    tree = json.loads(out.read_bytes()[20:20 + int.from_bytes(out.read_bytes()[12:16], "little")])
    nodes = {n["name"]: n for n in tree["nodes"]}
    root = np.array(nodes["model_file_frame"]["matrix"]).reshape(4, 4).T
    assert np.allclose(root[:3, :3], 0.01 * GLTF_FROM_WORLD)  # centimetres, z up -> glTF metres, y up
    shift = np.array(nodes["recentred"]["translation"])
    s, tags = tag_nodes(out)
    for m in markers:
        local = tags[m["tag_id"]][0]
        in_file = (np.array(m["position"]) + TAG_LIFT_M * np.array(m["normal"])) * 100.0
        assert np.abs(local.mean(axis=0) + shift - in_file).max() < 0.05  # centimetres: under half a millimetre
        assert np.linalg.norm(local[0] - local[1]) == pytest.approx(100 * outer_size(m["size"]), abs=1e-3)


@pytest.mark.parametrize("setup, args, message", [
    ("none", ["export", "{d}/missing", "--gltf", "{d}/o.glb"], "is not a folder"),
    ("empty", ["export", "{d}/empty", "--gltf", "{d}/o.glb"], "is not a plan folder"),
    ("badjson", ["export", "{d}/bad", "--gltf", "{d}/o.glb"], "not valid JSON"),
    ("none", ["export", "{d}", "--gltf", "{d}/o.gltf"], "must end in .glb"),
])
def test_export_errors_are_one_line(setup, args, message, tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "config.json").write_text("{not json")
    (tmp_path / "bad" / "placement.json").write_text("{}")
    code = main([a.format(d=tmp_path) for a in args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
