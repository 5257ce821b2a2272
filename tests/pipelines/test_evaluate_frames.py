"""``markerplace evaluate --frames`` end to end on a rendered RGB-D sequence of ``tiny`` (the
``tiny_frames`` fixture: 40 handheld-like frames with known poses, noisy depth).

The sequence stands in for a real one; the testbed's steps are the real ones: the block split,
the plan at the map frames, the tags composited into the frames by their poses and found by the
real detector, maps of real frames and of renders of the fused surface, localization, tables.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from markerplace.cli.main import main
from markerplace.testbed.frames.store import FeatureStore
from markerplace.testbed.reporting.tables import read_recall_csv

ARGS = ["--block", "10", "--gap-frames", "2", "--map-step", "1", "--query-step", "2", "--k", "1,2", "--runs", "1",
        "--methods", "none,omp,random", "--tag-size", "0.3", "--marker-spacing", "0.6", "--workers", "1", "--quiet"]


@pytest.fixture(scope="module")
def evaluated(tiny_frames, tmp_path_factory):
    out = tmp_path_factory.mktemp("eval_frames") / "o"
    assert main(["evaluate", "--frames", str(tiny_frames), "--out", str(out), *ARGS]) == 0
    return out


def test_split_is_disjoint_and_never_adjacent(evaluated):
    split = json.loads((evaluated / "split.json").read_text())
    names = [f"f{i:03d}" for i in range(40)]
    m = [names.index(n) for n in split["map_frames"]]
    q = [names.index(n) for n in split["query_frames"]]
    assert len(m) == 20 and len(q) == 6
    assert np.abs(np.subtract.outer(m, q)).min() > 2


def test_tables_hold_every_image_set_and_the_gap_table(evaluated):
    rows = read_recall_csv(evaluated / "recall.csv")
    sets = {r["test_set"] for r in rows}
    assert sets == {"real@frames", "real@render", "render@render"}
    assert {r["method"] for r in rows} == {"none", "omp", "random"}
    md = (evaluated / "tables.md").read_text()
    assert "gap table" in md and "Paired differences" in md
    html = (evaluated / "report.html").read_text()
    assert "Composited query frames" in html and "data:image/jpeg;base64" in html
    assert all(r["n_tests"] == 6 and 0.0 <= r["recall"] <= 1.0 for r in rows)


def test_composited_tags_are_found_by_the_detector_where_they_are_in_view(evaluated, tiny_frames):
    """The tags of every evaluated map, composited into every frame by the pipeline's own worker:
    each tag wholly inside the image (10 px margin), unhidden and at least 24 px across is found
    by the real detector with its id, its corners within 1.5 px of the projection of its corners;
    no tag is found that was not put in."""
    from markerplace.geometry import project
    from markerplace.imaging.config import ImagingConfig
    from markerplace.localization.sift import SIFT_DEFAULT
    from markerplace.localization.tags import detect_tags
    from markerplace.markers import marker_from_json
    from markerplace.scan.frames import open_frameset
    from markerplace.testbed.frames.config import FramesEvalConfig
    from markerplace.testbed.frames.frame_features import FrameJobSpec, FrameWorker, frame_in_view, real_image

    markers = {}
    for path in (evaluated / "cache" / "maps").glob("*/markers.json"):
        for d in json.loads(path.read_text()):
            m = marker_from_json(d)
            markers[(m.tag_id, tuple(np.round(m.world_from_marker[:3, 3], 4)))] = m
    fs = open_frameset(tiny_frames)
    worker = FrameWorker(FrameJobSpec(fs, None, ImagingConfig(camera=fs.intrinsics, sift=SIFT_DEFAULT),
                                      FramesEvalConfig().composite, 0))
    K, W, H = fs.intrinsics.K, fs.intrinsics.width, fs.intrinsics.height
    checked = 0
    for m in markers.values():
        for f, rec in enumerate(fs.frames):
            if not frame_in_view(rec.world_from_cam, K, (W, H), [m])[0]:
                continue
            rgb, _, stats = real_image(worker, f, [m])
            dets = detect_tags(rgb)
            assert {d.tag_id for d in dets} <= {m.tag_id}
            uv, z = project(K, rec.world_from_cam, m.corners_world())
            inside = np.all(z > 0) and np.all((uv > 10) & (uv < np.array([W - 10, H - 10])))
            side = np.min(np.linalg.norm(uv - np.roll(uv, 1, axis=0), axis=1))
            if inside and stats[0].visible_fraction > 0.99 and side >= 24:
                checked += 1
                assert len(dets) == 1, (f, m.tag_id, side)
                assert np.abs(np.asarray(dets[0].corners) - uv).max() < 1.5
    assert checked >= 3, "too few frames show a tag wholly: the sequence does not test compositing"


def test_rerun_reuses_every_image_and_localization(evaluated, tiny_frames, capsys):
    before = {p.name: p.stat().st_mtime_ns for p in (evaluated / "cache").rglob("*.npz")}
    assert main(["evaluate", "--frames", str(tiny_frames), "--out", str(evaluated), *ARGS]) == 0
    after = {p.name: p.stat().st_mtime_ns for p in (evaluated / "cache").rglob("*.npz")}
    assert before == after


@pytest.mark.parametrize("extra, message", [
    (["tiny"], "give no scene"),
    (["--map", "photos"], "--map"),
    (["--block", "30"], "too few"),
])
def test_bad_input_is_one_line(extra, message, tiny_frames, tmp_path, capsys):
    args = ["evaluate", "--frames", str(tiny_frames), "--out", str(tmp_path / "o"), *ARGS]
    if extra == ["tiny"]:
        args = ["evaluate", "tiny", *args[1:]]
    else:
        args += extra
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error:") and message in err[0], err


def test_store_keys_do_not_depend_on_marker_order(tmp_path):
    from markerplace.markers import Marker
    from markerplace.testbed.frames.store import image_key

    a = Marker(1, 0.2, np.eye(4))
    T = np.eye(4)
    T[0, 3] = 1.0
    b = Marker(2, 0.2, T)
    store = FeatureStore(tmp_path, "k")
    assert store._path(image_key("real", 3, [a, b])) == store._path(image_key("real", 3, [b, a]))
    assert store._path(image_key("real", 3, [a])) != store._path(image_key("render", 3, [a]))
