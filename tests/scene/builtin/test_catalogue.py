"""Built-in procedural scenes: catalogue, determinism, sizes, connectivity, eye-level walls, aliasing."""

from __future__ import annotations

import socket

import numpy as np
import pytest
from scipy import ndimage

from markerplace.errors import UserError
from markerplace.scene import load_scene
from markerplace.scene.builtin.catalogue import build_builtin, builtin_names, get_layout, list_scenes
from markerplace.scene.builtin.textures import BUNDLED_PHOTOS, bundled_photo

AREA_RANGES = {"office": (95, 125), "studio": (130, 170), "apartment": (270, 330), "room": (18, 24), "tiny": (0, 15), "house": (120, 170),
               "campus": (2000, 2200), "corridor": (200, 320), "corridor-small": (120, 160)}
EYE = 1.5


def _storeys(scene) -> list[float]:
    """Storey floor heights (one for the single-storey built-ins)."""
    return list(scene.meta.get("storeys", [scene.floor_z]))


def _storey_of(scene, room) -> float:
    """Floor height of the storey a room belongs to (a sunken room belongs to the storey above it)."""
    return max(z for z in _storeys(scene) if z <= room.floor_z + 0.5)


def _slice(scene, z: float):
    """Cross-section at height z: (S, 2, 2) xy segments and (S,) part index of each."""
    segs, owner = [], []
    for i, part in enumerate(scene.parts):
        tri = np.asarray(part.vertices, dtype=float)[np.asarray(part.faces)]  # (F, 3, 3)
        d = tri[:, :, 2] - z
        crosses = (d.min(axis=1) < 0) & (d.max(axis=1) > 0)
        for t, dt in zip(tri[crosses], d[crosses]):
            pts = []
            for a, b in ((0, 1), (1, 2), (2, 0)):
                if (dt[a] < 0) != (dt[b] < 0):
                    s = dt[a] / (dt[a] - dt[b])
                    pts.append(t[a, :2] + s * (t[b, :2] - t[a, :2]))
            if len(pts) == 2:
                segs.append(pts)
                owner.append(i)
    return np.array(segs), np.array(owner)


def _free_space_labels(scene, z: float, cell: float = 0.05):
    """Label connected free cells of the cross-section at z (occupied = within a cell of a surface)."""
    segs, _ = _slice(scene, z)
    lo = scene.bounds[0, :2] - 0.5
    hi = scene.bounds[1, :2] + 0.5
    shape = tuple(np.ceil((hi - lo) / cell).astype(int) + 1)
    occ = np.zeros(shape, dtype=bool)
    for a, b in segs:
        n = max(2, int(np.linalg.norm(b - a) / (cell / 3)) + 2)
        pts = a + np.linspace(0, 1, n)[:, None] * (b - a)
        ij = np.floor((pts - lo) / cell).astype(int)
        occ[ij[:, 0], ij[:, 1]] = True
    occ = ndimage.binary_dilation(occ)
    labels, _ = ndimage.label(~occ)
    return labels, lo, cell


def _label_at(labels, lo, cell, xy) -> int:
    i, j = np.floor((np.asarray(xy) - lo) / cell).astype(int)
    return int(labels[i, j])


@pytest.fixture(scope="module", params=builtin_names())
def builtin(request):
    return request.param, load_scene(request.param)


def test_catalogue_lists_required_scenes():
    rows = list_scenes()
    names = [r["name"] for r in rows]
    assert names == builtin_names()
    assert {"office", "studio", "apartment", "room", "tiny"} <= set(names)
    for r in rows:
        assert set(r) == {"name", "area_m2", "rooms", "description"}
        lo, hi = AREA_RANGES[r["name"]]
        assert lo <= r["area_m2"] <= hi, r
        assert r["rooms"] == len(get_layout(r["name"]).rooms)
    assert next(r for r in rows if r["name"] == "apartment")["rooms"] >= 8


def test_scene_structure(builtin):
    name, scene = builtin
    lo, hi = AREA_RANGES[name]
    area = sum(room.area for room in scene.rooms)
    assert lo <= area <= hi
    assert scene.floor_z == 0.0 and scene.source == f"builtin:{name}"
    assert scene.num_faces < 20000
    low = min(r.floor_z for r in scene.rooms)
    top = max(_storeys(scene)) + scene.meta["ceiling_height"]
    np.testing.assert_allclose(scene.bounds[:, 2], [low, top], atol=1e-6)
    for p in scene.parts:
        assert p.vertices.dtype == np.float32 and p.vertices.shape[1] == 3
        assert p.faces.dtype == np.int32 and p.faces.min() >= 0 and p.faces.max() < len(p.vertices)
        assert not p.vertices.flags.writeable
        np.testing.assert_allclose(np.linalg.norm(p.normals, axis=1), 1.0, atol=1e-5)
        # faces wind counter-clockwise seen from the side their normals point to
        tri = p.vertices[p.faces].astype(float)
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        assert np.all(np.einsum("ij,ij->i", fn, p.normals[p.faces[:, 0]]) > 0), p.name
        if p.texture is not None:
            assert p.uv is not None and p.uv.shape == (len(p.vertices), 2)
            assert p.texture.dtype == np.uint8 and p.texture.ndim == 3 and p.texture.shape[2] == 3
            assert max(p.texture.shape[:2]) <= 1024 and not p.texture.flags.writeable


def test_textures_are_shared_not_duplicated(builtin):
    _, scene = builtin
    arrays = {id(p.texture): p.texture for p in scene.parts if p.texture is not None}
    contents = {(a.shape, a.tobytes()) for a in arrays.values()}
    assert len(contents) == len(arrays)  # equal images are one object
    assert len(arrays) >= 5


