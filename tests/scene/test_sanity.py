"""Meshes that are wrong but load, and inputs checked against the scene (issue 13, items 4-7):
NaN/inf vertices, a wrong up axis, a model far from the origin, --existing markers off the
walls, a non-UTF-8 OBJ, a .gltf with a missing texture, a missing --placements folder."""

import csv
import json
import logging

import numpy as np
import pytest

from helpers import FAST
from helpers.gltf import gltf_with_texture_uri
from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.runtime import cache
from markerplace.scene import load_scene

FAR = np.array([1.0e6, 2.0e6, 0.0])  # survey-like coordinates, world metres


@pytest.fixture(autouse=True)
def _fresh_warnings():
    """Loader warnings are printed once per process; each test wants to see its own."""
    try:
        from markerplace.scene import sanity
    except ImportError:  # a version without the checks (the tests must fail on it, not error)
        return
    sanity._WARNED.clear()


def _obj_from_scene(scene, path, transform=np.eye(4)):
    """Write a trimesh.Scene as OBJ + MTL + textures (material names made file-safe)."""
    from trimesh.exchange.obj import export_obj

    scene = scene.copy()
    for i, g in enumerate(scene.geometry.values()):
        material = getattr(g.visual, "material", None)
        if material is not None:
            material.name = f"mat{i}"
    scene.apply_transform(transform)
    text, textures = export_obj(scene, include_texture=True, return_texture=True, digits=10)
    path.write_text(text)
    for name, data in textures.items():
        (path.parent / name).write_bytes(data)
    return path


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    """tiny as GLB, as GLB translated to FAR (a node transform), and as z-up and y-up OBJ."""
    import trimesh

    d = tmp_path_factory.mktemp("meshes")
    glb = d / "tiny.glb"
    assert main(["scene", "export", "tiny", str(glb)]) == 0
    gltf_scene = trimesh.load(str(glb), force="scene", process=False)
    far = gltf_scene.copy()
    T = np.eye(4)
    T[:3, 3] = [FAR[0], FAR[2], -FAR[1]]  # glTF (x, y, z) is world (x, -z, y)
    far.apply_transform(T)
    far_glb = d / "tiny_far.glb"
    far.export(str(far_glb))
    z_up = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # glTF -> world
    (d / "obj").mkdir()
    (d / "yup").mkdir()
    obj = _obj_from_scene(gltf_scene, d / "obj" / "tiny.obj", z_up)
    yup = _obj_from_scene(gltf_scene, d / "yup" / "tiny_yup.obj")
    return {"glb": glb, "far_glb": far_glb, "obj": obj, "yup": yup, "gltf_scene": gltf_scene, "z_up": z_up}


def _markers(out):
    return json.loads((out / "placement.json").read_text())["markers"]


# --- item 4: far from the origin ---------------------------------------------------------------------

