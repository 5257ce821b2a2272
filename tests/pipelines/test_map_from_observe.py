"""Nothing rendered twice: observe's renders also give the testbed's marker-free map
(:class:`markerplace.plan.observe.MapOutput`), so ``evaluate`` renders no map image of its own,
and neither does ``evaluate --plan`` after ``plan --with-map``. The map made that way is the one
the testbed renders itself, bit for bit (features, in-view masks, results), and a marker that is
not among observe's candidates falls back to depth renders."""

from __future__ import annotations

import csv

import numpy as np

from helpers import FAST_2_YAWS
from markerplace.cli.main import main
from markerplace.imaging.engine import ImagingEngine
from markerplace.imaging.features import FeatureSet
from markerplace.imaging.visibility import marker_points, select_in_view
from markerplace.pipelines import plan as plan_pipeline

EVAL = ["--tests", "8", "--test-sets", "weighted", "--methods", "none,omp", "--runs", "1", "--k", "2"]
RUN = ["--workers", "1", "--quiet"]


def _count_renders(monkeypatch) -> list:
    """Record every render of every imaging engine in this process (``--workers 1``): its
    (4, 4) pose, whether it drew markers and whether it made RGB."""
    calls, real = [], ImagingEngine.render

    def render(self, world_from_cam, markers=(), rgb=True):
        calls.append((np.asarray(world_from_cam, float).copy(), bool(markers), rgb))
        return real(self, world_from_cam, markers, rgb)

    monkeypatch.setattr(ImagingEngine, "render", render)
    return calls


def _map_renders(calls: list, discretization) -> int:
    """Renders without markers (RGB or depth only) at the map's poses (those of the
    ``discretization.npz`` file)."""
    poses = np.load(discretization)["world_from_cam"]
    keys = {p.tobytes() for p in np.asarray(poses, float)}
    return sum(1 for pose, markers, _ in calls if not markers and pose.tobytes() in keys)


def _rows(folder) -> list:
    return list(csv.DictReader((folder / "recall.csv").open()))


def test_evaluate_renders_each_map_pose_once_and_equals_the_rendered_map(tmp_path, monkeypatch):
    calls = _count_renders(monkeypatch)
    shared = tmp_path / "shared"
    assert main(["evaluate", "tiny", "--out", str(shared), *EVAL, *FAST_2_YAWS]) == 0
    N = len(np.load(shared / "plan" / "discretization.npz")["world_from_cam"])
    assert _map_renders(calls, shared / "plan" / "discretization.npz") == N > 0  # observe's renders, which also gave the map
    calls.clear()
    monkeypatch.setattr(plan_pipeline, "observed_map_output", lambda *a, **k: None)  # the testbed renders it
    rendered = tmp_path / "rendered"
    assert main(["evaluate", "tiny", "--out", str(rendered), *EVAL, *FAST_2_YAWS]) == 0
    assert _map_renders(calls, rendered / "plan" / "discretization.npz") >= 2 * N  # observe, then the map (and its in-view masks)
    a = FeatureSet.load(shared / "cache" / "map_base" / "features")
    b = FeatureSet.load(rendered / "cache" / "map_base" / "features")
    for name in FeatureSet.FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name
    assert len(a.tag_ids) == 0 and len(a.keypoints) > 1000
    mask_a = np.load(shared / "cache" / "map_base" / "in_view.npy")
    mask_b = np.load(rendered / "cache" / "map_base" / "in_view.npy")
    assert mask_a.shape == mask_b.shape and mask_a.any() and np.array_equal(mask_a, mask_b)
    assert _rows(shared) == _rows(rendered)


def test_plan_with_map_then_evaluate_plan_renders_no_map_image(run_plan, tmp_path, monkeypatch):
    plan = run_plan(2, options=FAST_2_YAWS)  # a plain plan: no map
    assert not (plan / "calibration").exists()
    before = (plan / "placement.json").read_bytes()
    calls = _count_renders(monkeypatch)
    assert main(["plan", "tiny", "-k", "2", "--out", str(plan), *FAST_2_YAWS, "--with-map"]) == 0
    assert (plan / "calibration" / "map_base" / "features" / "descriptors.npy").exists()
    N = len(np.load(plan / "discretization.npz")["world_from_cam"])
    assert _map_renders(calls, plan / "discretization.npz") == N  # cached observe: the map's renders only
    assert (plan / "placement.json").read_bytes() == before
    calls.clear()
    out = tmp_path / "eval"
    assert main(["evaluate", "--plan", str(plan), "--out", str(out), *EVAL, *RUN]) == 0
    assert _map_renders(calls, out / "plan" / "discretization.npz") == 0 and len(calls) > 0  # test images only


def test_plan_made_with_map_then_evaluate_plan_observes_nothing(tmp_path, monkeypatch):
    """plan --with-map observes per pose (its renders also give the map); evaluate --plan then
    reuses those observations although the plan's settings ask for location views."""
    plan = tmp_path / "plan"
    assert main(["plan", "tiny", "-k", "2", "--out", str(plan), *FAST_2_YAWS, "--with-map"]) == 0
    calls = _count_renders(monkeypatch)
    out = tmp_path / "eval"
    assert main(["evaluate", "--plan", str(plan), "--out", str(out), *EVAL, *RUN]) == 0
    assert _map_renders(calls, out / "plan" / "discretization.npz") == 0 and len(calls) > 0  # test images only


def test_in_view_columns_are_read_only_for_the_markers_observe_sampled():
    rng = np.random.default_rng(0)
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, :3, 3] = rng.normal(size=(3, 3))
    stored = marker_points(poses, 0.2, grid=3)  # (3, 9, 3)
    mask = rng.random((5, 3)) < 0.5
    picked = select_in_view(mask, stored, stored[[2, 0]])
    assert np.array_equal(picked, mask[:, [2, 0]])
    assert select_in_view(mask, stored, stored[:0]).shape == (5, 0)
    moved = stored[[1]].copy()
    moved[0, 0, 0] += 1e-12  # not the same marker any more: the mask must be computed
    assert select_in_view(mask, stored, moved) is None
    assert select_in_view(mask, stored, marker_points(poses[:1], 0.3, grid=3)) is None  # another size
    assert select_in_view(mask, stored, marker_points(poses[:1], 0.2, grid=4)) is None  # another grid