def test_floor_plan_is_connected_at_eye_level(builtin):
    _, scene = builtin
    for storey in _storeys(scene):
        labels, lo, cell = _free_space_labels(scene, storey + EYE)
        rooms = [r for r in scene.rooms if _storey_of(scene, r) == storey]
        centres = [((r.bounds[0] + r.bounds[2]) / 2, (r.bounds[1] + r.bounds[3]) / 2) for r in rooms]
        ids = {_label_at(labels, lo, cell, c) for c in centres}
        assert len(ids) == 1 and 0 not in ids, storey
        assert _label_at(labels, lo, cell, lo + 0.1) not in ids  # the outside does not leak in


def test_walls_dominate_eye_level(builtin):
    name, scene = builtin
    slices = {z: _slice(scene, z + EYE) for z in _storeys(scene)}
    hits_wall = total = 0
    for room in scene.rooms:
        segs, owner = slices[_storey_of(scene, room)]
        is_wall = np.array(["/wall_" in scene.parts[i].name or "/trim" in scene.parts[i].name for i in owner])
        x0, y0, x1, y1 = room.bounds
        origin = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
        for yaw in np.linspace(0, 2 * np.pi, 36, endpoint=False):
            d = np.array([np.cos(yaw), np.sin(yaw)])
            a, b = segs[:, 0], segs[:, 1]
            e = b - a
            den = d[0] * e[:, 1] - d[1] * e[:, 0]
            w = a - origin
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / den
                s = (w[:, 0] * d[1] - w[:, 1] * d[0]) / den
            ok = (np.abs(den) > 1e-12) & (t > 0) & (s >= 0) & (s <= 1)
            assert ok.any(), f"{name}: a ray from {room.name} escapes"
            total += 1
            hits_wall += bool(is_wall[np.flatnonzero(ok)[np.argmin(t[ok])]])
    assert hits_wall / total > 0.7, hits_wall / total


def test_pictures_hang_at_eye_level_off_the_wall(builtin):
    _, scene = builtin
    pics = [p for p in scene.parts if "/pic:" in p.name]
    assert pics
    for p in pics:
        for quad in p.vertices.reshape(-1, 4, 3).astype(float):
            c = quad.mean(axis=0)
            room = next(
                r for r in scene.rooms
                if r.bounds[0] < c[0] < r.bounds[2] and r.bounds[1] < c[1] < r.bounds[3] and 0 < c[2] - r.floor_z < 2.5
            )
            assert 1.3 - 1e-4 <= c[2] - _storey_of(scene, room) <= 1.7 + 1e-4
            x0, y0, x1, y1 = room.bounds
            gap = min(c[0] - x0, x1 - c[0], c[1] - y0, y1 - c[1]) - 0.05  # from the wall surface
            assert 0.01 <= gap <= 0.08


def test_builds_are_deterministic_in_the_seed(builtin):
    name, cached = builtin
    a, b, c = build_builtin(name, 0), build_builtin(name, 0), build_builtin(name, 1)

    def arrays(s):
        out = []
        for p in s.parts:
            out += [p.vertices, p.faces] + [x for x in (p.uv, p.texture, p.normals) if x is not None]
        return out

    assert [p.name for p in a.parts] == [p.name for p in b.parts] == [p.name for p in cached.parts]
    for x, y in zip(arrays(a), arrays(b)):
        assert np.array_equal(x, y)
    differs = [p.name for p, q in zip(a.parts, c.parts) if p.texture is not None and not np.array_equal(p.texture, q.texture)]
    assert differs  # a new seed changes textures (and jitters chairs where there are any)


def test_load_scene_caches_per_name_and_seed():
    assert load_scene("tiny") is load_scene("tiny")
    assert load_scene("TINY", seed=0) is load_scene("tiny")
    assert load_scene("tiny", seed=1) is not load_scene("tiny")


def test_unknown_builtin_raises():
    with pytest.raises(UserError, match="unknown built-in scene"):
        get_layout("castle")


def test_apartment_has_identical_twin_rooms():
    scene = load_scene("apartment")
    (name_a, name_b), = scene.meta["twins"]
    rooms = {r.name: r for r in scene.rooms}
    ra, rb = rooms[name_a].bounds, rooms[name_b].bounds
    assert np.isclose(ra[2] - ra[0], rb[2] - rb[0]) and np.isclose(ra[3] - ra[1], rb[3] - rb[1])
    offset = np.array([rb[0] - ra[0], rb[1] - ra[1], 0.0])

    def inside(v, b, m=0.055):
        return (v[:, 0] > b[0] + m) & (v[:, 0] < b[2] - m) & (v[:, 1] > b[1] + m) & (v[:, 1] < b[3] - m)

    shared = 0
    for p in scene.parts:
        v = p.vertices.astype(float)
        va, vb = v[inside(v, ra)] + offset, v[inside(v, rb)]
        assert len(va) == len(vb), p.name
        if len(va):
            shared += 1
            np.testing.assert_allclose(va[np.lexsort(va.T)], vb[np.lexsort(vb.T)], atol=1e-4)
    assert shared >= 10  # furniture, pictures, rugs, lights: the same in both rooms
    # and they carry the same posters: picture parts with vertices in both rooms
    assert any("/pic:" in p.name and inside(p.vertices, ra).any() and inside(p.vertices, rb).any() for p in scene.parts)


def test_bundled_photos_load_offline(monkeypatch):
    def no_network(*args, **kwargs):
        raise OSError("network disabled in this test")

    monkeypatch.setattr(socket.socket, "connect", no_network)
    monkeypatch.setattr(socket, "create_connection", no_network)
    for name in BUNDLED_PHOTOS:
        img = bundled_photo(name, 256)
        assert img is not None and img.dtype == np.uint8 and img.ndim == 3 and max(img.shape[:2]) <= 256, name