def test_far_model_is_recentred_and_plans_like_at_the_origin(meshes, tmp_path):
    scene = load_scene(str(meshes["far_glb"]))
    offset = np.asarray(scene.meta["world_offset"])
    assert np.allclose(offset[:2], FAR[:2], atol=5) and offset[2] == 0.0
    near = load_scene(str(meshes["glb"]))
    assert np.allclose(scene.bounds + offset, near.bounds + FAR, atol=1e-4)  # float32 near the origin: exact
    outs = {}
    for name in ("glb", "far_glb"):
        outs[name] = tmp_path / name
        assert main(["plan", str(meshes[name]), "-k", "3", "--out", str(outs[name]), *FAST]) == 0
    a, b = _markers(outs["glb"]), _markers(outs["far_glb"])
    assert len(a) == len(b) == 3
    for ma, mb in zip(a, b):  # the same picks, reported in the file's (far) coordinates
        assert np.allclose(np.add(ma["position"], FAR), mb["position"], atol=2e-3), (ma["position"], mb["position"])
        assert np.allclose(ma["normal"], mb["normal"], atol=1e-3)
        Ta, Tb = np.array(ma["world_from_marker"]), np.array(mb["world_from_marker"])
        assert np.allclose(Ta[:3, 3] + FAR, Tb[:3, 3], atol=2e-3) and np.allclose(Ta[:3, :3], Tb[:3, :3], atol=1e-3)
    rows = list(csv.DictReader((outs["far_glb"] / "placement.csv").open()))
    x = float(rows[0]["x"])
    assert abs(x - b[0]["position"][0]) < 1e-3 and x > 0.9e6
    sa, sb = np.load(outs["glb"] / "scores.npz"), np.load(outs["far_glb"] / "scores.npz")
    assert np.allclose(sa["world_from_cam"][:, :3, 3] + FAR, sb["world_from_cam"][:, :3, 3], atol=2e-3)
    # the renders differ by float32 rounding of a (whole-metre) shifted frame: scores agree closely
    diff = np.abs(sa["score_before"] - sb["score_before"])
    assert diff.mean() < 0.05 and np.corrcoef(sa["score_before"], sb["score_before"])[0, 1] > 0.999, diff

    # inputs in file coordinates are moved in: the far plan's own markers are valid --existing
    existing = tmp_path / "existing.json"
    existing.write_text(json.dumps({"markers": b[:1]}))
    out = tmp_path / "far_existing"
    assert main(["plan", str(meshes["far_glb"]), "-k", "1", "--existing", str(existing), "--out", str(out), *FAST]) == 0
    assert _markers(out)[0]["position"] != b[0]["position"]
    eye = np.add(b[0]["position"], b[0]["normal"])  # 1 m in front of the first tag, looking at it
    yaw = np.degrees(np.arctan2(-b[0]["normal"][1], -b[0]["normal"][0]))
    pose = f"{eye[0]:.4f},{eye[1]:.4f},{eye[2]:.4f},{yaw:.1f}"
    assert main(["render", str(meshes["far_glb"]), "--pose", pose, "--out", str(tmp_path / "r" / "far")]) == 0
    assert (np.load(tmp_path / "r" / "far_depth.npy") > 0).mean() > 0.5


def test_far_obj_vertices_are_recentred_in_float64(meshes, tmp_path):
    T = np.eye(4)
    T[:3, 3] = FAR
    (tmp_path / "far").mkdir()
    far = _obj_from_scene(meshes["gltf_scene"], tmp_path / "far" / "tiny_far.obj", T @ meshes["z_up"])
    scene, near = load_scene(str(far)), load_scene(str(meshes["obj"]))
    offset = np.asarray(scene.meta["world_offset"])
    for p, q in zip(scene.parts, near.parts):  # no 1/16 m snapping: vertices equal to float32 rounding
        assert np.allclose(p.vertices.astype(float) + offset, q.vertices.astype(float) + FAR, atol=1e-5)


def test_models_near_the_origin_are_not_shifted(meshes):
    assert "world_offset" not in load_scene(str(meshes["glb"])).meta
    assert "world_offset" not in load_scene(str(meshes["obj"])).meta


# --- item 4: NaN / inf vertices ----------------------------------------------------------------------

def _append_bad_object(path, n_bad, n_faces_good=0):
    text = path.read_text()
    count = sum(1 for line in text.splitlines() if line.startswith("v "))
    bad = ["v nan 0 0", "v 1 inf 1", "v 2 2 -inf"] * n_bad
    faces = [f"f {count + 3 * i + 1} {count + 3 * i + 2} {count + 3 * i + 3}" for i in range(n_bad)]
    path.write_text(text + "\no broken\n" + "\n".join(bad) + "\n" + "\n".join(faces) + "\n")


def test_non_finite_vertices_are_dropped_with_a_count(meshes, tmp_path, caplog):
    import shutil

    folder = tmp_path / "nan"
    shutil.copytree(meshes["obj"].parent, folder)
    path = folder / "tiny.obj"
    _append_bad_object(path, 1)
    with caplog.at_level(logging.WARNING):
        scene = load_scene(str(path))
    assert "dropped 3 of" in caplog.text and "NaN or infinite" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        load_scene(str(path))  # loaded again by the next stage: not warned twice
    assert "dropped" not in caplog.text
    assert all(np.isfinite(p.vertices).all() for p in scene.parts)
    # what is left is exactly the clean model, so the plan is the clean model's plan
    assert cache.scene_hash(scene) == cache.scene_hash(load_scene(str(meshes["obj"])))


def test_mostly_non_finite_mesh_is_refused(tmp_path):
    path = tmp_path / "broken.obj"
    path.write_text("v 0 0 0\nv 4 0 0\nv 4 4 0\nv 0 4 3\nv nan 1 1\nv 1 nan 1\nf 1 2 3\nf 1 3 4\nf 1 5 6\n")
    with pytest.raises(UserError, match=r"2 of 6 vertices .* NaN or infinite"):
        load_scene(str(path))


