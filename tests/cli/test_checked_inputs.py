"""Checked inputs everywhere (issue 35, item 5): argument errors, tag ids, poses, JSON depth and
size, cluster addresses (with silent and garbage servers on 127.0.0.1), ``-k`` against the
candidates right after discretize, and the issue's minor list. Each bad input ends in ONE line
``markerplace: error: ...`` with exit code 2, before the expensive work.
"""

from __future__ import annotations

import argparse
import json
import re
import time
from pathlib import Path

import numpy as np
import pytest

from helpers import FAST_2_YAWS as FAST
from helpers.loopback import LoopbackServer
from helpers.obj_files import latin1_room
from markerplace.cli.main import OneLineParser, build_parser, main
from markerplace.errors import UserError
from markerplace.jsonfile import json_depth, read_json
from markerplace.markers import load_markers

GOOD = {"tag_id": 3, "size": 0.4, "position": [1.0, 2.0, 1.5], "normal": [1.0, 0.0, 0.0]}


def _code(argv) -> int:
    try:
        return main(argv)
    except SystemExit as exc:  # argparse's errors end the parse by SystemExit(2)
        return exc.code


def _one_line(capsys, code: int, needle: str = "") -> str:
    err = capsys.readouterr().err
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and lines[0].startswith("markerplace: error: "), (code, err)
    assert needle in lines[0], (needle, lines[0])
    assert "Traceback" not in err and "usage:" not in err
    return lines[0]


@pytest.fixture(autouse=True)
def _fresh_log():
    """The CLI's logger as a fresh process has it (set up by main()), restored afterwards."""
    import logging

    logger = logging.getLogger("markerplace")
    saved = logger.handlers[:], logger.level, logger.propagate
    logger.handlers.clear()
    yield
    logger.handlers[:], logger.level, logger.propagate = saved


# --- argument errors: one line ---------------------------------------------------------------------


def test_every_parser_and_subparser_prints_one_line():
    def walk(p):
        yield p
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for sub in a.choices.values():
                    yield from walk(sub)

    parsers = list(walk(build_parser()))
    assert len(parsers) >= 10 and all(isinstance(p, OneLineParser) for p in parsers)


@pytest.mark.parametrize("argv, needle", [
    (["plan"], "required: --out"),  # the scene may be left out for --frames DIR (then it is refused with one line)
    (["plan", "tiny"], "required: --out"),
    (["plan", "tiny", "--out"], "expected one argument"),
    (["plan", "tiny", "--out", "x", "-k", "abc"], "invalid int value"),
    (["plan", "tiny", "--out", "x", "--method", "best"], "invalid choice"),
    (["plan", "tiny", "--out", "x", "--bogus"], "unrecognized arguments: --bogus"),
    (["evaluate", "tiny", "--out", "x", "--tests", "nan"], "invalid int value"),
    (["render", "tiny", "--out", "x", "--width", "1.5"], "invalid int value"),
    (["study", "tiny"], "required: --out"),
    (["scene", "export"], "required: name, out"),
    (["scene", "bogus"], "invalid choice"),
    (["fuse"], "required"),
    (["check"], "required"),
    (["export"], "required"),
    (["bogus-command"], "invalid choice"),
])
def test_argument_errors_are_one_line(argv, needle, capsys):
    line = _one_line(capsys, _code(argv), needle)
    assert "--help" in line  # says where the options are listed


@pytest.mark.parametrize("command", ["evaluate", "study"])
@pytest.mark.parametrize("k", ["1,,2", ",3", "4,", " , "])
def test_k_lists_with_an_empty_item_are_refused(command, k, tmp_path, capsys):
    _one_line(capsys, _code([command, "tiny", "--out", str(tmp_path / "o"), f"--k={k}", "--quiet"]), "--k")


# --- tag ids, poses, marker files ------------------------------------------------------------------


def _marker_file(tmp_path, entries, name="m.json") -> Path:
    path = tmp_path / name
    path.write_text(entries if isinstance(entries, str) else json.dumps({"markers": entries}))
    return path


