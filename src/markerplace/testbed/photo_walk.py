"""A walk with a phone, simulated: a plan's tags hung with known errors, photographed from
poses the solver is not told, under the query conditions. The truth for ``check --photos``
(``tests/pipelines/test_check_photos.py``, ``benchmarks/photo_check.py``).

Error sets (:data:`ERROR_SETS`) are lists of operations on the planned tags by placement order
(0-based): ``("shift", i, right_m, up_m)`` moves tag ``i`` along its wall (as you face it),
``("shift", ...)`` goes another way (mirrored, or only up or down) when the given way would put
its paper over a neighbour's or off its wall;
``("turn", i, deg)`` turns it on its wall (counter-clockwise as you face it), ``("swap", i, j)``
exchanges two tags' ids (``swapped``, or ``shifted`` when the two spots are within the check's
match radius: a tag with the spot's id within it is that spot's tag), ``("missing", i)`` leaves it out and ``("extra", tag_id)`` hangs an
unplanned tag on the free candidate spot farthest from every planned tag. Each comes with the
status ``check`` must give.

Photos (:func:`photo_poses`): per hung tag and per missing spot two off-axis views 1.3-2 m in
front of it; for each tag and its :data:`NEIGHBOURS` nearest neighbours (within :data:`PAIR_RANGE_M`, not
facing each other), and along a minimum spanning tree of all tags, two
views (:data:`PAIR_VIEWS`) that show both (what links the photos into one solve); each in free space with a clear line of sight, at
1.3-1.7 m, a few degrees of roll. Every photo gets one of the query conditions blur, noise and
exposure in turn (:func:`markerplace.simulation.conditions.degrade_render`).
"""

from __future__ import annotations

from dataclasses import replace

import networkx as nx
import numpy as np

from markerplace.geometry import Intrinsics, marker_corners_local
from markerplace.markers import Marker
from markerplace.plan.installed_vs_plan import MATCH_RADIUS_M
from markerplace.render.renderer import Renderer
from markerplace.scene.raycast import RayCaster
from markerplace.simulation.conditions import CONDITIONS as CONDITION_TYPES
from markerplace.simulation.conditions import ImageCondition, degrade_render
from markerplace.tagfamily import outer_size

__all__ = ["ERROR_SETS", "PHONE", "CONDITIONS", "hang", "photo_poses", "take_photos"]

PHONE = Intrinsics.from_fov(1024, 768, 66.0)
"""A phone's main camera (66 deg across, 4:3), at a resolution the tests can afford."""
CONDITIONS = ("blur", "noise", "exposure")
MAX_OBLIQUE_DEG = 65.0
"""A photo shows a tag when it is within this angle of the tag's normal."""
PAIR_VIEWS = 2
"""Views per pair of neighbouring tags."""
NEIGHBOURS = 3
"""Each tag is paired with this many nearest tags (and along a minimum spanning tree of all)."""
PAIR_RANGE_M = 6.0
"""Tags farther apart are not photographed together."""

ERROR_SETS = {
    "mixed": [("shift", 0, 0.30, 0.0), ("shift", 2, 0.0, 0.02), ("turn", 3, 90.0), ("turn", 4, 180.0),
              ("swap", 5, 6), ("missing", 7), ("extra", 40)],
    "small": [("shift", 0, 0.07, 0.04), ("shift", 1, -0.10, 0.0), ("shift", 2, 0.0, -0.03), ("extra", 41)],
    "turned": [("turn", 0, 180.0), ("turn", 1, -90.0), ("swap", 2, 3), ("missing", 4), ("shift", 5, 0.15, -0.10)],
}
"""Name -> operations (module docstring). ``mixed`` is the issue's list: shifts of 2 and 30 cm,
a turn of 90 and one of 180 deg, a swapped pair, a missing and an extra tag."""


def _turned(T: np.ndarray, right: float, up: float, deg: float) -> np.ndarray:
    out = np.array(T, float, copy=True)
    out[:3, 3] += right * T[:3, 0] + up * T[:3, 1]
    a = np.radians(deg)
    Rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    out[:3, :3] = T[:3, :3] @ Rz
    return out