def test_non_finite_node_transform_is_refused(meshes, tmp_path):
    import trimesh

    s = trimesh.load(str(meshes["glb"]), force="scene", process=False)
    T = np.eye(4)
    T[0, 3] = np.nan
    s.apply_transform(T)
    path = tmp_path / "nan_node.glb"
    s.export(str(path))
    with pytest.raises(UserError, match="NaN or infinite"):
        load_scene(str(path))


# --- item 4: up axis -----------------------------------------------------------------------------------

def test_wrong_up_axis_warns_naming_the_right_one(meshes, caplog):
    with caplog.at_level(logging.WARNING):
        load_scene(str(meshes["yup"]))  # a y-up OBJ read with the default --up z
    warnings = [r.getMessage() for r in caplog.records if "--up" in r.getMessage()]
    assert len(warnings) == 1 and "pass --up y" in warnings[0] and "\n" not in warnings[0]
    caplog.clear()
    with caplog.at_level(logging.WARNING):
        scene = load_scene(str(meshes["yup"]), up="y")
        load_scene(str(meshes["obj"]))
        load_scene(str(meshes["glb"]))
    assert "--up" not in caplog.text
    assert np.allclose(scene.bounds, load_scene(str(meshes["obj"])).bounds, atol=1e-4)


@pytest.mark.parametrize("name", ["tiny", "room", "office", "studio", "apartment"])
def test_up_axis_scores_prefer_z_on_builtins(name):
    from markerplace.scene.sanity import up_axis_scores

    scores = up_axis_scores(*load_scene(name).geometry())
    assert max(scores, key=lambda k: scores[k][0]) == "+z"
    assert all(scores[k][0] < 0.5 * scores["+z"][0] for k in ("+x", "-x", "+y", "-y"))


def test_up_axis_is_told_by_the_floors_not_by_a_pit_below_them():
    """A multi-level model's lowest vertex is often a pit, a shaft or a stairwell's bottom (a
    third-party game level: a 1 m^2 pit 5 m below the main floor). The floor the up axis is
    judged by is the lowest one covering 10 % of the footprint, so +z still wins clearly."""
    from markerplace.scene.sanity import up_axis_scores

    V, F = (np.asarray(a) for a in load_scene("tiny").geometry())
    x0, y0 = V[:, 0].min() + 1.0, V[:, 1].min() + 1.0
    pit = np.array([[x0, y0, -5.0], [x0 + 1, y0, -5.0], [x0 + 1, y0 + 1, -5.0], [x0, y0 + 1, -5.0]])
    V2 = np.vstack([V, pit])
    F2 = np.vstack([F, len(V) + np.array([[0, 1, 2], [0, 2, 3]])])  # its bottom faces up
    scores = up_axis_scores(V2, F2)
    assert max(scores, key=lambda k: scores[k][0]) == "+z"
    assert scores["+z"][0] == pytest.approx(up_axis_scores(V, F)["+z"][0], rel=0.05)
    assert all(scores[k][0] < 0.5 * scores["+z"][0] for k in ("+x", "-x", "+y", "-y"))


# --- item 5: --existing off the walls ----------------------------------------------------------------