@pytest.mark.parametrize("tag_id, needle", [
    (-1, "outside tag36h11 (0..586)"), (587, "outside tag36h11 (0..586)"), (1.5, "not an integer"),
    (True, "not an integer"), ("3", "not an integer"), (None, "not an integer"), (3.0, "not an integer"),
])
def test_tag_ids_must_be_integers_of_the_family(tag_id, needle, tmp_path):
    with pytest.raises(UserError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        load_markers(_marker_file(tmp_path, [{**GOOD, "tag_id": tag_id}]))


def test_tag_id_1e30_and_duplicates_are_refused(tmp_path):
    with pytest.raises(UserError, match="not an integer"):
        load_markers(_marker_file(tmp_path, '[{"tag_id": 1e30, "position": [1, 2, 1.5], "normal": [1, 0, 0]}]'))
    with pytest.raises(UserError, match="tag id 3 is listed twice"):
        load_markers(_marker_file(tmp_path, [GOOD, {**GOOD, "position": [3.0, 2.0, 1.5]}]))
    assert [m.tag_id for m in load_markers(_marker_file(tmp_path, [GOOD, {**GOOD, "tag_id": 586}]))] == [3, 586]


def _T(R=np.eye(3), t=(1.0, 2.0, 1.5), last=(0, 0, 0, 1)):
    T = np.eye(4)
    T[:3, :3], T[:3, 3], T[3] = R, t, last
    return T.tolist()


ROT_Z30 = np.array([[np.cos(0.5), -np.sin(0.5), 0], [np.sin(0.5), np.cos(0.5), 0], [0, 0, 1]])


@pytest.mark.parametrize("entry, needle", [
    ('{"tag_id": 1, "position": [NaN, 2, 1.5], "normal": [1, 0, 0]}', "NaN or infinite"),
    ('{"tag_id": 1, "position": [1, 2, Infinity], "normal": [1, 0, 0]}', "NaN or infinite"),
    ('{"tag_id": 1, "position": [1, 2, 1e400], "normal": [1, 0, 0]}', "NaN or infinite"),
    ('{"tag_id": 1, "position": ["1", "2", "3"], "normal": [1, 0, 0]}', "must be 3 numbers"),
    ('{"tag_id": 1, "position": [1, 2, 1.5], "normal": [0, 0, 1]}', "zero or vertical"),
    ('{"tag_id": 1, "position": [1, 2, 1.5], "normal": [0, 0, 0]}', "zero or vertical"),
    ('{"tag_id": 1, "size": true, "position": [1, 2, 1.5], "normal": [1, 0, 0]}', "not a number of metres"),
    (json.dumps({"tag_id": 1, "world_from_marker": _T(2 * np.eye(3))}), "not orthonormal"),
    (json.dumps({"tag_id": 1, "world_from_marker": _T(np.array([[1, 0.2, 0], [0, 1, 0], [0, 0, 1]]))}),
     "not orthonormal"),
    (json.dumps({"tag_id": 1, "world_from_marker": _T(np.diag([-1.0, 1, 1]))}), "determinant -1"),
    (json.dumps({"tag_id": 1, "world_from_marker": _T(last=(0, 0, 1, 1))}), "last row"),
    ('{"tag_id": 1, "world_from_marker": [[NaN, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}',
     "NaN or infinite"),
])
def test_poses_must_be_finite_and_rigid(entry, needle, tmp_path):
    with pytest.raises(UserError, match=needle):
        load_markers(_marker_file(tmp_path, f"[{entry}]"))


def test_a_rotated_pose_within_tolerance_is_read(tmp_path):
    R = ROT_Z30 @ np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0.0]])
    R_noisy = R + 1e-5  # a 5-digit export
    (m,) = load_markers(_marker_file(tmp_path, json.dumps([{"tag_id": 1, "world_from_marker": _T(R_noisy)}])))
    assert np.allclose(m.world_from_marker[:3, :3], R_noisy)


def test_cli_refuses_bad_tag_ids_before_loading_the_scene(tmp_path, capsys):
    existing = _marker_file(tmp_path, [{**GOOD, "tag_id": 1.5}])
    t0 = time.perf_counter()
    code = _code(["plan", "tiny", "-k", "2", "--out", str(tmp_path / "p"), "--existing", str(existing), *FAST])
    _one_line(capsys, code, "--existing")
    assert time.perf_counter() - t0 < 5 and not (tmp_path / "p").exists()


def test_render_refuses_a_nan_marker_pose(tmp_path, capsys):
    bad = _marker_file(tmp_path, '[{"tag_id": 1, "position": [1, 1, NaN], "normal": [1, 0, 0]}]')
    _one_line(capsys, _code(["render", "tiny", "--markers", str(bad), "--out", str(tmp_path / "v")]), "NaN or infinite")
    assert not list(tmp_path.glob("v_*"))


