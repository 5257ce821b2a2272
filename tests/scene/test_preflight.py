"""A mesh file checked before it is read (:mod:`markerplace.scene.preflight`, issue 50 item 3):
a file of zeros named like a mesh, a header claiming more than the file holds, a FIFO, a device
or a link loop is refused at once with one line; a model larger than the free memory is refused
naming ``--force``; a huge texture is downscaled with a warning naming it."""

from __future__ import annotations

import logging
import os
import struct
import time

import numpy as np
import pytest
import trimesh
from PIL import Image

from helpers.gltf import gltf_with_texture_uri
from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.jsonfile import read_json
from markerplace.scene import load_scene, preflight
from markerplace.scene.loader import load_mesh_file


def _error(spec) -> str:
    with pytest.raises(UserError) as info:
        load_scene(str(spec))
    msg = str(info.value)
    assert msg and "\n" not in msg
    return msg


def _room() -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=(4.0, 3.0, 2.6))
    m.apply_translation((2.0, 1.5, 1.3))
    return m


@pytest.mark.parametrize("ext, needle", [(".ply", "it does not start with 'ply'"),
                                         (".obj", "binary data (a NUL byte at 0)"),
                                         (".glb", "it does not start with 'glTF'"),
                                         (".gltf", "JSON text starting with '{'")])
def test_two_gib_of_zeros_named_like_a_mesh_is_refused_at_once(ext, needle, tmp_path):
    path = tmp_path / f"x{ext}"
    with open(path, "wb") as fh:
        fh.truncate(2 << 30)  # sparse: 2 GiB of zeros, no disk used
    t0 = time.perf_counter()
    msg = _error(path)
    assert time.perf_counter() - t0 < 2.0 and needle in msg and "is not a valid" in msg


def test_a_ply_claiming_more_than_it_holds_is_refused(tmp_path):
    path = tmp_path / "claims.ply"
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 100000000\nproperty float x\nproperty float y\n"
              "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")
    path.write_bytes(header.encode() + bytes(1000))
    assert "claims 100,000,000 vertex, 1 face, which need at least 1,200,000,001 bytes, but only 1,000" in _error(path)
    (tmp_path / "nohead.ply").write_bytes(b"ply\nformat ascii 1.0\n" + b"comment x\n" * 8000)
    assert "no end_header in its first 64 KiB" in _error(tmp_path / "nohead.ply")


@pytest.mark.parametrize("encoding", ["binary", "ascii"])
def test_a_valid_ply_passes_its_header_check_to_the_byte(encoding, tmp_path):
    path = tmp_path / "room.ply"
    _room().export(str(path), encoding=encoding)
    if encoding == "ascii":  # no separator after the last row: still enough bytes
        path.write_bytes(path.read_bytes().rstrip())
    assert preflight.check_header(path, ".ply") == ("binary" if encoding == "binary" else "ascii ply")
    assert load_mesh_file(path).num_faces == 12


