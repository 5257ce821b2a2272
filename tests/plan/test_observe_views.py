"""plan's observe stage looking at each camera location once (``--observe-views``): the same
poses written, features where the pose itself sees them, candidate occlusion as a render of the
pose gives it, and a rerun resumes from what was written."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from markerplace.geometry import project, world_from_cam_poses
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import FeatureSet
from markerplace.plan.observe import observe
from markerplace.runtime.executor import RuntimeConfig, make_executor
from markerplace.scene import load_scene
from markerplace.scene.spec import SceneSpec


@pytest.fixture(scope="module")
def setting():
    scene = load_scene("room")
    lo, hi = scene.bounds[0], scene.bounds[1]
    centres = [(lo[0] + (hi[0] - lo[0]) * f, (lo[1] + hi[1]) / 2, 1.5) for f in (0.35, 0.65)]
    yaws = 2 * np.pi * np.arange(8) / 8
    T = np.concatenate([world_from_cam_poses(np.tile(c, (8, 1)), yaws) for c in centres])
    rng = np.random.default_rng(0)
    cand = np.tile(np.eye(4), (12, 1, 1))
    cand[:, :3, 3] = rng.uniform(lo + 0.3, hi - 0.3, (12, 3))
    return T, cand


def run(tmp_path, name, views, T, cand):
    config = replace(ImagingConfig(), observe_views=views)
    with make_executor(RuntimeConfig(workers=1)) as ex:
        return observe(SceneSpec("room"), T, np.ones((len(T), len(cand)), bool), cand, 0.1, config, ex,
                       tmp_path / name, key=views, progress=False)


@pytest.mark.parametrize("views", ["location-renders", "location-features"])
def test_location_views_observe_every_pose(tmp_path, setting, views):
    T, cand = setting
    ref = run(tmp_path, "pose", "pose", T, cand)
    got = run(tmp_path, views, views, T, cand)
    K = ImagingConfig().camera.K
    n_ref, n_got = np.diff(ref.offsets), np.diff(got.offsets)
    assert len(n_got) == len(T) and (n_got > 0).all()
    assert abs(n_got.sum() - n_ref.sum()) < 0.25 * n_ref.sum()
    for i in range(len(T)):
        a, b = got.offsets[i], got.offsets[i + 1]
        uv, z = project(K, T[i], got.points_world[a:b].astype(float))
        # each pose's points are where that pose sees them, at its keypoints
        assert (z > 0).all()
        np.testing.assert_allclose(uv, got.keypoints[a:b], atol=1.0)
    occ_ref, occ_got = ref.extras["candidate_unoccluded"], got.extras["candidate_unoccluded"]
    assert occ_ref.any() and (occ_ref == occ_got).mean() > 0.97


def test_location_views_resume(tmp_path, setting, monkeypatch):
    """Interrupted after the first location, a rerun renders only the second."""
    T, cand = setting
    whole = run(tmp_path, "whole", "location-renders", T, cand)
    import functools

    import markerplace.plan.observe as obs

    monkeypatch.setattr(obs, "FeatureWriter", functools.partial(obs.FeatureWriter, part_size=8))
    real = obs._observe_location_task
    calls = []

    def interrupted(engine, item):
        calls.append(item)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(engine, item)

    monkeypatch.setattr(obs, "_observe_location_task", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run(tmp_path, "loc", "location-renders", T, cand)
    calls.clear()
    monkeypatch.setattr(obs, "_observe_location_task", lambda engine, item: calls.append(item) or real(engine, item))
    again = run(tmp_path, "loc", "location-renders", T, cand)
    assert len(calls) == 1 and calls[0][2].all()  # the second location only, all its poses
    np.testing.assert_allclose(calls[0][0], T[8:])
    np.testing.assert_array_equal(whole.offsets, again.offsets)
    np.testing.assert_array_equal(whole.points_world, again.points_world)
    assert isinstance(again, FeatureSet)