@pytest.mark.parametrize("marker, message", [
    ({"tag_id": 7, "size": 0.4, "position": [1.8, 1.8, 1.5], "normal": [1, 0, 0]}, "tag 7 at (1.80, 1.80, 1.50) is not on a wall"),
    ({"tag_id": 8, "size": 0.4, "position": [500, 500, 1.5], "normal": [1, 0, 0]}, "tag 8 at (500.00, 500.00, 1.50) is not on a wall"),
    ({"tag_id": 9, "size": 0.4, "world_from_marker": [[0, -0.8, 0.6, 0.05], [1, 0, 0, 0.9], [0, 0.6, 0.8, 1.5], [0, 0, 0, 1]]},
     "tag 9 at (0.05, 0.90, 1.50) has normal (0.60, 0.00, 0.80), not horizontal"),
])
def test_existing_marker_off_the_walls_stops_the_run(marker, message, tmp_path, capsys, monkeypatch):
    import markerplace.pipelines.plan

    monkeypatch.setattr(markerplace.pipelines.plan, "prepare", lambda *a, **k: pytest.fail("prepare ran"))
    path = tmp_path / "existing.json"
    path.write_text(json.dumps({"markers": [marker]}))
    assert main(["plan", "tiny", "-k", "1", "--existing", str(path), "--out", str(tmp_path / "o"), *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and str(path) in err[0], err


def test_existing_marker_facing_into_the_wall_is_refused():
    from markerplace.markers import check_markers_on_walls, marker_from_json

    scene = load_scene("tiny")
    # tiny's west wall is 10 cm thick, its inner face at x = 0.05 (a picture hangs at 1.5 <= y <= 2.1)
    good = marker_from_json({"tag_id": 1, "position": [0.05, 0.9, 1.5], "normal": [1, 0, 0]})
    on_picture = marker_from_json({"tag_id": 4, "position": [0.092, 1.8, 1.5], "normal": [1, 0, 0]})
    check_markers_on_walls(scene, [good, on_picture])
    flipped = marker_from_json({"tag_id": 2, "position": [0.05, 0.9, 1.5], "normal": [-1, 0, 0]})
    with pytest.raises(UserError, match="tag 2 .* faces into the wall"):
        check_markers_on_walls(scene, [flipped])
    behind = marker_from_json({"tag_id": 3, "position": [0.12, 0.9, 1.5], "normal": [1, 0, 0]})  # 7 cm off
    with pytest.raises(UserError, match="tag 3 .* not on a wall"):
        check_markers_on_walls(scene, [behind])


# --- item 6: non-UTF-8 text ---------------------------------------------------------------------------

def test_obj_with_latin1_comment_loads(meshes, tmp_path):
    import shutil

    folder = tmp_path / "latin1"
    shutil.copytree(meshes["obj"].parent, folder)
    path = folder / "tiny.obj"
    path.write_bytes("# exporté par un café, 3° étage\n".encode("latin-1") + path.read_bytes())
    scene = load_scene(str(path))  # trimesh needs charset-normalizer to decode this
    assert cache.scene_hash(scene) == cache.scene_hash(load_scene(str(meshes["obj"])))


# --- item 7: missing texture, missing --placements ------------------------------------------------

def test_gltf_missing_texture_is_named(tmp_path, caplog):
    path = gltf_with_texture_uri(tmp_path / "room.gltf", "textures/wall_paint.png")
    with caplog.at_level(logging.WARNING):
        load_scene(str(path))
    named = [r.getMessage() for r in caplog.records if "textures/wall_paint.png" in r.getMessage()]
    assert len(named) == 1 and str(path) in named[0]
    caplog.clear()
    (tmp_path / "textures").mkdir()
    from PIL import Image

    Image.new("RGB", (8, 8), (200, 30, 30)).save(tmp_path / "textures" / "wall_paint.png")
    with caplog.at_level(logging.WARNING):
        scene = load_scene(str(path))
    assert "not found" not in caplog.text and scene.parts[0].texture is not None


def test_obj_missing_texture_is_named(meshes, tmp_path, caplog):
    import shutil

    folder = tmp_path / "notex"
    shutil.copytree(meshes["obj"].parent, folder)
    gone = sorted(folder.glob("*.png"))[0]
    gone.unlink()
    with caplog.at_level(logging.WARNING):
        load_scene(str(folder / "tiny.obj"))
    assert gone.name in caplog.text


@pytest.mark.parametrize("make", ["missing", "empty", "malformed"])
def test_evaluate_checks_placements_before_any_work(make, tmp_path, capsys, monkeypatch):
    import markerplace.pipelines.evaluate
    import markerplace.pipelines.plan

    monkeypatch.setattr(markerplace.pipelines.plan, "prepare", lambda *a, **k: pytest.fail("prepare ran"))
    monkeypatch.setattr(markerplace.pipelines.evaluate, "run_evaluation", lambda *a, **k: pytest.fail("evaluation ran"))
    folder = tmp_path / "placements"
    if make != "missing":
        folder.mkdir()
    if make == "malformed":
        (folder / "mine").mkdir()
        (folder / "mine" / "placement.json").write_text('{"markers": [{"tag_id": 1}]}')
    code = main(["evaluate", "tiny", "--out", str(tmp_path / "e"), "--placements", str(folder), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "markerplace: error:" in err[0] and str(folder) in err[0], err
    assert not (tmp_path / "e").exists()