def _on_wall(caster, T: np.ndarray, edge: float) -> bool:
    """The paper of a tag at ``T`` (outer edge ``edge``, metres) lies flat on a wall: behind each
    of its corners, 10 cm in front of it, the wall is 10 cm away."""
    h = edge / 2
    corners = np.array([[-h, -h, 0.1], [h, -h, 0.1], [h, h, 0.1], [-h, h, 0.1]]) @ T[:3, :3].T + T[:3, 3]
    t, _ = caster.first_hits(corners, np.repeat(-T[None, :3, 2], 4, axis=0), 0.5)
    return bool(np.all(np.abs(t - 0.1) < 0.02))


def hang(planned: list[Marker], ops: list, free_spots: np.ndarray, scene=None) -> tuple[list[Marker], dict, dict]:
    """The tags as hung.

    Args:
        planned: the plan's markers in placement order.
        ops: an error set (module docstring).
        free_spots: (C, 4, 4) candidate ``world_from_marker`` poses (for an extra tag).
        scene: when given, a shift goes the other way when the given way would not leave the
            paper flat on its wall (a corner, a door).

    Returns:
        (hung markers, {placement order (1-based): expected status}, {tag_id: true
        world_from_marker} of every hung tag).
    """
    poses = {i: np.asarray(m.world_from_marker, float) for i, m in enumerate(planned)}
    ids = {i: int(m.tag_id) for i, m in enumerate(planned)}
    status = {i + 1: "as planned" for i in range(len(planned))}
    caster = RayCaster(*scene.geometry()) if scene is not None else None
    extra = []
    for op in ops:
        kind, i = op[0], op[1]
        if kind == "shift":  # away from a neighbour its paper would cover, if the given way does
            others = [T[:3, 3] for j, T in poses.items() if j != i]
            r, u = op[2], op[3]
            for dr, du in ((r, u), (-r, -u), (r, -u), (-r, u), (0.0, u), (0.0, -u), (0.0, r), (0.0, -r)):
                if np.hypot(dr, du) == 0.0 and np.hypot(r, u) > 0.0:
                    continue
                moved = _turned(poses[i], dr, du, 0.0)
                if all(np.linalg.norm(moved[:3, 3] - c) > outer_size(planned[i].size) for c in others) and (
                        caster is None or _on_wall(caster, moved, outer_size(planned[i].size))):
                    break
            poses[i] = moved
            status[i + 1] = "shifted" if np.linalg.norm(moved[:3, 3] - planned[i].position) > 0.05 else "as planned"
        elif kind == "turn":
            poses[i] = _turned(poses[i], 0.0, 0.0, op[2])
            status[i + 1] = "shifted"
        elif kind == "swap":
            j = op[2]
            ids[i], ids[j] = ids[j], ids[i]
            near = np.linalg.norm(poses[i][:3, 3] - poses[j][:3, 3]) <= MATCH_RADIUS_M
            status[i + 1] = status[j + 1] = "shifted" if near else "swapped"  # check's pairing: its id within the radius
        elif kind == "missing":
            poses.pop(i)
            status[i + 1] = "missing"
        elif kind == "extra":
            P = np.array([m.position for m in planned])
            C = np.asarray(free_spots, float)
            far = int(np.argmax(np.min(np.linalg.norm(C[:, None, :3, 3] - P[None], axis=2), axis=1)))
            extra.append(Marker(int(i), planned[0].size, C[far]))
    hung = [replace(planned[i], tag_id=ids[i], world_from_marker=T) for i, T in poses.items()] + extra
    return hung, status, {int(m.tag_id): np.asarray(m.world_from_marker, float) for m in hung}


def _look_at(eye, target, roll_deg: float) -> np.ndarray:
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    a = np.radians(roll_deg)
    x, y = np.cos(a) * x + np.sin(a) * y, -np.sin(a) * x + np.cos(a) * y
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