def test_more_tags_than_the_family_has_are_refused(tmp_path, capsys):
    existing = _marker_file(tmp_path, [{**GOOD, "tag_id": i} for i in (0, 1)])
    _one_line(capsys, _code(["plan", "tiny", "-k", "586", "--out", str(tmp_path / "p"), "--existing", str(existing),
                             *FAST]), "at most 585 new tags")
    _one_line(capsys, _code(["evaluate", "tiny", "--k", "5,600", "--out", str(tmp_path / "e"), *FAST]),
              "tag36h11 has 587 ids")


# --- JSON guards --------------------------------------------------------------------------------------


def test_json_depth_ignores_brackets_in_strings():
    assert json_depth(b'{"a": "[[[\\"[[{{", "b": [[1]]}') == 3
    assert json_depth(b"3") == 0 and json_depth(b"[" * 1000) == 1000


@pytest.mark.parametrize("option", ["--existing", "--markers", "--installed"])
def test_deep_json_is_one_line_not_a_recursion_error(option, tmp_path, capsys):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000)
    if option == "--installed":  # check reads the installed tags with the same reader
        from markerplace.pipelines.check import load_installed

        with pytest.raises(UserError, match="100000 deep"):
            load_installed(deep, 0.4)
        return
    argv = (["plan", "tiny", "-k", "2", "--out", str(tmp_path / "p"), "--existing", str(deep), *FAST]
            if option == "--existing" else ["render", "tiny", "--markers", str(deep), "--out", str(tmp_path / "v")])
    _one_line(capsys, _code(argv), "nests arrays/objects 100000 deep")


def test_json_size_encoding_and_folder_guards(tmp_path, monkeypatch):
    big = tmp_path / "big.json"
    big.write_text(json.dumps([GOOD] * 2000))
    with pytest.raises(UserError, match="MiB, more than"):
        read_json(big, max_bytes=1024)
    latin = tmp_path / "latin.json"
    latin.write_bytes('[{"name": "café"}]'.encode("latin-1"))
    with pytest.raises(UserError, match="not UTF-8"):
        read_json(latin)
    with pytest.raises(UserError, match="is a folder"):
        read_json(tmp_path)
    bom = tmp_path / "bom.json"
    bom.write_bytes(b"\xef\xbb\xbf" + json.dumps([GOOD]).encode())
    assert read_json(bom) == [GOOD]


# --- cluster addresses --------------------------------------------------------------------------------


@pytest.mark.parametrize("address, needle", [
    ("foo://x", "the scheme must be tcp:// or tls://"),
    ("127.0.0.1:8786", "the scheme must be tcp:// or tls://"),
    ("tcp://127.0.0.1", "HOST:PORT"),
    ("tcp://127.0.0.1:99999", "HOST:PORT"),
    ("local:0", "between 1 and"),
    ("local:100000", "between 1 and"),
    ("local:two", "whole number"),
])
def test_bad_cluster_addresses(address, needle, tmp_path, capsys):
    t0 = time.perf_counter()
    _one_line(capsys, _code(["plan", "tiny", "--out", str(tmp_path / "p"), "--cluster", address, "--quiet"]), needle)
    assert time.perf_counter() - t0 < 5


def test_workers_with_a_cluster_is_flagged(tmp_path, capsys):
    _one_line(capsys, _code(["plan", "tiny", "--out", str(tmp_path / "p"), "--cluster", "local:1", "--workers", "3"]),
              "--workers 3 has no effect with --cluster local:1")


@pytest.mark.parametrize("garbage, needle", [
    (False, "sent no Dask handshake within 1 s"),
    (True, "does not answer like a Dask scheduler"),
])
def test_silent_and_garbage_servers_are_one_line(garbage, needle, tmp_path, capsys, monkeypatch):
    from markerplace.runtime import cluster

    monkeypatch.setattr(cluster, "SCHEDULER_TIMEOUT_S", 1.0)
    with LoopbackServer(garbage) as server:
        t0 = time.perf_counter()
        code = _code(["plan", "tiny", "--out", str(tmp_path / "p"), "--cluster", server.address, "--quiet"])
        seconds = time.perf_counter() - t0
    _one_line(capsys, code, needle)
    assert seconds < 4, seconds


