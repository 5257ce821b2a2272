#!/usr/bin/env python
"""Re-run the bad inputs of issues 13, 35 and 50 as a new user would, through the real command line.

Every case runs ``python -m markerplace.cli ...`` in a subprocess and is judged on how it ends:

* ``error``: exit 2 and exactly one stderr line ``markerplace: error: ...`` containing the
  expected text (argument errors included: no argparse usage block);
* ``warn``: exit 0 with the expected warning on stderr;
* ``ok``: exit 0 (plus a check of the outputs where it matters);
* ``sigpipe``: exit 141 and nothing on stderr (standard output a pipe nobody reads, as ``| head -0``);
* ``interrupted``: the command is started in its own process group, and once its log shows the
  stage, SIGINT (or SIGTERM) goes to the whole group as a terminal's Ctrl-C does: exit 130 (143)
  within 5 s, one line saying how to resume, no traceback, no process of the group left
  (``tests/helpers/interrupts.py``).

Any traceback, any other exit code, a missing message, a run over its time limit or a failed
output check is reported. Prints one line per case and a summary; writes ``hostile_inputs.md``
into the work folder. Takes about 18 minutes on 2 cores (the probe group 10 of them). Usage::

    .venv/bin/python scripts/hostile_inputs.py [--workdir DIR] [--only SUBSTRING] [--group NAME]

Groups of cases: :func:`cases` (files, numbers, output paths, ``--existing``, damaged caches),
:func:`checked_input_cases` (tag ids, poses, JSON depth, cluster addresses with silent and
garbage servers on 127.0.0.1, ``-k`` against the candidates, argument errors, the minor list),
:func:`interrupt_cases` (Ctrl-C and SIGTERM at each stage), :func:`folder_cases` (run folders
and concurrency: the place for issue 35's items 1-3), :func:`issue50_cases` (files that are not
what their names say, stdout, encodings, resource limits, odd bookkeeping files, refusals before
any work, a plan folder's files checked against each other) and :func:`probe_cases` (``--group
probe``, 122 cases in about 10 minutes: the categories of issue 50's independent probe: a foreign
file or folder named like each output of plan, check, evaluate and study in an adopted folder, a
symlink out of the run folder under each output name, the manifest, marker and lock files edited,
odd ``--out`` paths, a full disk (a 256 kB tmpfs; skipped with its reason when it cannot be
mounted), a Dask scheduler without workers, TOML nesting, stdout full, closed or a broken pipe,
and a service account, uid 65534). A case whose set-up this machine cannot make is reported as
``SKIP`` with the reason. ``tests/e2e/test_hostile_script.py`` runs :data:`CHEAP_PROBE`, one
probe case of each kind.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from helpers.gltf import gltf_with_texture_uri  # noqa: E402
from helpers.interrupts import interrupt_cli  # noqa: E402  (tests/helpers: process-group signals, servers)
from helpers.loopback import LoopbackServer  # noqa: E402
from helpers.obj_files import latin1_room  # noqa: E402

FAST = ["--grid-spacing", "1.0", "--yaws", "4", "--workers", "1", "--quiet"]
FAR = np.array([1.0e6, 2.0e6, 0.0])


@dataclass
class Case:
    name: str
    argv: list[str]
    expect: str  # error | warn | ok | interrupted | sigpipe
    text: str = ""
    check: Callable[[], str | None] | None = None  # returns a problem or None
    setup: Callable[[], None] | None = None
    interrupt: tuple | None = None  # (log text to wait for, seconds more, signal) for "interrupted"
    extra: dict = field(default_factory=dict)


def cli(args: list[str], cwd: Path, timeout: float = 600):
    cmd = [sys.executable, "-m", "markerplace.cli", *args]
    t0 = time.perf_counter()
    res = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, timeout=timeout)
    return res.returncode, res.stdout, res.stderr, time.perf_counter() - t0


def without_root_powers(args: list[str]) -> list[str]:
    """argv prefix so that root cannot bypass file permissions (as an ordinary user)."""
    if os.geteuid() == 0 and shutil.which("setpriv"):
        return [shutil.which("setpriv"), "--inh-caps=-dac_override,-dac_read_search",
                "--bounding-set=-dac_override,-dac_read_search", "--"]
    return []


# --- fixtures -------------------------------------------------------------------------------------

def make_fixtures(w: Path) -> dict:
    import trimesh
    from trimesh.exchange.obj import export_obj

    f: dict = {}
    subprocess.run([sys.executable, "-m", "markerplace.cli", "scene", "export", "tiny", str(w / "tiny.glb")],
                   check=True, capture_output=True)
    f["glb"] = w / "tiny.glb"
    s = trimesh.load(str(f["glb"]), force="scene", process=False)
    for i, g in enumerate(s.geometry.values()):
        if getattr(g.visual, "material", None) is not None:
            g.visual.material.name = f"mat{i}"

    def obj(folder: str, transform=np.eye(4)) -> Path:
        d = w / folder
        d.mkdir(exist_ok=True)
        sc = s.copy()
        sc.apply_transform(transform)
        text, tex = export_obj(sc, include_texture=True, return_texture=True, digits=10)
        (d / "tiny.obj").write_text(text)
        for k, v in tex.items():
            (d / k).write_bytes(v)
        return d / "tiny.obj"

    z_up = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
    f["obj"] = obj("obj", z_up)
    f["yup"] = obj("yup")
    T = np.eye(4)
    T[:3, :3] = 100.0 * np.eye(3)
    f["cm"] = obj("cm", T @ z_up)
    T[:3, :3] = 0.001 * np.eye(3)
    f["tiny_mm"] = obj("mm", T @ z_up)
    far = s.copy()
    Tf = np.eye(4)
    Tf[:3, 3] = [FAR[0], FAR[2], -FAR[1]]
    far.apply_transform(Tf)
    far.export(str(w / "tiny_far.glb"))
    f["far"] = w / "tiny_far.glb"
    nan = obj("nan", z_up)
    text = nan.read_text()
    n = sum(1 for line in text.splitlines() if line.startswith("v "))
    nan.write_text(text + f"\no broken\nv nan 0 0\nv 1 inf 1\nv 2 2 -inf\nf {n + 1} {n + 2} {n + 3}\n")
    f["nan"] = nan
    (w / "mostly_nan.obj").write_text("v 0 0 0\nv 4 0 0\nv 4 4 0\nv 0 4 3\nv nan 1 1\nv 1 nan 1\n"
                                      "f 1 2 3\nf 1 3 4\nf 1 5 6\n")
    f["mostly_nan"] = w / "mostly_nan.obj"
    latin = obj("latin1", z_up)
    latin.write_bytes("# exporté, café, 3° étage\n".encode("latin-1") + latin.read_bytes())
    f["latin1"] = latin
    (w / "empty.obj").write_bytes(b"")
    (w / "corrupt.glb").write_bytes(os.urandom(2000))
    (w / "points.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                  "property float z\nend_header\n0 0 0\n1 0 0\n0 1 0\n")
    (w / "model.stl").write_text("solid x\nendsolid x\n")
    (w / "dir.glb").mkdir(exist_ok=True)
    gltf = w / "gltf"
    gltf.mkdir(exist_ok=True)

    f["gltf_missing"] = gltf_with_texture_uri(gltf / "room.gltf", "textures/wall.png")
    uni = w / "été ünïcode"
    uni.mkdir(exist_ok=True)
    shutil.copy(f["glb"], uni / "salle à manger.glb")
    f["unicode"] = uni / "salle à manger.glb"
    a_file = w / "a_file"
    a_file.write_text("x")
    f["a_file"] = a_file
    ro = w / "read_only"
    ro.mkdir(exist_ok=True)
    (ro / "plan").mkdir(exist_ok=True)
    for p in (ro / "plan", ro):
        p.chmod(0o555)
    f["ro"] = ro
    (w / "view_dir_rgb.png").mkdir(exist_ok=True)
    # a finished plan (caches, markers) to damage and reuse
    res = subprocess.run([sys.executable, "-m", "markerplace.cli", "plan", "tiny", "-k", "2", "--out",
                          str(w / "base_plan"), *FAST], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    f["base"] = w / "base_plan"
    markers = json.loads((w / "base_plan" / "placement.json").read_text())["markers"]
    f["markers"] = markers

    def marker_file(name, entries):
        p = w / name
        p.write_text(json.dumps({"markers": entries}))
        return p

    f["existing_ok"] = marker_file("existing_ok.json", markers[:1])
    f["existing_mid"] = marker_file("existing_mid.json", [{"tag_id": 7, "size": 0.4, "position": [1.8, 1.8, 1.5],
                                                            "normal": [1, 0, 0]}])
    f["existing_far"] = marker_file("existing_far.json", [{"tag_id": 8, "size": 0.4, "position": [500, 500, 1.5],
                                                            "normal": [1, 0, 0]}])
    flipped = dict(markers[0])
    flipped.pop("world_from_marker")
    flipped["normal"] = [-v for v in flipped["normal"]]
    f["existing_flipped"] = marker_file("existing_flipped.json", [flipped])
    (w / "existing_bad.json").write_text("{not json")
    f["existing_bad"] = w / "existing_bad.json"
    (w / "placements_empty").mkdir(exist_ok=True)
    # issue 35: hostile tag ids, poses and JSON
    good = {"size": 0.4, "position": [1.8, 0.1, 1.5], "normal": [0, 1, 0]}
    for name, tag_id in (("neg", -1), ("587", 587), ("1.5", 1.5), ("true", True), ("str", "3")):
        f[f"id_{name}"] = marker_file(f"id_{name}.json", [{**good, "tag_id": tag_id}])
    (w / "id_1e30.json").write_text('{"markers": [{"tag_id": 1e30, "position": [1.8, 0.1, 1.5], "normal": [0, 1, 0]}]}')
    f["id_1e30"] = w / "id_1e30.json"
    f["id_dup"] = marker_file("id_dup.json", [{**good, "tag_id": 4}, {**good, "tag_id": 4, "position": [2.5, 0.1, 1.5]}])
    nan_T = np.array(markers[0]["world_from_marker"], dtype=float)
    nan_T[0, 0] = np.nan
    (w / "pose_nan.json").write_text(json.dumps({"markers": [{**markers[0], "world_from_marker": nan_T.tolist()}]}))
    f["pose_nan"] = w / "pose_nan.json"
    scaled = np.array(markers[0]["world_from_marker"], dtype=float)
    scaled[:3, :3] *= 2.0
    f["pose_scaled"] = marker_file("pose_scaled.json", [{**markers[0], "world_from_marker": scaled.tolist()}])
    (w / "pos_nan.json").write_text('[{"tag_id": 1, "position": [1, 1, NaN], "normal": [1, 0, 0]}]')
    f["pos_nan"] = w / "pos_nan.json"
    (w / "deep.json").write_text("[" * 100_000)
    f["deep"] = w / "deep.json"
    (w / "empty.glb").write_bytes(b"")
    lat = w / "latin1_mtl"
    lat.mkdir(exist_ok=True)
    f["latin1_mtl"] = latin1_room(lat)
    issue50_fixtures(w, f)
    return f


def issue50_fixtures(w: Path, f: dict) -> None:
    """Issue 50's hostile files, all cheap (2 GiB of zeros as sparse files); the costly ones are
    made by their case's ``setup`` (:func:`issue50_cases`)."""
    for ext in (".ply", ".obj", ".glb", ".gltf"):
        f[f"zeros{ext}"] = w / f"zeros{ext}"
        with open(f[f"zeros{ext}"], "wb") as fh:
            fh.truncate(2 << 30)
    claims = w / "claims.ply"
    claims.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 100000000\nproperty float x\n"
                       b"property float y\nproperty float z\nend_header\n" + bytes(1000))
    f["claims"] = claims
    for name in ("fifo.ply", "fifo.json"):
        if not os.path.lexists(w / name):
            os.mkfifo(w / name)
    if not os.path.lexists(w / "loop.glb"):
        (w / "loop.glb").symlink_to("loop.glb")
    (w / "deep.toml").write_text("a = " + "[" * 3000 + "]" * 3000 + "\n")


