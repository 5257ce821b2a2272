"""Long per-image stages of ``evaluate`` resume mid-way: the marker-free map and query images
(features and in-view masks, :class:`~markerplace.simulation.rendered_images.BaseImages`) and the
localizations of one prediction (:class:`~markerplace.simulation.prediction_store.PartialPrediction`)
commit their work in parts, so a run stopped half-way (here by a ``KeyboardInterrupt`` raised
from the task after N images, as Ctrl-C raises one) loses at most one part; the next run
computes only what no part holds and gives what an uninterrupted run gives."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np
import pytest

from markerplace.geometry import world_from_cam_pose, world_from_marker_pose
from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.features import FeatureSet
from markerplace.localization.sift import SIFT_DEFAULT
from markerplace.markers import Marker
from markerplace.pipelines.evaluate import run_evaluation
from markerplace.plan.config import PlanConfig
from markerplace.plan.discretize.stage import DiscretizeConfig
from markerplace.runtime.executor import InProcessExecutor, RuntimeConfig
from markerplace.scene.spec import SceneSpec
from markerplace.simulation import placement_localization as predict
from markerplace.simulation import prediction_store
from markerplace.simulation import rendered_images as images
from markerplace.simulation.prediction_store import PartialPrediction
from markerplace.simulation.rendered_images import BaseImages, TestbedImaging
from markerplace.testbed import config as tbconfig

N = 20
PART = 4
TASKS = {name: getattr(images, name) for name in ("_render_task", "_in_view_task")}  # before any patch


def _poses() -> np.ndarray:
    """(N, 4, 4) cameras 1.5 m up inside ``tiny``, turning and stepping along its middle."""
    lo, hi = _bounds()
    mid = (lo + hi) / 2
    return np.stack([world_from_cam_pose(np.array([mid[0] + 0.3 * np.sin(i), mid[1] + 0.3 * np.cos(i), lo[2] + 1.5]),
                                         2 * np.pi * i / N) for i in range(N)])


def _bounds() -> tuple[np.ndarray, np.ndarray]:
    v = np.concatenate([p.vertices for p in SceneSpec("tiny").load().parts])
    return v.min(axis=0), v.max(axis=0)


def _markers() -> list[Marker]:
    """Two tags on walls-to-be (only their visibility columns matter here)."""
    lo, hi = _bounds()
    mid = (lo + hi) / 2
    return [Marker(0, 0.2, world_from_marker_pose(np.array([lo[0] + 0.05, mid[1], lo[2] + 1.5]), np.array([1.0, 0, 0]))),
            Marker(1, 0.2, world_from_marker_pose(np.array([mid[0], lo[1] + 0.05, lo[2] + 1.5]), np.array([0, 1.0, 0])))]


def _counting(monkeypatch, name: str, stop_after: int | None = None) -> list:
    """Replace the task ``images.<name>`` by one that counts its calls and raises
    ``KeyboardInterrupt`` (as Ctrl-C does) once ``stop_after`` calls have finished."""
    real, calls = TASKS[name], []

    def task(engine, item):
        if stop_after is not None and len(calls) >= stop_after:
            raise KeyboardInterrupt
        calls.append(1)
        return real(engine, item)

    monkeypatch.setattr(images, name, task)
    return calls


def _no_render(engine, item):
    raise AssertionError("the features were cached: nothing should be rendered with RGB")


def _same(a: BaseImages, b: BaseImages) -> None:
    for name in FeatureSet.FIELDS:
        x, y = getattr(a.features, name), getattr(b.features, name)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
    assert np.array_equal(a.in_view, b.in_view)
    assert a.digest == b.digest  # identical bytes: every later stage's key is the same too


def test_marker_free_images_resume_mid_way(tmp_path, monkeypatch, caplog):
    poses, union = _poses(), _markers()
    caplog.set_level(logging.INFO, logger="markerplace")
    with InProcessExecutor() as ex:
        tb = TestbedImaging(SceneSpec("tiny"), ImagingConfig(sift=SIFT_DEFAULT), union, ex, progress=False)
        calls = _counting(monkeypatch, "_render_task")
        clean = BaseImages(tb, poses, tmp_path / "clean", "k", False, "map", part_size=PART)
        assert len(calls) == N and clean.in_view.any()

        calls = _counting(monkeypatch, "_render_task", stop_after=10)  # stopped in its third part
        with pytest.raises(KeyboardInterrupt):
            BaseImages(tb, poses, tmp_path / "run", "k", False, "map", part_size=PART)
        assert len(list((tmp_path / "run" / "features" / "parts").glob("part_*.npz"))) == 2  # 8 images kept

        calls = _counting(monkeypatch, "_render_task")
        resumed = BaseImages(tb, poses, tmp_path / "run", "k", False, "map", part_size=PART)
        assert len(calls) == N - 8  # only the images no part held
        assert "map (no markers): resuming, 8 of 20 images already done" in caplog.text
        _same(clean, resumed)
        assert not (tmp_path / "run" / "features" / "parts").exists()

        # the markers change: the features are reused, the in-view mask is made again from depth
        # renders, which resume mid-way too
        tb2 = TestbedImaging(SceneSpec("tiny"), ImagingConfig(sift=SIFT_DEFAULT), union[:1], ex, progress=False)
        monkeypatch.setattr(images, "_render_task", _no_render)
        _counting(monkeypatch, "_in_view_task", stop_after=6)
        with pytest.raises(KeyboardInterrupt):
            BaseImages(tb2, poses, tmp_path / "run", "k", False, "map", part_size=PART)
        depth = _counting(monkeypatch, "_in_view_task")
        masked = BaseImages(tb2, poses, tmp_path / "run", "k", False, "map", part_size=PART)
        assert len(depth) == N - 4
        assert "map (marker visibility): resuming, 4 of 20 images already done" in caplog.text
        assert np.array_equal(masked.in_view, clean.in_view[:, :1])
        assert not (tmp_path / "run" / "in_view_parts").exists()


def test_partial_prediction_commits_in_chunks(tmp_path):
    est = np.arange(5 * 16, dtype=float).reshape(5, 4, 4)
    p = PartialPrediction(tmp_path, "key-a", every=2)
    assert p.done() == {}
    for i in (3, 0, 4):  # the third estimate is not committed when the run stops
        p.add(i, est[i])
    again = PartialPrediction(tmp_path, "key-a", every=2).done()
    assert sorted(again) == [0, 3] and all(np.array_equal(again[i], est[i]) for i in again)
    (tmp_path / "key-b.partial.npz").write_bytes(b"damaged")
    assert PartialPrediction(tmp_path, "key-b").done() == {}  # not trusted: those images are localized again
    p.discard()
    assert not (tmp_path / "key-a.partial.npz").exists()


def test_an_interrupted_localization_resumes_with_the_images_it_had_not_finished(tmp_path, monkeypatch, caplog):
    """Ctrl-C in the middle of one prediction's localizations: the next run localizes only the
    images no commit held, and every prediction equals an uninterrupted run's."""
    plan = PlanConfig(discretize=replace(DiscretizeConfig(), grid_spacing=1.0, num_yaws=2), runtime=RuntimeConfig(workers=1))
    config = tbconfig.EvaluateConfig(test=tbconfig.TestSetConfig(tests=12, sets=("weighted",)),
                                     study=tbconfig.StudyConfig(methods=("none", "omp"), runs=1, ks=(2,)))
    real, calls = predict.localize_task, []

    def localize(engine, item):
        if stop[0] is not None and len(calls) >= stop[0]:
            raise KeyboardInterrupt
        calls.append(1)
        return real(engine, item)

    monkeypatch.setattr(predict, "localize_task", localize)
    monkeypatch.setattr(prediction_store, "COMMIT_EVERY", 4)
    caplog.set_level(logging.INFO, logger="markerplace")
    stop = [None]
    run_evaluation(SceneSpec("tiny"), plan, config, tmp_path / "clean", progress=False)
    total = len(calls)
    calls.clear()
    stop[0] = 6  # in the first prediction (no markers, 12 test images): 4 committed
    with pytest.raises(KeyboardInterrupt):
        run_evaluation(SceneSpec("tiny"), plan, config, tmp_path / "run", progress=False)
    assert len(list((tmp_path / "run" / "cache" / "predictions").glob("*.partial.npz"))) == 1
    calls.clear()
    stop[0] = None
    run_evaluation(SceneSpec("tiny"), plan, config, tmp_path / "run", progress=False)
    assert len(calls) == total - 4
    assert "localize weighted none k=0 run 0: resuming, 4 of 12 images already localized" in caplog.text
    assert not list((tmp_path / "run" / "cache" / "predictions").glob("*.partial.npz"))
    a, b = np.load(tmp_path / "clean" / "query_errors.npz"), np.load(tmp_path / "run" / "query_errors.npz")
    for key in a.files:
        assert np.array_equal(a[key], b[key], equal_nan=a[key].dtype.kind == "f"), key
