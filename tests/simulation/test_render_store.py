"""The testbed's render store: renders with markers kept on disk between runs of a folder."""

import json
import shutil
from dataclasses import replace

import numpy as np

from markerplace.imaging.features import ImageFeatures
from markerplace.simulation.render_store import RenderStore
from markerplace.testbed import config as tbconfig


def _features(seed: int, n: int = 5, tags: int = 1) -> ImageFeatures:
    rng = np.random.default_rng(seed)
    return ImageFeatures(rng.random((n, 2), dtype=np.float32) * 600, rng.integers(0, 256, (n, 128), dtype=np.uint8),
                         rng.random((n, 3), dtype=np.float32), np.arange(tags, dtype=np.int32),
                         rng.random((tags, 4, 2), dtype=np.float32))


def _same(a: ImageFeatures, b: ImageFeatures) -> bool:
    return all(np.array_equal(getattr(a, n), getattr(b, n)) for n in
               ("keypoints", "descriptors", "points_world", "tag_ids", "tag_corners"))


def test_store_round_trip_parts_and_damage(tmp_path):
    store = RenderStore(tmp_path / "renders", part_size=3)
    feats = {f"k{i}": _features(i, n=i + 1, tags=i % 2) for i in range(7)}
    for k, f in feats.items():
        store.put(k, f)
    assert "k6" in store and len(store) == 7  # the last one is pending, not written yet
    assert len(list((tmp_path / "renders").glob("part_*.npz"))) == 2
    store.flush()
    again = RenderStore(tmp_path / "renders")  # a later run reads every part back
    got = again.get(list(feats) + ["missing"])
    assert set(got) == set(feats) and all(_same(got[k], feats[k]) for k in feats)
    again.put("k7", _features(7))
    again.flush()  # numbered after the parts already there: nothing is overwritten
    assert len(list((tmp_path / "renders").glob("part_*.npz"))) == 4
    # a damaged part is dropped (its renders are made again), the others still serve
    first = sorted((tmp_path / "renders").glob("part_*.npz"))[0]
    first.write_bytes(b"not an npz")
    third = RenderStore(tmp_path / "renders")
    got = third.get(list(feats) + ["k7"])
    assert not first.exists() and set(got) == {"k3", "k4", "k5", "k6", "k7"}


def test_second_run_in_a_folder_renders_nothing_again(tmp_path, monkeypatch):
    """With the predictions deleted, a second run in the same folder takes every render with
    markers from the store (none is made) and gives bit-identical per-image errors; a run that
    adds placements renders only views no earlier run rendered."""
    from markerplace.pipelines.evaluate import run_evaluation
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import DiscretizeConfig
    from markerplace.runtime.executor import RuntimeConfig
    from markerplace.scene.spec import SceneSpec
    from markerplace.simulation.rendered_images import TestbedImaging

    rendered = []
    real = TestbedImaging.render_iter

    def counting(self, world_from_cam, indices, markers, map_only, desc, condition=None):
        if markers:
            rendered.extend((desc, int(i)) for i in indices)
        return real(self, world_from_cam, indices, markers, map_only, desc, condition)

    monkeypatch.setattr(TestbedImaging, "render_iter", counting)
    plan = PlanConfig(discretize=replace(DiscretizeConfig(), grid_spacing=1.0, num_yaws=4),
                      runtime=RuntimeConfig(workers=1))
    config = tbconfig.EvaluateConfig(test=tbconfig.TestSetConfig(tests=12, sets=("weighted",)),
                                     study=tbconfig.StudyConfig(methods=("none", "omp", "random"), runs=1, ks=(2,)))
    out = tmp_path / "eval"
    run_evaluation(SceneSpec("tiny"), plan, config, out, progress=False)
    first = len(rendered)
    assert first > 0 and len(RenderStore(out / "cache" / "renders")) == first
    errors = np.load(out / "query_errors.npz")
    shutil.rmtree(out / "cache" / "predictions")
    rendered.clear()
    run_evaluation(SceneSpec("tiny"), plan, config, out, progress=False)
    assert rendered == []
    again = np.load(out / "query_errors.npz")
    for key in errors.files:
        a, b = errors[key], again[key]
        assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), key
    metas = [json.loads(p.read_text()) for p in (out / "cache" / "predictions").glob("*.meta.json")]
    assert sum(m["localized"] for m in metas) > 0  # localized again, from stored renders
    # k = 1 as well: new views (random's new draw, OMP's first tag alone) are rendered once and
    # stored; nothing the store holds is rendered again
    before = len(RenderStore(out / "cache" / "renders"))
    run_evaluation(SceneSpec("tiny"), plan, replace(config, study=replace(config.study, ks=(1, 2))), out,
                   progress=False)
    assert 0 < len(rendered) == len(RenderStore(out / "cache" / "renders")) - before