def damage(path: Path, how: str) -> Callable[[], None]:
    def run():
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2] if how == "truncate" else data[:16] + bytes(len(data) - 16))
    return run


def positions_far(out: Path) -> Callable[[], str | None]:
    def check():
        m = json.loads((out / "placement.json").read_text())["markers"]
        p = np.array([x["position"] for x in m])
        ok = np.all(np.abs(p[:, 0] - FAR[0]) < 10) and np.all(np.abs(p[:, 1] - FAR[1]) < 10)
        return None if ok else f"positions not in file coordinates: {p.tolist()}"
    return check


def placement_exists(out: Path) -> Callable[[], str | None]:
    return lambda: None if (out / "placement.json").is_file() else "no placement.json"


def same_markers(out: Path, reference: Path) -> Callable[[], str | None]:
    """``out``'s placement.json places the same tags as ``reference``'s (a run with the same inputs alone)."""
    def check():
        if not (out / "placement.json").is_file():
            return "no placement.json"
        got, ref = (json.loads((d / "placement.json").read_text())["markers"] for d in (out, reference))
        key = lambda ms: [(m["tag_id"], [round(v, 6) for v in m["position"]]) for m in ms]  # noqa: E731
        return None if key(got) == key(ref) else f"a different plan than the same run alone: {key(got)} vs {key(ref)}"
    return check


def no_grey_warning(w: Path) -> Callable[[], str | None]:
    """The Latin-1 case: the last run's stderr must not report parts without a material colour."""
    return lambda: "material colours lost" if "no texture, vertex colours or material colour" in LAST_STDERR[0] else None


LAST_STDERR = [""]


# --- cases ------------------------------------------------------------------------------------------

