"""The human baseline (``--method human``) on a hand-built two-room mesh without room metadata:
one busy wallpaper per room, every other wall plain. The method must measure the busy walls as
textured, pick stretch centres (never two on a stretch while one is free), leave the busy wall
out, share the tags over both rooms by area, be deterministic, and run through ``plan``.
Plus the selection rules (largest remainder, rounds) on synthetic inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from markerplace.cli.main import build_parser, main, plan_config_from_args
from markerplace.pipelines.plan import prepare
from markerplace.plan.place.human import HumanConfig, WallAnalysis, analyse, human_placement, largest_remainder, select
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.scene.export import export_glb
from markerplace.scene.spec import SceneSpec
from markerplace.scene.types import MeshPart, Scene

T, H = 0.1, 2.7  # wall thickness, ceiling height
FAST = ["--grid-spacing", "1.5", "--yaws", "4", "--workers", "1", "--no-similarity", "--quiet"]
# obstacles as xy rectangles: rooms a = [0, 5] x [0, 4] and b = [5, 9] x [0, 4], a 0.9 m door at x = 5
WALLS = [(-T / 2, -T / 2, 9 + T / 2, T / 2), (-T / 2, 4 - T / 2, 9 + T / 2, 4 + T / 2),
         (-T / 2, -T / 2, T / 2, 4 + T / 2), (9 - T / 2, -T / 2, 9 + T / 2, 4 + T / 2),
         (5 - T / 2, 0, 5 + T / 2, 1.5), (5 - T / 2, 2.4, 5 + T / 2, 4)]
# the busy walls: room a's north wall (facing -y), room b's south wall (facing +y)
BUSY = {"a": ((0.05, 3.95), (4.95, 3.95), (0.0, -1.0)), "b": ((5.05, 0.05), (8.95, 0.05), (0.0, 1.0))}
PLAIN = (0.88, 0.86, 0.82, 1.0)


def box(name, x0, y0, z0, x1, y1, z1) -> MeshPart:
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float32)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                  [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], np.int32)
    return MeshPart(name, v, f, base_color=PLAIN)


def busy_texture() -> np.ndarray:
    """Black and white blocks at two scales: SIFT finds hundreds of keypoints per m^2 on it."""
    rng = np.random.default_rng(7)
    coarse = np.kron(rng.random((12, 20)) > 0.5, np.ones((32, 32), bool))
    fine = np.kron(rng.random((48, 80)) > 0.5, np.ones((8, 8), bool))
    return np.repeat(np.where(coarse ^ fine, 20, 235).astype(np.uint8)[..., None], 3, axis=2)


def wallpaper(name, a, b, normal) -> MeshPart:
    """A textured quad over a whole wall face (2 mm in front of it) from xy ``a`` to ``b``."""
    a, b, n = (np.array([*p, 0.0]) for p in (a, b, normal))
    if np.cross(b - a, [0, 0, 1]) @ n < 0:
        a, b = b, a
    a, b = a + 0.002 * n, b + 0.002 * n
    v = np.array([a, b, b + [0, 0, H], a + [0, 0, H]], np.float32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    return MeshPart(name, v, np.array([[0, 1, 2], [0, 2, 3]], np.int32), uv=uv, texture=busy_texture())


def two_room_scene() -> Scene:
    parts = [MeshPart("floor", np.array([[0, 0, 0], [9, 0, 0], [9, 4, 0], [0, 4, 0]], np.float32),
                      np.array([[0, 1, 2], [0, 2, 3]], np.int32), base_color=(0.6, 0.6, 0.62, 1.0)),
             MeshPart("ceiling", np.array([[0, 0, H], [0, 4, H], [9, 4, H], [9, 0, H]], np.float32),
                      np.array([[0, 1, 2], [0, 2, 3]], np.int32), base_color=(0.95, 0.95, 0.95, 1.0)),
             box("lintel", 5 - T / 2, 1.5, 2.1, 5 + T / 2, 2.4, H)]
    parts += [box(f"wall{i}", x0, y0, 0.0, x1, y1, H) for i, (x0, y0, x1, y1) in enumerate(WALLS)]
    parts += [wallpaper(f"busy_{room}", *w) for room, w in BUSY.items()]
    return Scene("two_rooms_textured", tuple(parts))  # no rooms: the method finds them


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """The scene as a GLB, planned with ``--method human`` (k = 4), and its PlanData."""
    d = tmp_path_factory.mktemp("human")
    glb = d / "two_rooms.glb"
    export_glb(two_room_scene(), glb)
    out = d / "plan"
    assert main(["plan", str(glb), "-k", "4", "--method", "human", "--out", str(out), *FAST]) == 0
    config = plan_config_from_args(build_parser().parse_args(["plan", str(glb), "--out", str(out), *FAST]))
    data = prepare(SceneSpec(str(glb)), config, out, progress=False)  # cached stages
    return out, data, analyse(data, HumanConfig())


def _room(xy) -> str:
    return "a" if xy[0] < 5 else "b"


def _on_busy(p, n) -> bool:
    return any(abs(p[1] - a[1]) < 0.1 and np.allclose(n[:2], nn) and min(a[0], b[0]) < p[0] < max(a[0], b[0])
               for a, b, nn in BUSY.values())


def test_stretches_rooms_and_texture(planned):
    _, data, a = planned
    disc = data.disc
    pos, nrm = disc.candidate_position, disc.candidate_normal
    # ten flat walls: per room three full walls and the partition on both sides of the door
    assert len(a.centre) == 10 and abs(a.spacing - 1.0) < 0.1
    for s, c in enumerate(a.centre):
        members = np.flatnonzero(a.stretch_of == s)
        assert a.stretch_of[c] == s
        assert np.allclose(nrm[members], nrm[c], atol=1e-3) and len({_room(p) for p in pos[members]}) == 1
        u = pos[members] @ np.array([-nrm[c][1], nrm[c][0], 0.0])
        mid = 0.5 * (u.min() + u.max())
        assert abs(u[members == c][0] - mid) == np.abs(u - mid).min()  # the centre is nearest the middle
    # rooms found from the occupancy layer, split at the door, areas of the free space
    assert len(a.room_area) == 2
    by_room = {_room(p): r for p, r in zip(pos, a.room_of)}
    assert by_room["a"] != by_room["b"] and all(a.room_of[i] == by_room[_room(p)] for i, p in enumerate(pos))
    assert a.room_area[by_room["a"]] == pytest.approx(4.9 * 3.9, rel=0.08)
    assert a.room_area[by_room["b"]] == pytest.approx(3.9 * 3.9, rel=0.08)
    busy = np.array([_on_busy(pos[c], nrm[c]) for c in a.centre])
    assert busy.sum() == 2  # one busy stretch per room
    assert a.stretch_texture[busy].min() > 50 and a.stretch_texture[busy].min() > 5 * a.stretch_texture[~busy].max()


def test_picks_centres_of_least_textured_stretches_over_both_rooms(planned):
    out, data, a = planned
    for k in (4, 8):
        order = human_placement(data, k)
        stretches = a.stretch_of[order]
        assert len(set(order.tolist())) == k and len(set(stretches.tolist())) == k  # never two on one stretch
        assert set(order.tolist()) <= set(a.centre.tolist())  # centres only
        rooms = np.bincount(a.room_of[order], minlength=2)
        assert rooms.tolist() == [k // 2, k // 2]  # 19.1 : 15.2 m^2 -> 2.2 : 1.8 and 4.5 : 3.5
        for r in range(2):  # the least-textured stretches of each room
            mine = np.flatnonzero(a.room_of[a.centre] == r)
            chosen = stretches[a.room_of[order] == r]
            skipped = np.setdiff1d(mine, chosen)
            assert a.stretch_texture[chosen].max() <= a.stretch_texture[skipped].min()
        busy = [_on_busy(data.disc.candidate_position[c], data.disc.candidate_normal[c]) for c in order]
        assert not any(busy)  # k = 8 leaves exactly the busy wall of each room
    np.testing.assert_array_equal(human_placement(data, 8), human_placement(data, 8))  # deterministic
    plan = json.loads((out / "placement.json").read_text())
    assert plan["method"] == "human" and [m["candidate_index"] for m in plan["markers"]] == human_placement(data, 4).tolist()
    assert all(m["gain"] is None for m in plan["markers"])
    assert (out / "placement.png").stat().st_size > 0


def test_more_tags_than_stretches_go_round_again(planned):
    _, data, a = planned
    order = human_placement(data, 13)
    counts = np.bincount(a.stretch_of[order], minlength=len(a.centre))
    assert counts.min() == 1 and counts.max() == 2 and len(set(order.tolist())) == 13
    assert set(a.centre.tolist()) <= set(order[:10].tolist())  # every centre in the first round
    extra = order[10:]
    for c in extra:  # a second spot is its stretch's least-textured other candidate
        s = a.stretch_of[c]
        others = np.flatnonzero((a.stretch_of == s) & (np.arange(len(a.stretch_of)) != a.centre[s]))
        assert a.candidate_texture[c] == a.candidate_texture[others].min()


def test_registered_deterministic_and_not_randomized():
    cls = PLACEMENT_METHODS["human"]
    assert cls.label == "Human" and not cls.randomized and not cls.nested
    assert list(PLACEMENT_METHODS).index("human") == 3  # after omp, random, uniform


def test_largest_remainder_is_proportional_capped_and_tie_broken_by_index():
    assert largest_remainder(10, np.array([67.6, 20.9, 15.7]), np.array([9, 9, 9])).tolist() == [6, 2, 2]
    assert largest_remainder(3, np.array([1.0, 1.0, 1.0, 1.0]), np.array([5, 5, 5, 5])).tolist() == [1, 1, 1, 0]
    assert largest_remainder(6, np.array([10.0, 1.0, 1.0]), np.array([2, 9, 9])).tolist() == [2, 2, 2]
    assert largest_remainder(50, np.array([1.0, 2.0]), np.array([3, 4])).tolist() == [3, 4]
    rng = np.random.default_rng(0)
    for _ in range(200):
        w, caps = rng.uniform(0.5, 50, 5), rng.integers(0, 6, 5)
        k = int(rng.integers(0, 30))
        got = largest_remainder(k, w, caps)
        assert got.sum() == min(k, caps.sum()) and np.all(got <= caps) and np.all(got >= 0)
        if caps.min() >= k:  # uncapped: within one of the exact share
            assert np.all(np.abs(got - k * w / w.sum()) < 1)


def test_select_rounds_rooms_and_ties_on_a_synthetic_wall():
    # stretches 0, 1 in room 0 (area 30), 2 in room 1 (area 10); texture ties go to the lower index
    a = WallAnalysis(stretch_of=np.array([0, 0, 0, 1, 2, 2]), centre=np.array([1, 3, 4]),
                     stretch_texture=np.array([5.0, 5.0, 1.0]), candidate_texture=np.array([3.0, 9.0, 2.0, 5.0, 1.0, 0.0]),
                     room_of=np.array([0, 0, 0, 0, 1, 1]), room_area=np.array([30.0, 10.0]), spacing=1.0)
    assert select(a, 1) == [1]  # room 0's share; tie between stretches 0 and 1 -> lower candidate
    assert select(a, 2) == [1, 3]  # 1.5 : 0.5 -> tie in the remainders -> room 0
    assert select(a, 3) == [4, 1, 3]  # one per stretch, least textured first
    assert select(a, 5) == [4, 1, 3, 5, 2]  # round 2: stretch 2's next spot, stretch 0's least-textured other
    assert select(a, 9) == [4, 1, 3, 5, 2, 0]  # every candidate once at most