def test_a_real_dask_scheduler_passes_the_probe():
    from distributed import LocalCluster

    from markerplace.runtime.cluster import check_scheduler

    with LocalCluster(n_workers=0, processes=False, protocol="tcp", dashboard_address=":0") as cluster:
        check_scheduler(cluster.scheduler_address, timeout_s=5.0)  # no UserError


# --- -k against the candidates, right after discretize -----------------------------------------------


@pytest.mark.parametrize("command", ["plan", "evaluate", "study"])
def test_k_above_the_candidates_stops_before_observe(command, tmp_path, capsys):
    k = ["-k", "50"] if command == "plan" else ["--k", "50"]
    t0 = time.perf_counter()
    code = _code([command, "tiny", *k, "--out", str(tmp_path / "o"), *FAST])
    seconds = time.perf_counter() - t0
    _one_line(capsys, code, "candidate marker poses were found")
    assert not list(tmp_path.rglob("observations")) and not list(tmp_path.rglob("similarity.npz"))
    assert seconds < 20, seconds


# --- the minor list ---------------------------------------------------------------------------------


def test_empty_and_folder_meshes(tmp_path, capsys):
    (tmp_path / "empty.glb").write_bytes(b"")
    (tmp_path / "dir.glb").mkdir()
    _one_line(capsys, _code(["plan", str(tmp_path / "empty.glb"), "--out", str(tmp_path / "a"), *FAST]),
              "is empty (0 bytes)")
    _one_line(capsys, _code(["plan", str(tmp_path / "dir.glb"), "--out", str(tmp_path / "b"), *FAST]),
              "is a folder, not a mesh file")


def test_scene_export_refuses_a_name_that_is_not_glb(tmp_path, capsys):
    _one_line(capsys, _code(["scene", "export", "tiny", str(tmp_path / "x.txt")]), "must end in .glb")
    assert not (tmp_path / "x.txt").exists()


def test_latin1_material_names_keep_their_colours(tmp_path):
    from markerplace.scene.loader import load_mesh_file

    scene = load_mesh_file(latin1_room(tmp_path))
    colours = {p.name: tuple(round(c, 2) for c in p.base_color[:3]) for p in scene.parts}
    assert colours == {"Béton 3°": (0.6, 0.6, 0.6), "Plâtre": (0.9, 0.9, 0.9), "Bois": (0.5, 0.4, 0.3),
                       "Brique": (0.7, 0.2, 0.1)}


def test_files_outside_the_model_folder_are_named_without_trimesh_api(tmp_path, caplog):
    import logging

    from helpers.gltf import gltf_with_texture_uri
    from markerplace.scene import load_scene

    (tmp_path / "outside.png").write_bytes(b"\x89PNG")
    (tmp_path / "sub").mkdir()
    path = gltf_with_texture_uri(tmp_path / "sub" / "room.gltf", "../outside.png")
    with caplog.at_level(logging.WARNING):
        load_scene(str(path))
    text = " ".join(r.getMessage() for r in caplog.records)
    assert "outside the model's folder" in text and "../outside.png" in text and "FilePathResolver" not in text
    doc = json.loads(path.read_text())
    doc["buffers"][0]["uri"] = "../data.bin"  # the geometry itself outside: the model cannot be read
    (tmp_path / "data.bin").write_bytes(b"\x00" * doc["buffers"][0]["byteLength"])
    path.write_text(json.dumps(doc))
    with pytest.raises(UserError) as err:
        load_scene(str(path))
    assert "outside the model's folder" in str(err.value) and "FilePathResolver" not in str(err.value)


def test_tables_escape_names_the_user_chose():
    from markerplace.testbed.reporting.tables import method_table

    rows = [dict(scene="tiny|x", method=m, run=0, k=k, test_set="weighted", threshold="5cm/5deg", recall=0.5,
                 n_tests=10) for m, k in (("none", 0), ("omp", 2), ("<b>a|b</b>_c", 2))]
    md = method_table(rows, "weighted", "5cm/5deg", [2])
    assert "&lt;b&gt;a\\|b&lt;/b&gt;\\_c" in md and "tiny\\|x" in md and "<b>" not in md
    assert all(len(re.split(r"(?<!\\)\|", line)) == 5 for line in md.splitlines())  # three cells each


def test_every_hint_reads_right(tmp_path, capsys):
    code = _code(["fuse", str(tmp_path), "--out", str(tmp_path / "f.ply"), "--every", "0"])
    line = _one_line(capsys, code, "--every 0 must be at least 1")
    assert "give use" not in line