def cases(w: Path, f: dict) -> list[Case]:
    o = lambda name: str(w / "out" / name)  # noqa: E731
    plan = lambda scene, name, *extra: ["plan", str(scene), "-k", "2", "--out", o(name), *FAST, *extra]  # noqa: E731
    ev = ["evaluate", "tiny", "--quiet"]
    c: list[Case] = [
        # scene files
        Case("missing mesh file", plan("nope.glb", "s1"), "error", "no such file"),
        Case("unknown extension", plan(w / "model.stl", "s2"), "error", "unknown scene format"),
        Case("unknown built-in name", plan("offfice", "s3"), "error", "unknown scene"),
        Case("empty OBJ", plan(w / "empty.obj", "s4"), "error", "is empty (0 bytes)"),
        Case("corrupt GLB", plan(w / "corrupt.glb", "s5"), "error", "could not read"),
        Case("point-cloud PLY", plan(w / "points.ply", "s6"), "error", "no triangle faces"),
        Case("a folder named .glb", plan(w / "dir.glb", "s7"), "error", "is a folder, not a mesh file"),
        Case("OBJ in cm without --unit-scale", plan(f["cm"], "s8"), "error", "pass --unit-scale (e.g. 0.01 for cm)"),
        Case("OBJ in mm scaled to 3 mm", plan(f["tiny_mm"], "s9"), "error", "too small"),
        Case("bad --up", plan(f["obj"], "s10", "--up", "w"), "error", "--up 'w' is not an axis"),
        Case("OBJ with NaN/inf vertices", plan(f["nan"], "s11"), "warn", "dropped 3 of"),
        Case("OBJ mostly NaN", plan(f["mostly_nan"], "s12"), "error", "NaN or infinite"),
        Case("y-up OBJ read as z-up", plan(f["yup"], "s13"), "warn", "pass --up y"),
        Case("y-up OBJ with --up y", plan(f["yup"], "s14", "--up", "y"), "ok", check=placement_exists(w / "out" / "s14")),
        Case("GLB at 1e6 m (survey coordinates)", plan(f["far"], "s15"), "ok", check=positions_far(w / "out" / "s15")),
        Case("OBJ with a Latin-1 comment", plan(f["latin1"], "s16"), "ok"),
        Case(".gltf with a missing texture", ["render", str(f["gltf_missing"]), "--out", o("s17/v")], "warn",
             "textures/wall.png"),
        Case("non-ASCII path", ["render", str(f["unicode"]), "--out", o("été/vue")], "ok"),
        Case("scene export of a mesh file (a conversion)", ["scene", "export", str(f["glb"]), o("s19.glb")], "ok"),
        # numbers: plan
        Case("--grid-spacing nan", plan("tiny", "n1", "--grid-spacing", "nan"), "error", "not a finite number"),
        Case("--grid-spacing 1e-4", plan("tiny", "n2", "--grid-spacing", "1e-4"), "error", "outside [0.05, 50] m"),
        Case("--grid-spacing 0.01", plan("tiny", "n3", "--grid-spacing", "0.01"), "error", "outside [0.05, 50] m"),
        Case("--grid-spacing -1", plan("tiny", "n4", "--grid-spacing=-1"), "error", "outside"),
        Case("--grid-spacing inf", plan("tiny", "n5", "--grid-spacing", "inf"), "error", "not a finite number"),
        Case("--grid-spacing 0", plan("tiny", "n6", "--grid-spacing", "0"), "error", "--grid-spacing 0 m"),
        Case("--marker-spacing nan", plan("tiny", "n7", "--marker-spacing", "nan"), "error", "not a finite number"),
        Case("--marker-spacing 0", plan("tiny", "n8", "--marker-spacing", "0"), "error", "--marker-spacing"),
        Case("--clearance -1", plan("tiny", "n9", "--clearance=-1"), "error", "--clearance"),
        Case("--clearance nan", plan("tiny", "n10", "--clearance", "nan"), "error", "not a finite number"),
        Case("--height nan", plan("tiny", "n11", "--height", "nan"), "error", "not a finite number"),
        Case("--height 100", plan("tiny", "n12", "--height", "100"), "error", "--height 100 m is outside"),
        Case("--yaws 0", plan("tiny", "n13", "--yaws", "0"), "error", "--yaws 0 must be at least 1"),
        Case("--yaws 10^20", plan("tiny", "n14", "--yaws", "1" + "0" * 20), "error", "must be at most 360"),
        Case("-k 0", plan("tiny", "n15", "-k", "0"), "error", "-k 0 must be at least 1"),
        Case("-k 10^20", plan("tiny", "n16", "-k", "1" + "0" * 20), "error", "must be at most 10000"),
        Case("-k 500 (more than candidates)", plan("tiny", "n17", "-k", "500"), "error", "candidate marker poses",
             extra={"max_seconds": 15}),
        Case("-v nan", plan("tiny", "n18", "-v", "nan"), "error", "not a finite number"),
        Case("-v 150", plan("tiny", "n19", "-v", "150"), "error", "outside [0, 100]"),
        Case("--tag-size 0", plan("tiny", "n20", "--tag-size", "0"), "error", "--tag-size 0 m is outside"),
        Case("--tag-size nan", plan("tiny", "n21", "--tag-size", "nan"), "error", "not a finite number"),
        Case("--level 99999", plan("tiny", "n22", "--level", "99999"), "error", "at most 1000"),
        Case("--level 3 (one storey)", plan("tiny", "n23", "--level", "3"), "error", "--level"),
        Case("--workers -1", plan("tiny", "n24", "--workers=-1"), "error", "--workers -1 must be at least 0"),
        Case("--workers 100000", plan("tiny", "n25", "--workers", "100000"), "error", "at most 256"),
        Case("--placement-seed -1", plan("tiny", "n26", "--placement-seed=-1", "--method", "random"), "error",
             "must be at least 0"),
        Case("--seed -1", plan("tiny", "n27", "--seed=-1"), "error", "--seed -1 must be at least 0"),
        Case("--start nan,1", plan("tiny", "n28", "--start", "nan,1"), "error", "X = nan"),
        Case("--start 1,2,3", plan("tiny", "n29", "--start", "1,2,3"), "error", "must be X,Y"),
        Case("--start 100,100 (outside)", plan("tiny", "n30", "--start", "100,100"), "error", "--start"),
        Case("--unit-scale nan", plan(f["obj"], "n31", "--unit-scale", "nan"), "error", "not a finite number"),
        Case("--unit-scale 0", plan(f["obj"], "n32", "--unit-scale", "0"), "error", "--unit-scale 0 is outside"),
        Case("size guard: office at 0.05 m", ["plan", "office", "--grid-spacing", "0.05", "--out", o("n33"), "--quiet"],
             "error", "--force"),
        # numbers: render
        Case("render --pose nan,1,1.5,0", ["render", "tiny", "--pose", "nan,1,1.5,0", "--out", o("r1/v")], "error", "X = nan"),
        Case("render --pose outside the model", ["render", "tiny", "--pose", "50,50,1.5,0", "--out", o("r2/v")], "error",
             "outside the model"),
        Case("render --pose with 3 numbers", ["render", "tiny", "--pose", "1,1,1.5", "--out", o("r3/v")], "error", "X,Y,Z,YAW_DEG"),
        Case("render --pose yaw inf", ["render", "tiny", "--pose", "1,1,1.5,inf", "--out", o("r4/v")], "error", "YAW_DEG = inf"),
        Case("render --width 0", ["render", "tiny", "--width", "0", "--out", o("r5/v")], "error", "--width 0"),
        Case("render --width 100000", ["render", "tiny", "--width", "100000", "--out", o("r6/v")], "error", "at most 4096"),
        Case("render --hfov 180", ["render", "tiny", "--hfov", "180", "--out", o("r7/v")], "error", "--hfov 180"),
        Case("render --hfov nan", ["render", "tiny", "--hfov", "nan", "--out", o("r8/v")], "error", "not a finite number"),
        # numbers and inputs: evaluate
        Case("evaluate --tests 0", [*ev, "--out", o("e1"), "--tests", "0"], "error", "--tests 0 must be at least 1"),
        Case("evaluate --tests nan", [*ev, "--out", o("e2"), "--tests", "nan"], "error", "invalid int value"),
        Case("evaluate --k 5,a", [*ev, "--out", o("e3"), "--k", "5,a"], "error", "comma-separated list of integers"),
        Case("evaluate --k 0", [*ev, "--out", o("e4"), "--k", "0"], "error", "--k 0 must be at least 1"),
        Case("evaluate --tag-scale nan", [*ev, "--out", o("e5"), "--tag-scale", "nan"], "error", "not a finite number"),
        Case("evaluate --shift -1", [*ev, "--out", o("e6"), "--shift=-1"], "error", "--shift -1 m is outside"),
        Case("evaluate --runs 0", [*ev, "--out", o("e7"), "--runs", "0"], "error", "--runs 0"),
        Case("evaluate --test-seed -1", [*ev, "--out", o("e8"), "--test-seed=-1"], "error", "must be at least 0"),
        Case("evaluate --methods best", [*ev, "--out", o("e9"), "--methods", "best"], "error", "--methods"),
        Case("evaluate --test-sets hard", [*ev, "--out", o("e10"), "--test-sets", "hard"], "error", "--test-sets"),
        Case("evaluate --placements /nonexistent", [*ev, "--out", o("e11"), "--placements", "/nonexistent"], "error",
             "is not a directory", extra={"max_seconds": 10}),
        Case("evaluate --placements (empty folder)", [*ev, "--out", o("e12"), "--placements", str(w / "placements_empty")],
             "error", "holds no placement.json", extra={"max_seconds": 10}),
        # output folders
        Case("plan --out an existing file", plan("tiny", "x", "--out", str(f["a_file"])), "error", "is an existing file"),
        Case("plan --out under a file", plan("tiny", "x", "--out", str(f["a_file"] / "sub")), "error", "is a file"),
        Case("plan --out read-only folder", plan("tiny", "x", "--out", str(f["ro"] / "plan")), "error",
             "cannot write there", extra={"no_root": True}),
        Case("render --out under a file", ["render", "tiny", "--out", str(f["a_file"] / "v")], "error", "is a file"),
        Case("render --out in a read-only folder", ["render", "tiny", "--out", str(f["ro"] / "v")], "error",
             "cannot write there", extra={"no_root": True}),
        Case("render --out PREFIX_rgb.png is a folder", ["render", "tiny", "--out", str(w / "view_dir")], "error",
             "is an existing folder"),
        Case("scene export under a file", ["scene", "export", "tiny", str(f["a_file"] / "t.glb")], "error", "is a file"),
        Case("scene export into a read-only folder", ["scene", "export", "tiny", str(f["ro"] / "t.glb")], "error",
             "cannot write there", extra={"no_root": True}),
        Case("scene export OUT is a folder", ["scene", "export", "tiny", str(w / "dir.glb")], "error", "is an existing folder"),
        # --existing
        Case("--existing from a plan", plan("tiny", "x1", "-k", "1", "--existing", str(f["existing_ok"])), "ok"),
        Case("--existing in the middle of a room", plan("tiny", "x2", "--existing", str(f["existing_mid"])), "error",
             "tag 7 at (1.80, 1.80, 1.50) is not on a wall"),
        Case("--existing at (500, 500)", plan("tiny", "x3", "--existing", str(f["existing_far"])), "error",
             "tag 8 at (500.00, 500.00, 1.50) is not on a wall"),
        Case("--existing facing into the wall", plan("tiny", "x4", "--existing", str(f["existing_flipped"])), "error",
             "faces into the wall"),
        Case("--existing not JSON", plan("tiny", "x5", "--existing", str(f["existing_bad"])), "error", "not valid JSON"),
    ]
    base = f["base"]
    base_args = ["plan", "tiny", "-k", "2", "--out", str(base), *FAST]
    for art, damaged in (("observations", "observations/descriptors.npy"), ("discretization.npz", "discretization.npz"),
                         ("similarity.npz", "similarity.npz")):
        for how in ("truncate", "garble"):
            c.append(Case(f"{how}d {damaged}", base_args, "warn", f"{art} is not usable",
                          setup=damage(base / damaged, how)))
    c.append(Case("garbled .meta.json", base_args, "ok",
                  setup=lambda: (base / "observations.meta.json").write_text("{oops")))
    return c


