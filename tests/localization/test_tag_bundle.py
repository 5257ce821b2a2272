"""The tag/camera factor graph and the robust fit to the plan, on synthetic corner measurements
(known truth; no rendering)."""

from __future__ import annotations

import numpy as np

from helpers.poses import look_at_pose
from markerplace.geometry import invert, marker_corners_local, world_from_marker_pose
from markerplace.localization.tag_anchor import anchor_to_plan, rotation_deg
from markerplace.localization.tag_bundle import Detection, solve_tags

K = np.array([[800.0, 0.0, 639.5], [0.0, 800.0, 479.5], [0.0, 0.0, 1.0]])


def _wall_tags():
    return {i: world_from_marker_pose(np.array([x, 3.0, 1.5 + 0.1 * (i % 2)]), np.array([0.0, -1.0, 0.0]))
            for i, x in enumerate([0.0, 0.8, 1.6, 2.4, 3.2])}


def _observe(tags, cams, noise, rng, size=0.4):
    dets = []
    for p, C in enumerate(cams):
        for t, T in tags.items():
            q = (marker_corners_local(size) @ T[:3, :3].T + T[:3, 3] - C[:3, 3]) @ C[:3, :3]
            uv = q @ K.T
            uv = uv[:, :2] / uv[:, 2:]
            if np.all(q[:, 2] > 0) and np.all(uv > 0) and np.all(uv[:, 0] < 1280) and np.all(uv[:, 1] < 960):
                dets.append(Detection(p, t, uv + rng.normal(0, noise, uv.shape)))
    return dets


def _cams():
    return [look_at_pose([x, 0.8, 1.4], [x + 0.2, 3.0, 1.5]) for x in np.linspace(-0.4, 3.6, 9)]


def test_bundle_recovers_relative_poses_and_a_bad_detection_is_dropped():
    rng = np.random.default_rng(1)
    tags, cams = _wall_tags(), _cams()
    dets = _observe(tags, cams, 0.3, rng)
    bad = dets[3]
    dets[3] = Detection(bad.photo, bad.tag_id, bad.corners + np.array([25.0, -10.0]))  # a corrupted detection
    sol = solve_tags(dets, {p: K for p in range(len(cams))}, {t: 0.4 for t in tags})
    assert len(sol.inliers) == len(dets) - 1 and sol.rms_px < 0.6
    for t in tags:
        est, tru = invert(sol.tags[0]) @ sol.tags[t], invert(tags[0]) @ tags[t]
        assert np.linalg.norm(est[:3, 3] - tru[:3, 3]) < 0.02 and rotation_deg(est, tru) < 1.0  # 3.2 m lever
    cov = sol.covariances(0, {0: (0.01, 0.005)})
    sol.cov.update(cov)
    pos, rot = sol.std(4)
    assert 0.0 < pos < 0.05 and 0.0 < rot < 5.0
    assert sol.std(4)[0] > sol.std(0)[0]  # farther from the gauge, less certain


def test_two_unlinked_walls_are_two_components():
    rng = np.random.default_rng(2)
    tags = _wall_tags()
    far = {10 + t: T.copy() for t, T in tags.items()}
    for T in far.values():
        T[:3, 3] += [20.0, 0.0, 0.0]
    cams = _cams() + [C.copy() for C in _cams()]
    for C in cams[9:]:
        C[:3, 3] += [20.0, 0.0, 0.0]
    dets = [d for d in _observe({**tags, **far}, cams, 0.2, rng)]
    sol = solve_tags(dets, {p: K for p in range(len(cams))}, {t: 0.4 for t in {**tags, **far}})
    assert len(set(sol.component.values())) == 2
    assert len({sol.component[t] for t in tags}) == 1 and sol.component[0] != sol.component[10]


def test_anchor_ignores_tags_hung_wrong():
    """Five tags: two shifted 30 cm / turned 90 deg; the frame comes from the other three."""
    rng = np.random.default_rng(3)
    planned = _wall_tags()
    M = np.eye(4)
    M[:3, :3] = world_from_marker_pose(np.zeros(3), np.array([0.3, 0.9, 0.0]))[:3, :3]
    M[:3, 3] = [5.0, -2.0, 0.3]  # the solver's frame is anywhere
    hung = {t: T.copy() for t, T in planned.items()}
    hung[1][:3, 3] += 0.3 * hung[1][:3, 0]
    a = np.radians(90)
    hung[3][:3, :3] = hung[3][:3, :3] @ np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    recovered = {t: invert(M) @ T for t, T in hung.items()}
    for T in recovered.values():
        T[:3, 3] += rng.normal(0, 0.002, 3)
    fit = anchor_to_plan(recovered, planned, {t: 0.4 for t in planned}, 0.05, 5.0)
    assert fit.tags == (0, 2, 4) and fit.rms_m < 0.005
    assert np.linalg.norm(fit.model_from_solver[:3, 3] - M[:3, 3]) < 0.01
    assert anchor_to_plan({0: recovered[0], 1: recovered[1]}, planned, {0: 0.4, 1: 0.4}, 0.05, 5.0) is None