def _sees(caster, T: np.ndarray, tags: list[np.ndarray], size: float, intr: Intrinsics, margin: float = 30.0) -> bool:
    """All ``tags`` (world_from_marker) fully in the image, facing the camera and in clear view."""
    K = intr.K
    for M in tags:
        corners = marker_corners_local(size) @ M[:3, :3].T + M[:3, 3]
        q = (corners - T[:3, 3]) @ T[:3, :3]
        if np.any(q[:, 2] < 0.3):
            return False
        uv = (q @ K.T)[:, :2] / q[:, 2:]
        if np.any(uv < margin) or np.any(uv[:, 0] > intr.width - margin) or np.any(uv[:, 1] > intr.height - margin):
            return False
        to_cam = T[:3, 3] - M[:3, 3]
        if to_cam @ M[:3, 2] < np.cos(np.radians(MAX_OBLIQUE_DEG)) * np.linalg.norm(to_cam):
            return False
        d = np.vstack([corners, M[:3, 3][None]]) - T[:3, 3]
        n = np.linalg.norm(d, axis=1)
        t, _ = caster.first_hits(np.repeat(T[None, :3, 3], len(d), axis=0), d / n[:, None], n + 1.0)
        if np.any(t < n - 0.03):
            return False
    around = caster.first_hits(np.repeat(T[None, :3, 3], 6, axis=0),
                               np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]]))[0]
    return bool(np.all(around > 0.25))


def photo_poses(scene, targets: list[np.ndarray], size: float, rng: np.random.Generator,
                intr: Intrinsics = PHONE) -> list[np.ndarray]:
    """Camera poses (world_from_cam) of the walk (module docstring) around ``targets`` (the hung
    tags' and the missing spots' world_from_marker)."""
    caster = RayCaster(*scene.geometry())
    out = []
    for M in targets:
        c, n, right = M[:3, 3], M[:3, 2], M[:3, 0]
        for side in (-1.0, 1.0):
            for dist, lateral in ((1.8, 0.45), (1.5, 0.35), (2.0, 0.25), (1.2, 0.3), (1.0, 0.2)):
                eye = c + dist * n + side * lateral * dist * right
                eye[2] = float(rng.uniform(1.3, 1.7))
                T = _look_at(eye, c + 0.1 * rng.normal(size=3), float(rng.uniform(-6, 6)))
                if _sees(caster, T, [M], size, intr):
                    out.append(T)
                    break
    P = np.array([M[:3, 3] for M in targets])
    D = np.linalg.norm(P[:, None] - P[None], axis=2)
    pairs = set()
    for a, A in enumerate(targets):
        near = [b for b in np.argsort(D[a]) if b != a and D[a, b] <= PAIR_RANGE_M and A[:3, 2] @ targets[b][:3, 2] >= -0.2]
        pairs.update(tuple(sorted((a, int(b)))) for b in near[:NEIGHBOURS])
    tree = nx.minimum_spanning_tree(nx.from_numpy_array(D))  # a chain through every tag, where one can be seen
    pairs.update(tuple(sorted(e)) for e in tree.edges if D[e] <= PAIR_RANGE_M)
    for a, b in sorted(pairs):
        A, B = targets[a], targets[b]
        mid = (A[:3, 3] + B[:3, 3]) / 2
        n = A[:3, 2] + B[:3, 2]
        n /= np.linalg.norm(n)
        found = 0
        for dist in (1.2, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 5.0):
            for ang in np.radians([-20.0, 20.0, 0.0, -40.0, 40.0]):
                c, s_ = np.cos(ang), np.sin(ang)
                eye = mid + dist * np.array([c * n[0] - s_ * n[1], s_ * n[0] + c * n[1], n[2]])
                eye[2] = float(rng.uniform(1.3, 1.7))
                T = _look_at(eye, mid, float(rng.uniform(-4, 4)))
                if found < PAIR_VIEWS and _sees(caster, T, [A, B], size, intr) and not (
                        found and np.linalg.norm(out[-1][:3, 3] - eye) < 0.5):
                    out.append(T)
                    found += 1
    return out


def take_photos(scene, hung: list[Marker], poses: list[np.ndarray], seed: int = 0, intr: Intrinsics = PHONE):
    """Render the photos: (H, W, 3) uint8 each, the conditions of :data:`CONDITIONS` in turn."""
    images = []
    with Renderer(scene, intr, markers=hung) as r:
        for k, T in enumerate(poses):
            name = CONDITIONS[k % len(CONDITIONS)]
            cond = ImageCondition(name, CONDITION_TYPES.lookup(name).default_conf, (int(seed), k))

            def render(light, T=T):
                r.set_lighting(light)
                try:
                    return r.render(T, rgb=True, depth=False, normal=False)
                finally:
                    r.set_lighting(None)

            images.append(degrade_render(T, cond, render, intr.K)[0].rgb)
    return images