def checked_input_cases(w: Path, f: dict) -> list[Case]:
    """Issue 35, item 5: every input checked, one line, exit 2, before the expensive work."""
    o = lambda name: str(w / "out" / name)  # noqa: E731
    plan = lambda name, *extra: ["plan", "tiny", "-k", "2", "--out", o(name), *FAST, *extra]  # noqa: E731
    check = lambda name, installed: ["check", str(f["base"]), "--installed", str(installed), "--out", o(name)]  # noqa: E731
    cluster = lambda name, address: ["plan", "tiny", "-k", "2", "--out", o(name), "--grid-spacing", "1.0",  # noqa: E731
                                     "--quiet", "--cluster", address]
    quick = {"max_seconds": 10}
    c: list[Case] = []
    for key, text in (("neg", "tag_id -1 is outside tag36h11"), ("587", "tag_id 587 is outside tag36h11"),
                      ("1e30", "is not an integer"), ("1.5", "tag_id 1.5 is not an integer"),
                      ("true", "tag_id true is not an integer"), ("str", 'tag_id "3" is not an integer'),
                      ("dup", "tag id 4 is listed twice")):
        c.append(Case(f"--existing tag id {key}", plan(f"i_{key}", "--existing", str(f[f"id_{key}"])), "error", text,
                      extra=quick))
        c.append(Case(f"check --installed tag id {key}", check(f"ci_{key}", f[f"id_{key}"]), "error", text,
                      extra=quick))
    c += [
        Case("--existing NaN world_from_marker", plan("p1", "--existing", str(f["pose_nan"])), "error",
             "NaN or infinite", extra=quick),
        Case("--existing scaled rotation", plan("p2", "--existing", str(f["pose_scaled"])), "error", "not orthonormal",
             extra=quick),
        Case("render --markers with a NaN pose", ["render", "tiny", "--markers", str(f["pos_nan"]), "--out", o("p3/v")],
             "error", "NaN or infinite", extra=quick),
        Case("--existing [ x 100000", plan("j1", "--existing", str(f["deep"])), "error", "100000 deep", extra=quick),
        Case("check --installed [ x 100000", check("j2", f["deep"]), "error", "100000 deep", extra=quick),
        Case("render --markers [ x 100000", ["render", "tiny", "--markers", str(f["deep"]), "--out", o("j3/v")],
             "error", "100000 deep", extra=quick),
        Case("-k 587 with 1 existing tag", plan("t1", "-k", "587", "--existing", str(f["existing_ok"])), "error",
             "at most 586 new tags can be placed", extra=quick),
        Case("evaluate --k=1,,2", ["evaluate", "tiny", "--out", o("k1"), "--k=1,,2", "--quiet"], "error",
             "has an empty item", extra=quick),
        Case("study -k 50 (more than candidates)", ["study", "tiny", "--k", "50", "--out", o("k2"), *FAST], "error",
             "candidate marker poses", extra={"max_seconds": 15}),
        Case("--cluster foo://x", cluster("c1", "foo://x"), "error", "the scheme must be tcp://", extra=quick),
        Case("--cluster 127.0.0.1:8786 (no scheme)", cluster("c2", "127.0.0.1:8786"), "error",
             "the scheme must be tcp://", extra=quick),
        Case("--cluster local:100000", cluster("c3", "local:100000"), "error", "N must be between 1 and",
             extra=quick),
        Case("--cluster local:1 --workers 3", ["plan", "tiny", "--out", o("c4"), "--cluster", "local:1", "--workers",
                                               "3"], "error", "--workers 3 has no effect", extra=quick),
        Case("--cluster: a server that never answers", cluster("c5", f["silent"]), "error",
             "sent no Dask handshake", extra=quick),
        Case("--cluster: a server answering garbage", cluster("c6", f["garbage"]), "error",
             "does not answer like a Dask scheduler", extra=quick),
        Case("--cluster: nothing listening", cluster("c7", "tcp://127.0.0.1:9"), "error",
             "cannot reach the Dask scheduler", extra=quick),
        Case("plan without --out", ["plan", "tiny"], "error", "required: --out"),
        Case("plan -k abc", ["plan", "tiny", "--out", o("a1"), "-k", "abc"], "error", "invalid int value"),
        Case("plan --method best", ["plan", "tiny", "--out", o("a2"), "--method", "best"], "error", "invalid choice"),
        Case("an unknown option", ["plan", "tiny", "--out", o("a3"), "--bogus"], "error", "unrecognized arguments"),
        Case("an unknown command", ["plann", "tiny"], "error", "invalid choice"),
        Case("an empty .glb", ["plan", str(w / "empty.glb"), "--out", o("m1"), *FAST], "error", "is empty (0 bytes)"),
        Case("OBJ + MTL with Latin-1 material names", ["render", str(f["latin1_mtl"]), "--out", o("m2/v")], "ok",
             check=no_grey_warning(w)),
        Case("scene export tiny x.txt", ["scene", "export", "tiny", o("x.txt")], "error", "must end in .glb"),
        Case("fuse --every 0 (hint)", ["fuse", str(w), "--out", o("f.ply"), "--every", "0"], "error",
             "a frame step N"),
    ]
    return c


def interrupt_cases(w: Path, f: dict) -> list[Case]:
    """Issue 35, item 4: SIGINT (SIGTERM) to the process group at each stage, then a resume."""
    o = lambda name: str(w / "out" / name)  # noqa: E731
    small = ["--grid-spacing", "1.0", "--yaws", "4"]
    ev = ["--tests", "40", "--k", "2", "--runs", "1", "--methods", "none,omp", "--test-sets", "weighted", *small]
    room = ["plan", "room", "-k", "2", "--out", o("sig"), "--yaws", "4", "--workers", "2"]
    observe, sigint, sigterm = "observe: rendering", signal.SIGINT, signal.SIGTERM
    return [
        Case("Ctrl-C during observe (process pool)", room, "interrupted", interrupt=(observe, 4.0, sigint)),
        Case("re-run after Ctrl-C resumes", [*room, "--quiet"], "ok", check=placement_exists(w / "out" / "sig")),
        Case("SIGTERM during observe (process pool)", ["plan", "tiny", "-k", "2", "--out", o("i1"), *small,
                                                       "--workers", "2"], "interrupted",
             interrupt=(observe, 1.5, sigterm)),
        Case("Ctrl-C during observe (in this process)", ["plan", "tiny", "-k", "2", "--out", o("i2"), *small,
                                                         "--workers", "1"], "interrupted", interrupt=(observe, 1.0, sigint)),
        Case("Ctrl-C during observe (Dask local:2)", ["plan", "tiny", "-k", "2", "--out", o("i3"), *small, "--cluster",
                                                      "local:2"], "interrupted", interrupt=(observe, 1.5, sigint)),
        Case("Ctrl-C during the look-alike search", ["plan", "tiny", "-k", "2", "--out", o("i4"), "--workers", "2"],
             "interrupted", interrupt=("counting look-alikes", 0.5, sigint)),
        Case("Ctrl-C during evaluate's map stage", ["--verbose", "evaluate", "tiny", "--out", o("i5"), *ev, "--workers",
                                                    "2"], "interrupted",
             interrupt=("map (no markers): starting", 1.0, sigint)),
        Case("Ctrl-C during evaluate's test stage", ["--verbose", "evaluate", "tiny", "--out", o("i6"), *ev, "--workers",
                                                     "2"], "interrupted",
             interrupt=("queries weighted (no markers): starting", 0.5, sigint)),
        Case("SIGTERM during evaluate (Dask local:2)", ["--verbose", "evaluate", "tiny", "--out", o("i7"), *ev,
                                                        "--cluster", "local:2"], "interrupted",
             interrupt=("map (no markers): starting", 1.0, sigterm)),
        Case("Ctrl-C during study", ["--verbose", "study", "tiny", "--out", o("i8"), "--tests", "20", "--k", "2", *small,
                                     "--workers", "2", "--vs", "50", "--shifts", "0.1", "--scales", "0.5"],
             "interrupted", interrupt=("map (no markers): starting", 1.0, sigint)),
    ]


def folder_cases(w: Path, f: dict) -> list[Case]:
    """Run folders and concurrency (issue 35, items 1-3: foreign files in --out, symlinked
    tags/, --out /, a dangling symlink, disk full, two runs in one folder). The cases of those
    items go here."""
    o = lambda name: str(w / "out" / name)  # noqa: E731
    return [
        Case("two plans into one folder at once", ["plan", "tiny", "-k", "2", "--out", o("conc"), *FAST], "ok",
             extra={"concurrent": 2}, check=same_markers(w / "out" / "conc", f["base"])),
    ]


def copy_base(w: Path, f: dict, name: str, change: Callable[[Path], None] | None = None) -> Callable[[], None]:
    """A setup: ``out/name`` a fresh copy of the base plan, then ``change(copy)``."""
    def run():
        dst = w / "out" / name
        if dst.exists():
            shutil.rmtree(dst)
        shutil.copytree(f["base"], dst)
        if change is not None:
            change(dst)
    return run


def edit_json(name: str, change: Callable[[dict], None]) -> Callable[[Path], None]:
    def run(folder: Path):
        doc = json.loads((folder / name).read_text())
        change(doc)
        (folder / name).write_text(json.dumps(doc))  # Python writes NaN as the bare token NaN
    return run


