"""Self-checking stage caches: a damaged, partial or unreadable artifact is recomputed with a
warning naming it, never a traceback (issue 13, item 1)."""

import json
import logging

import numpy as np
import pytest

from helpers import FAST
from markerplace.cli.main import main
from markerplace.runtime import cache


def test_mark_done_records_size_and_checksum(tmp_path):
    art = tmp_path / "a.bin"
    art.write_bytes(b"0123456789")
    cache.mark_done(art, "k1", note="x")
    meta = json.loads((tmp_path / "a.bin.meta.json").read_text())
    assert meta["key"] == "k1" and meta["size"] == 10 and len(meta["sha256"]) == 64 and meta["note"] == "x"
    assert cache.is_fresh(art, "k1")


@pytest.mark.parametrize("damage", ["truncate", "flip", "grow"])
def test_damaged_file_is_stale_with_a_warning_naming_it(tmp_path, caplog, damage):
    art = tmp_path / "a.bin"
    art.write_bytes(bytes(range(200)))
    cache.mark_done(art, "k")
    data = art.read_bytes()
    art.write_bytes({"truncate": data[:50], "flip": data[:-1] + b"\xff", "grow": data + b"x"}[damage])
    with caplog.at_level(logging.WARNING, logger="markerplace.runtime.cache"):
        assert not cache.is_fresh(art, "k")
    assert any(str(art) in r.getMessage() and "recomputing" in r.getMessage() for r in caplog.records)


def test_other_key_is_stale_silently(tmp_path, caplog):
    art = tmp_path / "a.bin"
    art.write_bytes(b"x")
    cache.mark_done(art, "k")
    with caplog.at_level(logging.WARNING):
        assert not cache.is_fresh(art, "other")
    assert not caplog.records


def test_meta_without_checksum_or_garbled_is_stale(tmp_path):
    art = tmp_path / "a.bin"
    art.write_bytes(b"x")
    (tmp_path / "a.bin.meta.json").write_text('{"key": "k"}')  # older versions wrote only the key
    assert not cache.is_fresh(art, "k")
    (tmp_path / "a.bin.meta.json").write_text('{"key": "k", "size"')
    assert not cache.is_fresh(art, "k")
    (tmp_path / "a.bin.meta.json").write_text("[1, 2]")
    assert not cache.is_fresh(art, "k")


def test_folder_artifact_checks_every_file(tmp_path, caplog):
    folder = tmp_path / "features"
    folder.mkdir()
    for name in ("a.npy", "b.npy"):
        np.save(folder / name, np.arange(100))
    cache.mark_done(folder, "k")
    assert (tmp_path / "features.meta.json").exists() and cache.is_fresh(folder, "k")
    (folder / "b.npy").write_bytes((folder / "b.npy").read_bytes()[:-8])
    with caplog.at_level(logging.WARNING, logger="markerplace.runtime.cache"):
        assert not cache.is_fresh(folder, "k")
    assert "b.npy" in caplog.text
    cache.mark_done(folder, "k")
    (folder / "a.npy").unlink()
    assert not cache.is_fresh(folder, "k")


def test_load_fresh_falls_back_when_loading_fails(tmp_path, caplog):
    art = tmp_path / "a.npz"
    art.write_bytes(b"not a zip file at all")
    cache.mark_done(art, "k")  # the checksum matches, but the bytes were never a valid npz
    with caplog.at_level(logging.WARNING, logger="markerplace.runtime.cache"):
        assert cache.load_fresh(art, "k", lambda p: np.load(p)["x"]) is None
    assert str(art) in caplog.text and "could not read" in caplog.text
    np.savez(art, x=np.arange(3))
    cache.mark_done(art, "k")
    assert cache.load_fresh(art, "k", lambda p: np.load(p)["x"]).tolist() == [0, 1, 2]
    assert cache.load_fresh(art, "other", lambda p: np.load(p)["x"]) is None


@pytest.fixture(scope="module")
def tiny_run(run_plan):
    out = run_plan(2, folder="cache")
    return out, json.loads((out / "placement.json").read_text())["markers"]


@pytest.mark.parametrize("artifact, damaged", [("discretization.npz", "discretization.npz"),
                                               ("observations", "observations/descriptors.npy"),
                                               ("similarity.npz", "similarity.npz")])
@pytest.mark.parametrize("damage", ["truncate", "garble"])
def test_damaged_stage_artifact_is_recomputed(tiny_run, artifact, damaged, damage, caplog, capsys):
    out, markers = tiny_run
    path = out / damaged
    data = path.read_bytes()
    if damage == "truncate":  # a full disk or an interrupted copy
        path.write_bytes(data[: len(data) // 2])
    else:  # same size, different bytes
        path.write_bytes(data[:16] + bytes(len(data) - 16))
    with caplog.at_level(logging.WARNING):
        assert main(["plan", "tiny", "-k", "2", "--out", str(out), *FAST]) == 0
    assert "Traceback" not in capsys.readouterr().err
    assert any(artifact in r.getMessage() and "recomputing" in r.getMessage() for r in caplog.records), caplog.text
    again = json.loads((out / "placement.json").read_text())["markers"]
    assert [m["position"] for m in again] == [m["position"] for m in markers]
    assert cache.is_fresh(out / artifact, json.loads((out / f"{artifact}.meta.json").read_text())["key"])
