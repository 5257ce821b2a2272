"""``plan --exclude FILE``: the file format and its one-line errors, which candidates a spot or
box removes, what a replan changed, and a replan of a cached ``tiny`` run that renders nothing
and drops the excluded spot."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from helpers import FAST_2_YAWS as FAST
from markerplace.cli.main import main
from markerplace.errors import UserError
from markerplace.plan.discretize.exclusion import describe_changes, excluded, load_exclusion, placement_changes


def write(tmp_path, doc, name="x.json"):
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def test_spots_and_boxes(tmp_path):
    ex = load_exclusion(write(tmp_path, {
        "format": "markerplace-exclude/1", "scene": "tiny", "note": "review of 3 May",
        "spots": [{"x": 1.0, "y": 0.0, "z": 1.5, "radius": 0.25, "order": 3, "tag_id": 2, "note": "door swings"},
                  {"x": 3.0, "y": 3.0, "z": 1.5}],
        "boxes": [{"min": [4.0, -1.0, 0.0], "max": [5.0, 1.0, 2.7], "note": "to be painted"}]}))
    assert ex.radius.tolist() == [0.25, 0.3]  # default radius
    p = np.array([[1.0, 0.2, 1.5], [1.0, 0.3, 1.5], [3.2, 3.1, 1.5], [4.0, 1.0, 1.5], [5.01, 0.0, 1.5]])
    assert excluded(ex, p).tolist() == [True, False, True, True, False]  # box bounds included
    back = load_exclusion(write(tmp_path, ex.to_json(), "back.json"))
    assert np.array_equal(back.spots, ex.spots) and np.array_equal(back.boxes, ex.boxes)


@pytest.mark.parametrize("doc, message", [
    ("{not json", "not valid JSON"),
    ("[" * 100_000, "100000 deep"),
    ([1, 2], "must be a JSON object"),
    ({"spots": []}, "nothing to exclude"),
    ({"spots": [{"x": 1, "y": 2}]}, "spot 1 has no z"),
    ({"spots": [{"x": 1, "y": 2, "z": "high"}]}, "spot 1 z must be a finite number"),
    ({"spots": [{"x": 1, "y": 2, "z": 1.5, "radius": -1}]}, "radius must be positive"),
    ({"spots": [{"x": 1, "y": 2, "z": 1.5, "radius_m": 1}]}, "unknown key(s) 'radius_m'"),
    ({"boxes": [{"min": [0, 0, 0], "max": [1, -1, 1]}]}, "above max"),
    ({"boxes": [{"min": [0, 0], "max": [1, 1, 1]}]}, "box 1 needs 'min'"),
    ({"walls": []}, "unknown key(s) 'walls'"),
    ({"format": "other/2", "spots": [{"x": 0, "y": 0, "z": 0}]}, "is not 'markerplace-exclude/1'"),
])
def test_bad_files_are_one_line_errors(tmp_path, doc, message):
    with pytest.raises(UserError) as err:
        load_exclusion(write(tmp_path, doc if isinstance(doc, str) else json.dumps(doc)))
    assert message in str(err.value) and "\n" not in str(err.value)


def test_cli_refuses_a_bad_file_with_exit_2(tmp_path, capsys):
    assert main(["plan", "tiny", "-k", "2", "--out", str(tmp_path / "p"), "--exclude", str(tmp_path / "none.json"),
                 *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("markerplace: error: --exclude") and "no such file" in err[0]
    assert not (tmp_path / "p" / "placement.json").exists()


def rec(order, tag_id, pos, normal=(0.0, 1.0, 0.0)):
    return {"order": order, "tag_id": tag_id, "position": list(pos), "normal": list(normal)}


def test_placement_changes():
    old = [rec(1, 0, (1, 0, 1.5)), rec(2, 1, (3, 0, 1.5)), rec(3, 2, (0, 2, 1.5), (1, 0, 0)), rec(4, 3, (5, 5, 1.5))]
    new = [rec(1, 0, (3, 0, 1.5)), rec(2, 1, (1.004, 0, 1.5)), rec(3, 2, (0, 3.2, 1.5), (1, 0, 0)),
           rec(4, 3, (9, 9, 1.5), (-1, 0, 0))]
    ch = placement_changes(old, new)
    assert [(a["order"], b["order"]) for a, b in ch["kept"]] == [(1, 2), (2, 1)]
    assert [(a["order"], b["order"], round(d, 2)) for a, b, d in ch["moved"]] == [(3, 3, 1.2)]
    assert [a["order"] for a in ch["removed"]] == [4] and [b["order"] for b in ch["added"]] == [4]
    lines = describe_changes(ch)
    assert lines[0] == ("changes against the previous placement.json: 2 kept (2 of them renumbered), 1 moved, "
                        "1 removed, 1 added")
    assert any(line.strip().startswith("removed: #4 (tag id 3) at (5.00, 5.00, 1.50)") for line in lines)


@pytest.fixture(scope="module")
def tiny_run(run_plan):
    return run_plan(3, options=FAST, folder="exclude")


def test_replan_with_exclude_renders_nothing_and_drops_the_spot(tiny_run, tmp_path, monkeypatch, capsys):
    import markerplace.plan.discretize.stage as discretize_stage
    import markerplace.plan.observe as observe_stage
    import markerplace.plan.similarity.stage as similarity_stage

    capsys.readouterr()
    first = json.loads((tiny_run / "placement.json").read_text())["markers"]
    assert all(m["surface"] == "wall" and m["surface_part"].startswith("tiny/wall/") for m in first)
    x, y, z = first[0]["position"]
    path = write(tmp_path, {"spots": [{"x": x, "y": y, "z": z, "radius": 0.2}]})

    def no_stage(*args, **kwargs):
        raise AssertionError("a cached stage ran again")

    monkeypatch.setattr(observe_stage, "observe", no_stage)  # rendering + SIFT
    monkeypatch.setattr(discretize_stage, "discretize", no_stage)
    monkeypatch.setattr(similarity_stage, "count_similar", no_stage)
    assert main(["plan", "tiny", "-k", "3", "--out", str(tiny_run), "--exclude", str(path), *FAST]) == 0
    out = capsys.readouterr().out
    assert "changes against the previous placement.json" in out
    after = json.loads((tiny_run / "placement.json").read_text())["markers"]
    assert len(after) == 3
    assert min(np.linalg.norm(np.array(m["position"]) - [x, y, z]) for m in after) > 0.2  # the spot is gone
    assert re.search(r"(moved|removed): #1 \(tag id 0\) at", out)
    config = json.loads((tiny_run / "config.json").read_text())
    assert config["exclude"]["spots"][0]["x"] == pytest.approx(x)


def test_exclude_that_leaves_too_few_candidates_is_refused(tiny_run, tmp_path, capsys):
    path = write(tmp_path, {"boxes": [{"min": [-10, -10, -10], "max": [10, 10, 10]}]})
    assert main(["plan", "tiny", "-k", "3", "--out", str(tiny_run), "--exclude", str(path), *FAST]) == 2
    assert "fewer than -k 3" in capsys.readouterr().err


def test_exclusion_masks_candidates_and_the_calibrations_coverages(tiny_run):
    """exclude_candidates keeps the candidate arrays, coverages, visibility and a calibrated
    method's coverages aligned (existing markers stay at the end)."""
    from markerplace.pipelines.plan import prepare
    from markerplace.plan.discretize.exclusion import exclude_candidates
    from markerplace.plan.folder import read_plan_folder

    folder = read_plan_folder(tiny_run)
    data = prepare(folder.spec, folder.config, tiny_run, progress=False)  # every stage cached
    C = data.num_candidates
    data.calibration["fake"] = {"model": None, "coverages": list(data.coverages)}
    drop = np.zeros(C, bool)
    drop[[0, C - 1]] = True
    out = exclude_candidates(data, drop)
    keep = np.flatnonzero(~drop)
    assert out.num_candidates == C - 2 == len(out.disc.candidate_position) == len(out.disc.candidate_surface)
    assert [c.pose_idx.tolist() for c in out.coverages] == [data.coverages[i].pose_idx.tolist() for i in keep]
    assert out.calibration["fake"]["coverages"] == out.coverages
    assert np.array_equal(out.visible, data.visible[:, keep])
    assert np.array_equal(out.disc.candidate_position, data.disc.candidate_position[keep])