def foreign_folder(w: Path, name: str, entry: str) -> Callable[[], None]:
    def run():
        d = w / "out" / name
        d.mkdir(parents=True, exist_ok=True)
        (d / entry).write_text("the user's own")
    return run


def big_texture(w: Path) -> Callable[[], None]:
    """A room whose texture is a 20000 x 20000 JPEG (about 1.2 GB of RGB while it is made)."""
    def run():
        from PIL import Image

        d = w / "texture"
        d.mkdir(exist_ok=True)
        if not (d / "big.jpg").exists():
            Image.linear_gradient("L").resize((20000, 20000)).convert("RGB").save(d / "big.jpg", quality=80)
        gltf_with_texture_uri(d / "room.gltf", "big.jpg")
    return run


def unchanged(path: Path, text: str) -> Callable[[], str | None]:
    return lambda: None if path.read_text() == text else f"{path} was overwritten"


def quiet_stderr() -> Callable[[], str | None]:
    return lambda: None if not LAST_STDERR[0].strip() else f"--quiet still printed: {LAST_STDERR[0].strip()[:120]}"


def issue50_cases(w: Path, f: dict) -> list[Case]:
    """Issue 50, items 3-6: files that are not what their names say, tracebacks at the edges
    (stdout, encodings, resource limits, a deleted working directory, odd bookkeeping files),
    refusals that came only at the end, and a plan folder's files checked against each other."""
    o = lambda name: str(w / "out" / name)  # noqa: E731
    plan = lambda scene, name, *extra: ["plan", str(scene), "-k", "2", "--out", o(name), *FAST, *extra]  # noqa: E731
    quick = {"max_seconds": 10}
    base, lock = f["base"], ".markerplace-run.lock"
    target = w / "precious.txt"
    c = [Case(f"2 GiB of zeros named x{ext}", plan(f[f"zeros{ext}"], f"z{ext[1:]}"), "error", "is not a valid",
              extra=quick) for ext in (".ply", ".obj", ".glb", ".gltf")]
    c += [
        Case("PLY claiming 1e8 vertices in 1 kB", plan(f["claims"], "z5"), "error", "which need at least", extra=quick),
        Case("a FIFO as the mesh", plan(w / "fifo.ply", "z6"), "error", "is a named pipe (FIFO)", extra=quick),
        Case("/dev/zero as the mesh", plan("/dev/zero", "z7"), "error", "is a device", extra=quick),
        Case("a symlink loop as the mesh", plan(w / "loop.glb", "z8"), "error", "symbolic link loop", extra=quick),
        Case("a FIFO as --existing", plan("tiny", "z9", "--existing", str(w / "fifo.json")), "error",
             "is a named pipe (FIFO)", extra=quick),
        Case("a 20000 x 20000 texture", ["render", str(w / "texture" / "room.gltf"), "--out", o("z10/v")], "warn",
             "downscaled to 10000 x 10000", setup=big_texture(w)),
        Case("TOML config nested 3000 deep", plan("tiny", "t1", "--config", str(w / "deep.toml")), "error",
             "nests arrays/tables too deeply", extra=quick),
        Case("a folder named like the lock file", plan("tiny", "t2"), "error", "where markerplace keeps its lock file",
             setup=copy_base(w, f, "t2", lambda d: (d / lock).mkdir()), extra=quick),
        Case("a hard link named like the lock file", plan("tiny", "t3"), "error", "is a hard link",
             setup=copy_base(w, f, "t3", lambda d: (target.write_text("precious"), os.link(target, d / lock))),
             check=unchanged(target, "precious"), extra=quick),
        Case("non-ASCII --out on an ASCII stdout", ["render", "tiny", "--out", o("été/vue")], "ok",
             extra={"run": {"env": {**os.environ, "PYTHONIOENCODING": "ascii"}}}),
        Case("stdout on a full device", ["scene", "list"], "error", "cannot write to standard output",
             extra={"run": {"stdout": "/dev/full"}}),
        Case("ulimit -n 16 with --workers 2", ["plan", "tiny", "-k", "2", "--out", o("t6"), "--grid-spacing", "1.0",
                                               "--yaws", "2", "--workers", "2", "--quiet"], "error",
             "too many open files", extra={"run": {"rlimit": ("RLIMIT_NOFILE", 16)}}),
        Case("ulimit -v 1500000", plan("tiny", "t7"), "error", "out of memory",
             extra={"run": {"rlimit": ("RLIMIT_AS", 1_500_000 * 1024)}, "native_noise": "OpenBLAS"}),
        Case("a deleted working directory", plan("tiny", "t8"), "error", "working directory cannot be read",
             extra={"run": {"gone_cwd": True}}),
    ]
    for entry in ("placement.json", "tags.pdf", "report.html", "config.json", "scores.npz"):
        name = f"a{len(c)}"
        c.append(Case(f"--adopt a folder holding a foreign {entry}", plan("tiny", name, "--adopt"), "error",
                      f"{entry} is not written by markerplace", setup=foreign_folder(w, name, entry), extra=quick))
    nan_position = edit_json("placement.json", lambda d: d["markers"][0]["position"].__setitem__(0, float("nan")))
    room = edit_json("config.json", lambda d: d.__setitem__("scene", "room"))
    readers = {"export": lambda d: ["export", o(d), "--gltf", o(f"{d}.glb")],
               "check": lambda d: ["check", o(d), "--installed", str(base / "placement.json"), "--out", o(f"{d}_c")],
               "evaluate --plan": lambda d: ["evaluate", "--plan", o(d), "--out", o(f"{d}_e"), "--quiet"]}
    for i, (what, argv) in enumerate(readers.items()):
        c.append(Case(f"{what} of a placement.json with a NaN", argv(f"n{i}"), "error", "NaN or infinite",
                      setup=copy_base(w, f, f"n{i}", nan_position), extra=quick))
        c.append(Case(f"{what} after config.json's scene was edited", argv(f"s{i}"), "error",
                      "does not match the scene of its config.json", setup=copy_base(w, f, f"s{i}", room),
                      extra={"max_seconds": 30}))
    c += [
        Case("print-volume advice under --quiet", plan("tiny", "q1"), "ok", check=quiet_stderr()),
        Case("check --out PLAN_DIR", ["check", str(base), "--installed", str(base / "placement.json"), "--out",
                                      str(base)], "error", "is the plan folder itself", extra=quick),
        Case("evaluate tiny --plan DIR", ["evaluate", "tiny", "--plan", str(base), "--out", o("e50"), "--quiet"],
             "error", "is already the scene of the plan", extra=quick),
    ]
    return c


# --- the probe's run-folder categories ------------------------------------------------------------

PRECIOUS = "precious, not markerplace's"


def _precious(w: Path, name: str) -> Path:
    """A file of the user's outside every run folder, which no case may change."""
    p = w / "precious" / name
    p.parent.mkdir(exist_ok=True)
    p.write_text(PRECIOUS)
    return p


def untouched(*paths: Path) -> Callable[[], str | None]:
    """Each of ``paths`` (made by :func:`_precious`) still holds what it held."""
    def check():
        changed = [str(p) for p in paths if not p.is_file() or p.read_text() != PRECIOUS]
        return f"changed outside the run folder: {', '.join(changed)}" if changed else None
    return check


def always(check: Callable[[], str | None]) -> Callable[[], str | None]:
    """A case's ``check`` run whatever the exit code (``check`` runs only on exit 0 otherwise)."""
    check.always = True  # type: ignore[attr-defined]
    return check


def entries(w: Path, name: str, paths: dict) -> Callable[[], None]:
    """A setup: ``out/name`` made afresh holding ``paths`` (relative path -> text; ``None``: a
    folder)."""
    def run():
        d = w / "out" / name
        if d.exists():
            shutil.rmtree(d)
        for rel, text in paths.items():
            (d / rel).parent.mkdir(parents=True, exist_ok=True)
            (d / rel).mkdir() if text is None else (d / rel).write_text(text)
    return run


def replace_with_link(rel: str, target: Path) -> Callable[[Path], None]:
    def run(folder: Path):
        p = folder / rel
        shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink(missing_ok=True)
        p.symlink_to(target)
    return run


def write_entry(rel: str, data: str | bytes | None) -> Callable[[Path], None]:
    """Replace ``rel`` with ``data`` (``None``: a folder, ``"fifo"``: a named pipe)."""
    def run(folder: Path):
        p = folder / rel
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)
        if data is None:
            p.mkdir()
        elif data == "fifo":
            os.mkfifo(p)
        elif isinstance(data, bytes):
            p.write_bytes(data)
        else:
            p.write_text(data)
    return run