def test_a_truncated_glb_and_a_text_file_named_obj_are_refused(tmp_path):
    good = tmp_path / "room.glb"
    _room().export(str(good))
    assert preflight.check_header(good, ".glb") == "binary"
    cut = tmp_path / "cut.glb"
    cut.write_bytes(good.read_bytes()[: good.stat().st_size // 2])
    assert "its header says" in _error(cut) and "(truncated?)" in _error(cut)
    bad = tmp_path / "chunk.glb"
    data = bytearray(good.read_bytes())
    struct.pack_into("<I", data, 16, 0x12345678)  # the first chunk is no JSON chunk
    bad.write_bytes(bytes(data))
    assert "first chunk is not a JSON chunk" in _error(bad)
    notes = tmp_path / "notes.obj"
    notes.write_text("Dear team,\nhere are the notes of the meeting.\n")
    assert "no OBJ statement (v, f, o, ...)" in _error(notes)


@pytest.mark.parametrize("kind, needle", [("fifo", "is a named pipe (FIFO), not a file"),
                                          ("loop", "is a symbolic link loop"),
                                          ("dangling", "is a symbolic link to nowhere.ply, which does not exist"),
                                          ("device", "is a device, not a file")])
def test_a_fifo_a_device_or_a_link_loop_is_named_not_missing(kind, needle, tmp_path, capsys):
    path = tmp_path / "model.ply"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "loop":
        path.symlink_to(path.name)
    elif kind == "dangling":
        path.symlink_to("nowhere.ply")
    else:
        path.symlink_to("/dev/zero")
    msg = _error(path)
    assert needle in msg and "no such file" not in msg
    assert main(["render", str(path), "--out", str(tmp_path / "v")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and needle in err
    assert "no such file" not in _error("/dev/zero") and "is a device" in _error("/dev/zero")


def test_json_inputs_name_a_fifo_too(tmp_path):
    os.mkfifo(tmp_path / "markers.json")
    with pytest.raises(UserError, match="is a named pipe"):
        read_json(tmp_path / "markers.json", "--existing markers.json")


def test_a_model_larger_than_the_free_memory_is_refused_unless_forced(tmp_path, monkeypatch, caplog):
    path = tmp_path / "room.glb"
    _room().export(str(path))
    monkeypatch.setattr(preflight, "available_memory_bytes", lambda: 50e6)
    msg = _error(path)
    assert "loading it needs about 0.1 GiB of memory" in msg and "more than the 0.0 GiB free now" in msg
    assert "pass --force" in msg
    try:
        preflight.allow_large_models(True)
        with caplog.at_level(logging.WARNING, logger="markerplace"):
            assert load_mesh_file(path).num_faces == 12
    finally:
        preflight.allow_large_models(False)
    assert any("going on because of --force" in r.getMessage() for r in caplog.records)


def test_the_memory_estimate_grows_with_the_mesh_and_its_textures(tmp_path):
    path = tmp_path / "room.glb"
    _room().export(str(path))
    small = preflight.check_memory(path, "binary", [])
    big = preflight.check_memory(path, "binary", [preflight.Texture("t.png", 8192, 8192)])
    assert big - small == pytest.approx(preflight.BYTES_PER_TEXEL * 8192**2)
    assert small == pytest.approx(preflight.BASE_LOAD_BYTES + 20 * path.stat().st_size)


def test_a_texture_over_the_side_limit_is_downscaled_with_a_warning_naming_it(tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(preflight, "MAX_TEXTURE_SIDE", 64)
    rgb = (np.random.default_rng(0).random((100, 200, 3)) * 255).astype(np.uint8)
    Image.fromarray(rgb).save(tmp_path / "wall.png")
    path = gltf_with_texture_uri(tmp_path / "room.gltf", "wall.png")
    with caplog.at_level(logging.WARNING, logger="markerplace"):
        scene = load_mesh_file(path)
    texture = next(p.texture for p in scene.parts if p.texture is not None)
    assert texture.shape == (25, 50, 3)  # 200 px over a 64 px limit: every 4th pixel (ceil(200 / 64))
    text = " ".join(r.getMessage() for r in caplog.records)
    assert f"texture {tmp_path / 'wall.png'} is 200 x 100 pixels, more than 64 on a side: downscaled to 50 x 25" in text
    monkeypatch.setattr(preflight, "MAX_TEXTURE_PIXELS", 1000)
    msg = _error(path)
    assert f"texture {tmp_path / 'wall.png'} is 200 x 100 pixels" in msg and "shrink it" in msg


def test_glb_textures_are_sized_from_their_headers_and_named_when_downscaled(tmp_path, monkeypatch, caplog):
    from markerplace.scene.export import export_glb

    path = tmp_path / "tiny.glb"
    export_glb(load_scene("tiny"), path)
    sizes = preflight.texture_sizes(path, ".glb")
    loaded = load_mesh_file(path)
    assert {(t.height, t.width) for t in sizes} == {p.texture.shape[:2] for p in loaded.parts if p.texture is not None}
    assert all(t.stored > 0 and t.name.startswith("tiny.glb image ") for t in sizes)
    big = max(sizes, key=lambda t: max(t.width, t.height))
    monkeypatch.setattr(preflight, "MAX_TEXTURE_SIDE", max(big.width, big.height) - 1)
    with caplog.at_level(logging.WARNING, logger="markerplace"):
        scene = load_mesh_file(path)
    assert max(max(p.texture.shape[:2]) for p in scene.parts if p.texture is not None) < max(big.width, big.height)
    assert f"texture {big.name} is {big.width} x {big.height} pixels" in caplog.text