def test_candidate_tag_ids_are_fixed_by_spot():
    from markerplace.markers import Marker
    from markerplace.simulation.marker_sets import PlacementRun, shift_markers, with_candidate_ids

    rng = np.random.default_rng(0)
    cands = np.tile(np.eye(4), (6, 1, 1))
    cands[:, :3, 3] = rng.random((6, 3)) * 5
    a = PlacementRun("omp", 0, 3, tuple(Marker(i, 0.4, cands[c]) for i, c in enumerate([4, 1, 2])))
    b = PlacementRun("random", 2, 2, tuple(Marker(i, 0.3, cands[c] + 1e-7) for i, c in enumerate([1, 5])),
                     test_sets=("weighted",))
    moved = shift_markers(list(a.markers), 0.25, seed=0)
    c = PlacementRun("omp", 0, 3, tuple(moved))
    d = PlacementRun("other", 0, 1, (moved[1],))
    got = with_candidate_ids([a, b, c, d], cands)
    assert [m.tag_id for m in got[0].markers] == [4, 1, 2]
    assert [m.tag_id for m in got[1].markers] == [1, 5] and got[1].test_sets == ("weighted",)
    assert [m.tag_id for m in got[2].markers] == [6, 7, 8] and [m.tag_id for m in got[3].markers] == [7]
    for new, old in zip(got, (a, b, c, d)):  # only the ids change
        assert (new.method, new.run, new.k) == (old.method, old.run, old.k)
        assert all(np.array_equal(x.world_from_marker, y.world_from_marker) and x.size == y.size
                   for x, y in zip(new.markers, old.markers))
    # more spots than tag36h11 codes: ids stay as placed
    many = np.tile(np.eye(4), (600, 1, 1))
    many[:, 0, 3] = np.arange(600)
    e = PlacementRun("omp", 0, 2, (Marker(0, 0.4, many[599]), Marker(1, 0.4, many[3])))
    assert [m.tag_id for m in with_candidate_ids([e], many)[0].markers] == [0, 1]


def test_candidate_tag_ids_share_renders(tmp_path, monkeypatch):
    """``--tag-ids candidate``: placements with the same spot in an image's view (random draws
    at k = 2 and 3, OMP) draw the same image and share its render, so the run renders fewer
    images than with ids in placement order."""
    from markerplace.cli.main import main
    from markerplace.simulation.rendered_images import TestbedImaging

    counts: dict[str, int] = {}
    real = TestbedImaging.render_iter
    mode = {"now": ""}

    def counting(self, world_from_cam, indices, markers, map_only, desc, condition=None):
        if markers:
            counts[mode["now"]] = counts.get(mode["now"], 0) + len(indices)
        return real(self, world_from_cam, indices, markers, map_only, desc, condition)

    monkeypatch.setattr(TestbedImaging, "render_iter", counting)
    base = ["evaluate", "tiny", "--tests", "12", "--test-sets", "weighted", "--k", "2,3", "--runs", "2",
            "--methods", "none,omp,random", "--grid-spacing", "1.0", "--yaws", "4", "--workers", "1", "--quiet"]
    for ids in ("order", "candidate"):
        mode["now"] = ids
        assert main(base + ["--out", str(tmp_path / ids), "--tag-ids", ids]) == 0
        assert (tmp_path / ids / "tables.md").stat().st_size > 0
    assert 0 < counts["candidate"] < counts["order"], counts