def edit_lines(rel: str, change: Callable[[list[str]], list[str]]) -> Callable[[Path], None]:
    def run(folder: Path):
        p = folder / rel
        p.write_text("".join(line + "\n" for line in change(p.read_text().splitlines())))
    return run


class _Mounts:
    """The tmpfs mounted by the full-disk cases, unmounted when the probe ends."""
    paths: list[Path] = []

    @classmethod
    def full_disk(cls, where: Path) -> Callable[[], None]:
        def run():
            if where in cls.paths:
                return
            where.mkdir(parents=True, exist_ok=True)
            res = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=256k", "tmpfs", str(where)], capture_output=True,
                                 text=True)
            if res.returncode != 0:
                raise Skip(f"cannot mount a small tmpfs ({res.stderr.strip() or 'not root'})")
            cls.paths.append(where)
            with open(where / "filler", "wb") as fh:  # leave about 40 kB free
                fh.write(bytes(200 * 1024))
        return run

    @classmethod
    def release(cls) -> None:
        for p in cls.paths:
            subprocess.run(["umount", "-l", str(p)], capture_output=True)
        cls.paths.clear()


class _Cluster:
    """One ``dask scheduler`` without workers on 127.0.0.1 (tests/helpers/dask_processes.py),
    started by the first cluster case and stopped when the probe ends."""
    procs = None

    @classmethod
    def address(cls, w: Path) -> str:
        if cls.procs is None:
            from helpers.dask_processes import DaskProcesses

            cls.procs = DaskProcesses(w / "dask")
        return cls.procs.address

    @classmethod
    def release(cls) -> None:
        if cls.procs is not None:
            cls.procs.__exit__()
            cls.procs = None


class Skip(Exception):
    """A case this machine cannot set up (reported with its reason, not counted as bad)."""


def nobody(args: list[str] | None = None) -> list[str]:
    """argv prefix running as uid/gid 65534 (a service account), when root and ``setpriv`` are there."""
    if os.geteuid() != 0 or not shutil.which("setpriv"):
        return []
    return [shutil.which("setpriv"), "--reuid=65534", "--regid=65534", "--clear-groups", "--", *(args or [])]


PLAN_FILES = ("placement.json", "placement.csv", "tags.pdf", "report.html", "config.json", "scores.npz", "scores.png",
              "placement.png", "where.png", "gain_first.png", "similarity.npz", "discretization.npz",
              "observations.meta.json", "tags/00_tag0.svg", "success_model_omp.json")
PLAN_FOLDERS = ("observations", "tags", "calibration")
CHEAP_PROBE = ("adopt plan: a foreign placement.csv", "adopt plan: a folder named placement.json",
               "adopt check: a foreign check.json", "adopt evaluate: a foreign recall.csv",
               "adopt study: a foreign study.md",
               "plan resumes: tags a symlink out", "plan resumes: the manifest's placement.json line deleted",
               "plan resumes: the manifest is a folder", "plan resumes: the lock a symlink out",
               "--out 300 characters long", "--out a dangling symlink", "--cluster-wait without --cluster",
               "TOML: [a.a.a...] 5000 deep", "TOML: grid_spacing = nan", "stdout closed: scene list",
               "stdout a broken pipe: --version", "--config a FIFO named x.toml")
"""The probe cases the default tests run (tests/e2e/test_hostile_script.py): one of each kind, the cheap ones."""


