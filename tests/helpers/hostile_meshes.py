"""A corpus of broken or odd mesh files, written by the tests (nothing is downloaded).

Each entry is ``name -> (writer, expect)``: ``writer(dir) -> path`` writes the file(s) and
returns the path to give ``markerplace plan``; ``expect`` is ``"plan"`` (a sensible plan must
come out), ``"error"`` (a one-line ``markerplace: error:`` with exit code 2) or ``"either"``
(both are acceptable: e.g. a y-up file read as z-up that still looks like a building).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

H = 2.6


def box(lo, hi):
    """(8, 3) vertices and (12, 3) outward faces of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                  [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    return v, f


def quad(corners, up=True):
    v = np.asarray(corners, float)
    f = np.array([[0, 1, 2], [0, 2, 3]]) if up else np.array([[0, 2, 1], [0, 3, 2]])
    return v, f


def merge(*meshes):
    vs, fs, off = [], [], 0
    for v, f in meshes:
        vs.append(np.asarray(v, float))
        fs.append(np.asarray(f) + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def room(x0=0.0, y0=0.0, w=6.0, d=4.5, z0=0.0, floor=True, ceiling=True, door=None, hole=None, t=0.1, table=True):
    """A furnished room: floor, ceiling, four box walls (door: (x_from, x_to) opening in the south
    wall; hole: (y_from, y_to, z_from, z_to) scan hole in the east wall), a table and a cabinet."""
    parts = []
    if floor:
        parts.append(quad([[x0, y0, z0], [x0 + w, y0, z0], [x0 + w, y0 + d, z0], [x0, y0 + d, z0]]))
    if ceiling:
        parts.append(quad([[x0, y0, z0 + H], [x0 + w, y0, z0 + H], [x0 + w, y0 + d, z0 + H], [x0, y0 + d, z0 + H]], up=False))
    if door is None:
        parts.append(box((x0 - t, y0 - t, z0), (x0 + w + t, y0, z0 + H)))
    else:
        a, b = door
        parts += [box((x0 - t, y0 - t, z0), (x0 + a, y0, z0 + H)), box((x0 + b, y0 - t, z0), (x0 + w + t, y0, z0 + H)),
                  box((x0 + a, y0 - t, z0 + 2.1), (x0 + b, y0, z0 + H))]
    parts.append(box((x0 - t, y0 + d, z0), (x0 + w + t, y0 + d + t, z0 + H)))
    parts.append(box((x0 - t, y0, z0), (x0, y0 + d, z0 + H)))
    if hole is None:
        parts.append(box((x0 + w, y0, z0), (x0 + w + t, y0 + d, z0 + H)))
    else:
        ya, yb, za, zb = hole
        parts += [box((x0 + w, y0, z0), (x0 + w + t, y0 + ya, z0 + H)), box((x0 + w, y0 + yb, z0), (x0 + w + t, y0 + d, z0 + H)),
                  box((x0 + w, y0 + ya, z0), (x0 + w + t, y0 + yb, z0 + za)),
                  box((x0 + w, y0 + ya, z0 + zb), (x0 + w + t, y0 + yb, z0 + H))]
    if table:
        parts += [box((x0 + 1.0, y0 + 1.0, z0), (x0 + 2.2, y0 + 1.8, z0 + 0.75)),
                  box((x0 + w - 1.0, y0 + d - 0.5, z0), (x0 + w - 0.1, y0 + d - 0.05, z0 + 1.9))]
    return merge(*parts)


def _colors(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, size=(n, 3))


def write_obj(path: Path, v, f, header: str = "", mtl: str | None = None) -> Path:
    lines = [header] if header else []
    if mtl:
        lines.append(f"mtllib {mtl}")
    lines += [f"v {float(a):.6f} {float(b):.6f} {float(c):.6f}" for a, b, c in np.asarray(v, float)]
    if mtl:
        lines.append("usemtl m")
    lines += [f"f {int(a) + 1} {int(b) + 1} {int(c) + 1}" for a, b, c in np.asarray(f)]
    path.write_text("\n".join(lines) + "\n", encoding="latin-1" if "\xe9" in header else "utf-8")
    return path


def write_ply(path: Path, v, f=None, colors=None, binary=True) -> Path:
    import trimesh

    v = np.asarray(v, float)
    if f is None or len(f) == 0:
        pc = trimesh.PointCloud(v, colors=colors)
        path.write_bytes(pc.export(file_type="ply"))
        return path
    m = trimesh.Trimesh(v, np.asarray(f), vertex_colors=colors, process=False)
    path.write_bytes(m.export(file_type="ply", encoding="binary" if binary else "ascii"))
    return path


def write_glb(path: Path, v, f) -> Path:
    import trimesh

    # glTF is y-up: rotate our z-up model into it
    vv = np.asarray(v, float)[:, [0, 2, 1]] * np.array([1, 1, -1])
    m = trimesh.Trimesh(vv, np.asarray(f), process=False)
    path.write_bytes(m.export(file_type="glb"))
    return path


def subdivided_room(target_faces: int):
    """A furnished room whose every face is split until about ``target_faces`` faces."""
    v, f = room()
    import trimesh

    m = trimesh.Trimesh(v, f, process=False)
    while len(m.faces) * 4 <= target_faces:
        m = m.subdivide()
    return np.asarray(m.vertices), np.asarray(m.faces)


def _scan_like(seed=0):
    """A room with many small holes punched in walls, floor and ceiling, and vertex noise."""
    v, f = subdivided_room(20_000)
    rng = np.random.default_rng(seed)
    keep = rng.random(len(f)) > 0.08
    v = v + rng.normal(scale=0.005, size=v.shape)
    return v, f[keep]


def _entries():
    def obj(name, v, f, **kw):
        return lambda d: write_obj(Path(d) / f"{name}.obj", v, f, **kw)

    def ply(name, v, f=None, **kw):
        return lambda d: write_ply(Path(d) / f"{name}.ply", v, f, **kw)

    r_v, r_f = room(door=(2.0, 2.9))
    E = {}
    E["empty_file"] = (lambda d: (Path(d) / "empty.obj").write_text("") or Path(d) / "empty.obj", "error")
    E["comments_only"] = (lambda d: (Path(d) / "c.obj").write_text("# nothing\n# here\n") or Path(d) / "c.obj", "error")
    E["obj_point_cloud"] = (lambda d: (Path(d) / "pts.obj").write_text(
        "".join(f"v {a} {b} {c}\n" for a, b, c in np.random.default_rng(1).uniform(0, 5, (500, 3)))) or Path(d) / "pts.obj",
        "error")
    E["ply_point_cloud"] = (ply("cloud", np.random.default_rng(2).uniform(0, 5, (2000, 3)), None,
                                colors=_colors(2000)), "error")
    E["single_triangle"] = (obj("tri", [[0, 0, 0], [5, 0, 0], [0, 5, 0]], [[0, 1, 2]]), "error")
    E["single_plane"] = (obj("plane", *quad([[0, 0, 0], [8, 0, 0], [8, 6, 0], [0, 6, 0]])), "error")
    E["walls_only"] = (obj("walls", *room(floor=False, ceiling=False, table=False)), "error")
    E["no_floor"] = (obj("nofloor", *room(floor=False, table=False)), "error")
    E["open_box_no_ceiling"] = (obj("open_box", *room(ceiling=False)), "plan")
    E["room"] = (obj("room", r_v, r_f), "plan")
    nan_v = r_v.copy()
    nan_v[[3, 17]] = np.nan
    E["nan_vertices"] = (obj("nan", nan_v, r_f), "either")
    inf_v = r_v.copy()
    inf_v[[5]] = np.inf
    E["inf_vertices"] = (obj("inf", inf_v, r_f), "either")
    E["flipped_normals"] = (obj("flipped", r_v, r_f[:, ::-1]), "plan")
    rng = np.random.default_rng(3)
    mixed = r_f.copy()
    flip = rng.random(len(mixed)) < 0.5
    mixed[flip] = mixed[flip][:, ::-1]
    E["random_winding"] = (obj("mixed", r_v, mixed), "plan")
    E["duplicate_faces"] = (obj("dups", r_v, np.concatenate([r_f, r_f])), "plan")
    degenerate = np.concatenate([r_f, np.array([[0, 0, 1], [2, 2, 2], [3, 4, 4]])])
    E["degenerate_faces"] = (obj("degen", r_v, degenerate), "plan")
    E["bad_face_index"] = (lambda d: write_obj(Path(d) / "badidx.obj", r_v, np.concatenate([r_f, [[0, 1, 10_000]]])),
                           "either")
    y_up = r_v[:, [0, 2, 1]] * np.array([1, 1, -1])
    E["y_up_read_as_z_up"] = (obj("yup", y_up, r_f), "either")
    E["centimetres"] = (obj("cm", r_v * 100, r_f), "either")
    E["millimetres"] = (obj("mm", r_v * 1000, r_f), "error")
    E["tiny_units"] = (obj("km", r_v / 1000, r_f), "error")
    E["far_from_origin"] = (obj("far", r_v + np.array([5.0e5, 4.2e6, 120.0]), r_f), "plan")
    E["mirrored"] = (obj("mirror", r_v * np.array([-1, 1, 1]), r_f), "plan")
    E["holes_in_walls"] = (obj("holes", *room(door=(2.0, 2.9), hole=(1.0, 2.5, 0.8, 2.2))), "plan")
    E["scan_like_noise_and_holes"] = (ply("scanlike", *_scan_like(), colors=None), "plan")
    E["two_disjoint_buildings"] = (obj("two", *merge(room(door=(2.0, 2.9)), room(x0=40.0, door=(2.0, 2.9)))), "plan")
    E["two_storeys"] = (obj("storeys", *merge(room(door=(2.0, 2.9)), room(z0=3.0, door=(2.0, 2.9)),
                                               box((-0.1, -0.1, H), (6.1, 4.6, 3.0)))), "plan")
    E["quads_and_ngons"] = (lambda d: _write_ngon_room(Path(d) / "ngon.obj"), "plan")
    E["latin1_comment"] = (obj("latin1", r_v, r_f, header="# caf\xe9 scann\xe9 par un t\xe9l\xe9phone"), "plan")
    E["ply_ascii_colours"] = (ply("ascii", r_v, r_f, colors=_colors(len(r_v)), binary=False), "plan")
    E["glb_room"] = (lambda d: write_glb(Path(d) / "room.glb", r_v, r_f), "plan")
    E["garbage_glb"] = (lambda d: (Path(d) / "junk.glb").write_bytes(b"glTF" + bytes(range(256)) * 4) or Path(d) / "junk.glb",
                        "error")
    E["truncated_glb"] = (lambda d: _truncated(write_glb(Path(d) / "trunc.glb", r_v, r_f)), "error")
    E["gltf_missing_bin"] = (lambda d: _gltf_missing_bin(Path(d)), "error")
    E["stairs_only"] = (obj("stairs", *merge(*[box((0, 0.3 * i, 0), (1.0, 0.3 * (i + 1), 0.18 * (i + 1))) for i in range(10)])),
                        "error")
    E["huge_mesh_2M_faces"] = (ply("huge", *subdivided_room(2_000_000)), "plan")
    return E


def _write_ngon_room(path: Path) -> Path:
    v, f = room(door=(2.0, 2.9))
    lines = [f"v {float(a):.6f} {float(b):.6f} {float(c):.6f}" for a, b, c in v]
    # the floor as one quad, the ceiling as a pentagon-free quad, the rest as triangles
    lines.append("f 1 2 3 4")
    lines.append("f 5 6 7 8")
    lines += [f"f {int(a) + 1} {int(b) + 1} {int(c) + 1}" for a, b, c in f[4:]]
    path.write_text("\n".join(lines) + "\n")
    return path


def _truncated(path: Path) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


def _gltf_missing_bin(d: Path) -> Path:
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": "missing.bin", "byteLength": 96}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 12}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "max": [1, 1, 0], "min": [0, 0, 0]},
                         {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}
    p = d / "lost.gltf"
    p.write_text(json.dumps(doc))
    return p


CORPUS = _entries()