def probe_cases(w: Path, f: dict) -> list[Case]:
    """The categories of issue 50's independent probe: foreign files and folders named like each
    output (``--adopt``, and folders not markerplace's), symlinks out of a run folder, manifest,
    marker and lock files edited, odd ``--out`` paths, a full disk (a 256 kB tmpfs, root only),
    a Dask scheduler without workers, TOML nesting and non-finite values, stdout on a full
    device, closed or a broken pipe, and a service account (uid 65534). Cheap: the run-folder
    cases refuse before any work or resume a copy of the base plan."""
    o = lambda name: str(w / "out" / name)  # noqa: E731
    quick = {"max_seconds": 15}
    base = f["base"]
    plan = lambda name, *extra: ["plan", "tiny", "-k", "2", "--out", o(name), *FAST, *extra]  # noqa: E731
    check = lambda name, *extra: ["check", str(base), "--installed", str(base / "placement.json"), "--out",  # noqa: E731
                                  o(name), "--quiet", *extra]
    small_eval = ["--k", "2", "--tests", "10", *FAST]
    c: list[Case] = []
    # foreign files and folders named like an output, in an adopted folder: refused before any work
    adopted = {"plan": (plan, PLAN_FILES), "check": (check, ("check.json", "check.csv", "check_map.png", "check.html")),
               "evaluate": (lambda name: ["evaluate", "tiny", "--out", o(name), *small_eval],
                            ("recall.csv", "tables.md", "timings.json", "test_poses_weighted.npz", "report.html",
                             "plan/similarity.npz")),
               "study": (lambda name: ["study", "tiny", "--out", o(name), *small_eval],
                         ("study.md", "study.csv", "study_v.png", "runs/default/recall.csv"))}
    for command, (argv, names) in adopted.items():
        for entry in names:
            name = f"pa{len(c)}"
            c.append(Case(f"adopt {command}: a foreign {entry}", [*argv(name), "--adopt"], "error",
                          f"{entry} is not written by markerplace", extra=quick,
                          setup=entries(w, name, {entry: "the user's own", "notes.txt": "mine"})))
        for entry in names[:2]:
            name = f"pa{len(c)}"
            c.append(Case(f"adopt {command}: a folder named {entry}", [*argv(name), "--adopt"], "error",
                          "is a folder where markerplace writes a file", extra=quick,
                          setup=entries(w, name, {entry: None, "notes.txt": "mine"})))
        name = f"pa{len(c)}"
        c.append(Case(f"{command} into a foreign folder without --adopt", argv(name), "error",
                      "was not made by markerplace", extra=quick, setup=entries(w, name, {"notes.txt": "mine"})))
    for entry in PLAN_FOLDERS:
        name = f"pa{len(c)}"
        c.append(Case(f"adopt plan: a file named {entry}", [*plan(name), "--adopt"], "error",
                      "is a file where markerplace makes a folder", extra=quick,
                      setup=entries(w, name, {entry: "the user's own"})))
    # a copy of the finished base plan, changed, then the same plan again (a resume)
    outside = w / "precious"
    for entry in ("placement.json", "placement.csv", "tags.pdf", "report.html", "config.json", "scores.npz"):
        name, target = f"pl{len(c)}", _precious(w, f"link{len(c)}.txt")
        c.append(Case(f"plan resumes: {entry} a symlink out", plan(name), "ok",  # the link replaced, not its target
                      setup=copy_base(w, f, name, replace_with_link(entry, target)), check=always(untouched(target)),
                      extra={"max_seconds": 40}))
    for entry in ("tags", "observations"):
        name, target = f"pl{len(c)}", _precious(w, f"link{len(c)}.txt")
        c.append(Case(f"plan resumes: {entry} a symlink out", plan(name), "error", "is a symbolic link",
                      setup=copy_base(w, f, name, replace_with_link(entry, outside)), check=always(untouched(target)),
                      extra=quick))
    name = f"pl{len(c)}"
    c.append(Case("plan resumes: a foreign notes.txt is kept", plan(name), "ok", extra=quick,
                  setup=copy_base(w, f, name, write_entry("notes.txt", "mine")),
                  check=lambda n=name: None if (w / "out" / n / "notes.txt").read_text() == "mine" else "notes.txt lost"))
    manifest, marker, lock = ".markerplace-run.manifest", ".markerplace-run.json", ".markerplace-run.lock"
    target = _precious(w, "manifest_out.txt")
    bookkeeping = [
        ("the manifest's placement.json line deleted", "error", "is not written by markerplace",
         edit_lines(manifest, lambda ls: [ln for ln in ls if "placement.json" not in ln])),
        ("the manifest deleted", "error", "is not written by markerplace", lambda d: (d / manifest).unlink()),
        ("the manifest torn mid-line", "ok", "", edit_lines(manifest, lambda ls: [*ls, '["+f", "plac'])),
        ("the manifest garbage bytes", "error", "is not written by markerplace", write_entry(manifest, os.urandom(512))),
        ("the manifest with NaN and numbers", "ok", "", edit_lines(manifest, lambda ls: [*ls, "[NaN, 1]", "1e999",
                                                                                         '["+f", NaN]'])),
        ("the manifest claims ../precious", "ok", "",
         edit_lines(manifest, lambda ls: [*ls, json.dumps(["+f", f"../../precious/{target.name}"])])),
        ("the manifest claims an absolute path", "ok", "",
         edit_lines(manifest, lambda ls: [*ls, json.dumps(["+f", str(target)])])),
        ("the manifest is a folder", "error", "where markerplace keeps its bookkeeping file",
         write_entry(manifest, None)),
        ("the manifest a symlink out", "error", "is not written by markerplace",  # a link is no manifest
         replace_with_link(manifest, target)),
        ("the manifest a FIFO", "error", "where markerplace keeps its bookkeeping file", write_entry(manifest, "fifo")),
        ("the marker garbage", "ok", "", write_entry(marker, "{oops")),
        ("the marker NaN", "ok", "", write_entry(marker, '{"command": NaN}')),
        ("the marker is a folder", "error", "was not made by markerplace", write_entry(marker, None)),
        ("the marker a symlink out", "error", "was not made by markerplace",
         replace_with_link(marker, target)),
        ("the lock a symlink out", "error", "where markerplace keeps its lock file", replace_with_link(lock, target)),
        ("the lock a dangling symlink", "error", "is a symbolic link",
         replace_with_link(lock, w / "nowhere")),
        ("the lock a FIFO", "error", "where markerplace keeps its lock file", write_entry(lock, "fifo")),
        ("the lock garbage", "ok", "", write_entry(lock, "{oops")),
        ("the lock of a dead pid", "ok", "", write_entry(lock, json.dumps({"pid": 2 ** 22 + 7, "host": os.uname()[1],
                                                                            "command": "plan"}))),
        ("a cache meta with NaN", "ok", "", write_entry("similarity.npz.meta.json", '{"key": NaN}')),
        ("placement.json garbage", "ok", "", write_entry("placement.json", "{oops")),
    ]
    for what, expect, text, change in bookkeeping:  # a file missing from the manifest is the user's: refused
        name = f"pl{len(c)}"
        c.append(Case(f"plan resumes: {what}", plan(name), expect, text, extra={"max_seconds": 40},
                      setup=copy_base(w, f, name, change), check=always(untouched(target))))
    # odd --out paths
    for what, folder in (("non-ASCII", "plän ünï 計画"), ("with spaces", " a plan "), ("leading dash", "-dash")):
        c.append(Case(f"--out {what}", ["plan", "tiny", "-k", "2", f"--out={w / 'out' / folder}", *FAST], "ok",
                      setup=copy_base(w, f, folder), check=placement_exists(w / "out" / folder), extra=quick))
    c.append(Case("--out=-dash", ["plan", "tiny", "-k", "2", "--out=-dash", *FAST], "ok",
                  setup=lambda: (shutil.rmtree(w / "-dash", ignore_errors=True), shutil.copytree(base, w / "-dash")),
                  check=placement_exists(w / "-dash"), extra=quick))
    odd = [("--out 300 characters long", o("x" * 300), "File name too long"),
           ("--out empty", "", "--out"), ("--out /", "/", "--out /"), ("--out /dev/null", "/dev/null", "/dev/null"),
           ("--out /proc/self", "/proc/self", "/proc/self"),
           ("--out a dangling symlink", str(w / "dangling_out"), "which does not exist"),
           ("--out under /dev/null", "/dev/null/plan", "/dev/null")]
    for what, path, text in odd:
        c.append(Case(what, ["plan", "tiny", "-k", "2", "--out", path, *FAST], "error", text, extra=quick,
                      setup=lambda: (w / "dangling_out").is_symlink() or (w / "dangling_out").symlink_to(w / "gone")))
    # a service account (uid 65534): an unwritable folder, --version and scene list with an unwritable HOME
    as_nobody = {"run": {"prefix": nobody(), "env": {**os.environ, "HOME": "/nonexistent"}}}
    c += [Case("uid 65534: --out in root's folder", ["plan", "tiny", "-k", "2", "--out", o("root_only/p"), *FAST],
               "error", "cannot write", setup=lambda: (w / "out" / "root_only").mkdir(mode=0o755, exist_ok=True),
               extra={**as_nobody, **quick}),
          Case("uid 65534: --version, HOME unwritable", ["--version"], "ok", extra={**as_nobody, **quick}),
          Case("uid 65534: scene list, HOME unwritable", ["scene", "list"], "ok", extra={**as_nobody, **quick}),
          Case("uid 65534: a mesh only root may read", ["plan", str(w / "root_mesh.glb"), "-k", "2", "--out", o("nb/p"),
                                                        *FAST], "error", "ermission denied",
               setup=lambda: (shutil.copy(f["glb"], w / "root_mesh.glb"), (w / "root_mesh.glb").chmod(0o600),
                              (w / "out" / "nb").mkdir(exist_ok=True), (w / "out" / "nb").chmod(0o777)),
               extra={**as_nobody, **quick})]
    # a full disk: a 256 kB tmpfs (root only)
    full = w / "full"
    c += [Case("a full disk: plan --out", ["plan", "tiny", "-k", "2", "--out", str(full / "p"), *FAST], "error",
               "No space left on device", setup=_Mounts.full_disk(full), extra={"max_seconds": 60}),
          Case("a full disk: a second plan", ["plan", "tiny", "-k", "2", "--out", str(full / "q"), *FAST],
               "error", "No space left on device", setup=_Mounts.full_disk(full), extra={"max_seconds": 60}),
          Case("a full disk: render", ["render", "tiny", "--out", str(full / "v")], "error", "No space left on device",
               setup=_Mounts.full_disk(full), extra=quick),
          Case("a full disk: scene export", ["scene", "export", "tiny", str(full / "t.glb")], "error",
               "No space left on device", setup=_Mounts.full_disk(full), extra=quick)]
    # a Dask scheduler that has no worker
    cluster = ["--grid-spacing", "1.0", "--yaws", "4", "--quiet", "--cluster", "{cluster}", "--cluster-wait", "3"]
    c += [Case("a scheduler with no workers: plan", ["plan", "tiny", "-k", "2", "--out", o("cw1"), *cluster], "error",
               "no Dask worker joined the scheduler within 3 s", extra={"max_seconds": 30, "cluster": True}),
          Case("a scheduler with no workers: evaluate", ["evaluate", "tiny", "--out", o("cw2"), "--k", "2", "--tests",
                                                         "10", *cluster], "error",
               "no Dask worker joined the scheduler within 3 s", extra={"max_seconds": 30, "cluster": True}),
          Case("--cluster-wait without --cluster", plan("cw3", "--cluster-wait", "3"), "error",
               "has no effect without --cluster"),
          Case("--cluster-wait -1", [*plan("cw4")[:-1], "--cluster", "local:1", "--cluster-wait=-1"], "error",
               "--cluster-wait"),
          Case("--cluster-wait nan", [*plan("cw5")[:-1], "--cluster", "local:1", "--cluster-wait", "nan"], "error",
               "not a finite number")]
    # TOML: nesting and values a settings file never has
    toml = {"[a.a.a...] 5000 deep": "[" + ".".join(["a"] * 5000) + "]\nx = 1\n",
            "inline tables 3000 deep": "a = " + "{b = " * 3000 + "1" + "}" * 3000 + "\n",
            "arrays of tables 300 deep": "".join(f"[[{'.'.join(['a'] * i)}]]\n" for i in range(1, 300)),
            "a key 100000 characters long": "x" * 100_000 + " = 1\n",
            "grid_spacing = nan": "[discretize]\ngrid_spacing = nan\n",
            "grid_spacing = inf": "[discretize]\ngrid_spacing = inf\n",
            "k = 1e400": "[placement]\nk = 1e400\n",
            "a NUL byte": "[discretize]\ngrid_spacing = 1.0\x00\n",
            "UTF-16": None, "a table where a value goes": "[discretize.grid_spacing]\nx = 1\n"}
    texts = {"[a.a.a...] 5000 deep": "nests arrays/tables more than", "inline tables 3000 deep": "too deeply",
             "arrays of tables 300 deep": "nests arrays/tables more than",
             "a key 100000 characters long": "unknown setting",
             "grid_spacing = nan": "must be a finite number", "grid_spacing = inf": "must be a finite number",
             "k = 1e400": "k", "a NUL byte": "is not valid TOML", "UTF-16": "is not valid TOML",
             "a table where a value goes": "grid_spacing"}
    for i, (what, text) in enumerate(toml.items()):
        path = w / f"probe{i}.toml"
        if text is None:
            path.write_bytes("[discretize]\ngrid_spacing = 1.0\n".encode("utf-16"))
        else:
            path.write_text(text)
        c.append(Case(f"TOML: {what}", plan(f"tm{i}", "--config", str(path)), "error", texts[what], extra=quick))
    c += [Case("--config a FIFO named x.toml", plan("tm_f", "--config", str(w / "fifo.toml")), "error",
               "is a named pipe (FIFO), not a settings file",
               setup=lambda: (w / "fifo.toml").exists() or os.mkfifo(w / "fifo.toml"), extra=quick),
          Case("--config a folder named x.toml", plan("tm_d", "--config", str(w / "dir.toml")), "error",
               "is a folder, not a settings file",
               setup=lambda: (w / "dir.toml").mkdir(exist_ok=True), extra=quick),
          Case("--config /dev/zero", plan("tm_z", "--config", "/dev/zero"), "error", "--config", extra=quick)]
    # standard output full, closed or a broken pipe
    for what, how, expect in (("on a full device", {"stdout": "/dev/full"}, "error"),
                              ("closed", {"stdout_closed": True}, "error"),
                              ("a broken pipe", {"stdout_broken": True}, "sigpipe")):  # as `| head -0`: quiet, 141
        for argv in (["--version"], ["scene", "list"], ["plan", "--help"]):
            c.append(Case(f"stdout {what}: {' '.join(argv)}", argv, expect, "standard output",
                          extra={"run": how, **quick}))
        name = f"so{len(c)}"
        c.append(Case(f"stdout {what}: plan (resumed)", plan(name), expect, "standard output",
                      setup=copy_base(w, f, name), extra={"run": how, "max_seconds": 40}))
    return c


def run_cli(argv: list[str], w: Path, run: dict) -> tuple[int, str, float]:
    """Run the CLI as :func:`cli` does, with a case's ``extra["run"]``: ``env``, ``stdout`` (a
    path to write it to), ``stdout_closed`` / ``stdout_broken`` (no standard output, or a pipe
    nobody reads), ``prefix`` (argv before the interpreter: ``setpriv``), ``rlimit`` ((name,
    value) set in the child) or ``gone_cwd`` (started in a folder deleted under it)."""
    import resource

    cmd, cwd = [*run.get("prefix", []), sys.executable, "-m", "markerplace.cli", *argv], w
    if run.get("gone_cwd"):
        gone = w / "gone"
        gone.mkdir(exist_ok=True)
        cmd = ["sh", "-c", f"cd '{gone}' && rmdir '{gone}' && exec \"$0\" \"$@\"", *cmd]
    limit = run.get("rlimit")
    pre = (lambda: resource.setrlimit(getattr(resource, limit[0]), (limit[1], limit[1]))) if limit else None
    if run.get("stdout_closed"):
        pre = lambda: os.close(1)  # noqa: E731
    stdout, spare = (open(run["stdout"], "w") if run.get("stdout") else None), None
    if run.get("stdout_broken"):
        spare, write_end = os.pipe()
        os.close(spare)  # nobody reads: the first write fails with EPIPE
        stdout = os.fdopen(write_end, "w")
    t0 = time.perf_counter()
    try:
        res = subprocess.run(cmd, stdout=stdout or subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=cwd,
                             env=run.get("env"), preexec_fn=pre, timeout=600)
    finally:
        if stdout is not None:
            stdout.close()
    return res.returncode, res.stderr, time.perf_counter() - t0


def judge(case: Case, code: int, err: str, seconds: float) -> str | None:
    if "Traceback" in err:
        return "traceback"
    noise = case.extra.get("native_noise")  # a native library's own lines (OpenBLAS under ulimit -v)
    lines = [ln for ln in err.strip().splitlines() if ln.strip() and not (noise and ln.startswith(noise))]
    if case.expect == "sigpipe":  # a reader that stopped reading: quiet, exit 141 as a shell tool
        return None if code == 141 and not lines else f"exit {code} with {len(lines)} stderr lines, expected 141, quiet"
    if case.expect == "error":
        if code != 2:
            return f"exit {code}, expected 2"
        if len(lines) != 1 or not lines[0].startswith("markerplace: error:"):
            return f"{len(lines)} stderr lines, not one 'markerplace: error:' line"
        if case.text not in lines[0]:
            return f"message lacks {case.text!r}"
    else:
        if code != 0:
            return f"exit {code}, expected 0"
        if case.expect == "warn" and case.text not in err:
            return f"no warning with {case.text!r}"
    if case.extra.get("max_seconds") and seconds > case.extra["max_seconds"]:
        return f"took {seconds:.0f} s"
    if case.check is not None and (code == 0 or getattr(case.check, "always", False)):
        return case.check()
    return None


GROUPS = {"files": cases, "checked": checked_input_cases, "interrupts": interrupt_cases, "folders": folder_cases,
          "issue50": issue50_cases, "probe": probe_cases}
"""The groups of cases, in the order they run (``--group`` picks one)."""


def run_case(case: Case, w: Path) -> tuple:
    """Set ``case`` up, run it and judge it; prints its line and returns its row of the report
    (name, expected, exit, seconds, problem or "", first message). Raises :class:`Skip` when its
    setup cannot be made on this machine."""
    if case.setup:
        case.setup()
    argv = case.argv
    if case.extra.get("cluster"):
        argv = [a.replace("{cluster}", _Cluster.address(w)) for a in argv]
    prefix = without_root_powers([]) if case.extra.get("no_root") else []
    if case.interrupt is not None:
        wait_for, delay, sig = case.interrupt
        r = interrupt_cli(argv, wait_for, delay=delay, sig=sig, cwd=w)
        code, err, seconds = r.returncode, r.stderr, r.exit_s
        problems = r.problems(expect_code=128 + sig)
        problem = "; ".join(problems) if problems else None
        first = next((ln for ln in err.strip().splitlines() if ln.startswith("markerplace:")), "")[:150]
        verdict = "OK " if problem is None else "BAD"
        print(f"{verdict} {case.name:<42} exit {code!s:>4} {seconds:5.1f} s  {problem or first}", flush=True)
        return (case.name, case.expect, code, f"{seconds:.1f}", problem or "", first.replace("|", "/"))
    if case.extra.get("concurrent"):
        cmd = [sys.executable, "-m", "markerplace.cli", *argv]
        t0 = time.perf_counter()
        procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=w)
                 for _ in range(case.extra["concurrent"])]
        outs = [p.communicate(timeout=600) for p in procs]
        codes, errs = [p.returncode for p in procs], [e for _, e in outs]
        # one correct plan and clear refusals (one 'markerplace: error:' line each), or all correct
        refusals_ok = all(c == 0 or (c == 2 and len(e.strip().splitlines()) == 1
                                     and e.startswith("markerplace: error:")) for c, e in zip(codes, errs))
        code = 0 if 0 in codes and refusals_ok else max(codes)
        err = "".join(errs)
        seconds = time.perf_counter() - t0
    elif prefix:
        res = subprocess.run([*prefix, sys.executable, "-m", "markerplace.cli", *argv], capture_output=True,
                             text=True, cwd=w, timeout=600)
        code, err, seconds = res.returncode, res.stderr, 0.0
    elif case.extra.get("run"):
        code, err, seconds = run_cli(argv, w, case.extra["run"])
    else:
        code, _, err, seconds = cli(argv, w)
    LAST_STDERR[0] = err
    problem = judge(case, code, err, seconds)
    first = next((ln for ln in err.strip().splitlines() if "error:" in ln or "WARNING" in ln), "")[:150]
    verdict = "OK " if problem is None else "BAD"
    print(f"{verdict} {case.name:<42} exit {code:>3} {seconds:5.1f} s  {problem or first}", flush=True)
    return (case.name, case.expect, code, f"{seconds:.1f}", problem or "", first.replace("|", "/"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workdir", default="out/hostile_inputs", help="scratch folder (emptied first)")
    ap.add_argument("--only", default=None, help="run the cases whose name contains this")
    ap.add_argument("--group", default=None, choices=sorted(GROUPS), help="run one group of cases")
    args = ap.parse_args()
    w = Path(args.workdir).resolve()
    if w.exists():
        for p in [w / "read_only" / "plan", w / "read_only"]:
            if p.exists():
                p.chmod(0o755)
        shutil.rmtree(w)
    (w / "out").mkdir(parents=True)
    t_all = time.perf_counter()
    f = make_fixtures(w)
    servers = [LoopbackServer(garbage=False), LoopbackServer(garbage=True)]
    f["silent"], f["garbage"] = servers[0].address, servers[1].address
    rows, bad, skipped = [], 0, 0
    every = [case for name, group in GROUPS.items() if args.group in (None, name) for case in group(w, f)]
    try:
        for case in every:
            if args.only and args.only not in case.name:
                continue
            try:
                row = run_case(case, w)
            except Skip as why:
                skipped += 1
                print(f"SKIP {case.name:<41} {why}", flush=True)
                rows.append((case.name, case.expect, "-", "-", f"skipped: {why}", ""))
                continue
            bad += bool(row[4])
            rows.append(row)
    finally:
        for server in servers:
            server.close()
        _Mounts.release()
        _Cluster.release()
    ro = w / "read_only"
    for p in (ro / "plan", ro):
        p.chmod(0o755)
    summary = f"{len(rows)} cases, {bad} bad, {skipped} skipped, {time.perf_counter() - t_all:.0f} s"
    print(summary)
    lines = ["| case | expected | exit | s | problem | stderr |", "|---|---|---|---|---|---|"]
    lines += [f"| {' | '.join(str(x) for x in r)} |" for r in rows]
    (w / "hostile_inputs.md").write_text("\n".join(lines) + f"\n\n{summary}\n")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
