"""`markerplace check PLAN_DIR --installed FILE`: installed tags vs the plan, from the cached stages."""

from __future__ import annotations

import json

import numpy as np
import pytest

from helpers import negative_zeros
from helpers.browser import check_page, click_tag, view_call
from markerplace.cli.main import main


@pytest.fixture(scope="module")
def plan(run_plan):
    return run_plan(4, folder="check")


def missing_marks(png) -> int:
    """Pixels of the map in the colour of the missing-tag crosses."""
    from PIL import Image

    from markerplace.report.figures import MISSING_COLOR

    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    rgb = [int(MISSING_COLOR[i:i + 2], 16) for i in (1, 3, 5)]
    return int((np.abs(img - rgb).sum(axis=2) < 30).sum())


def markers_of(plan):
    return json.loads((plan / "placement.json").read_text())["markers"]


def test_installed_coverages_are_the_plans_own(plan):
    """The same code as --existing and the candidates: a tag at a candidate pose covers the same
    poses with the same information as that candidate in the plan."""
    from markerplace.markers import Marker
    from markerplace.pipelines.plan import prepare
    from markerplace.plan.folder import read_plan_folder
    from markerplace.plan.installed_vs_plan import installed_coverages
    from markerplace.runtime.executor import RuntimeConfig, make_executor

    folder = read_plan_folder(plan)
    with make_executor(RuntimeConfig(workers=1)) as ex:
        data = prepare(folder.spec, folder.config, plan, progress=False, executor=ex)
        cands = list(range(data.num_candidates))
        ms = [Marker(i, folder.config.placement.tag_size, data.disc.candidate_world_from_marker[c]) for i, c in enumerate(cands)]
        covs = installed_coverages(folder.spec, data.disc.world_from_cam, ms, folder.config, ex)
    assert sum(len(c.pose_idx) for c in covs) > 0
    for c, cov in zip(cands, covs):
        assert np.array_equal(cov.pose_idx, data.coverages[c].pose_idx)
        assert np.array_equal(cov.info, data.coverages[c].info)


def test_installed_as_planned_loses_nothing(plan, tmp_path, capsys):
    out = tmp_path / "same"
    assert main(["check", str(plan), "--installed", str(plan / "placement.json"), "--out", str(out)]) == 0
    report = json.loads((out / "check.json").read_text())
    assert [t["status"] for t in report["tags"]] == ["as planned"] * 4
    assert abs(report["summary"]["mean_score_lost"]) < 1e-6
    scores = np.load(plan / "scores.npz")
    assert report["summary"]["mean_score_planned"] == pytest.approx(scores["score_after"].mean(), abs=1e-9)
    text = capsys.readouterr().out
    assert "no camera location lost anything" in text and not negative_zeros(text)
    assert missing_marks(out / "check_map.png") == 0


def test_shifted_missing_swapped_and_extra_tags(plan, tmp_path, capsys):
    from markerplace.plan.discretize.artifact import load

    ms = markers_of(plan)
    a, b, c, d = ms
    T = np.array(a["world_from_marker"])
    shifted = T[:3, 3] + 0.3 * T[:3, 0]  # 30 cm along the wall
    planned_xyz = np.array([m["position"] for m in ms])
    cands = load(plan / "discretization.npz").candidate_position
    far = cands[np.argmax(np.min(np.linalg.norm(cands[:, None] - planned_xyz[None], axis=2), axis=1))]
    far_T = load(plan / "discretization.npz").candidate_world_from_marker[
        int(np.argmin(np.linalg.norm(cands - far, axis=1)))]
    installed = [
        {"tag_id": a["tag_id"], "position": shifted.tolist(), "normal": a["normal"]},  # simple format, plan's size
        {"tag_id": d["tag_id"], "size": d["size"], "world_from_marker": c["world_from_marker"]},  # swapped
        {"tag_id": c["tag_id"], "size": c["size"], "world_from_marker": d["world_from_marker"]},
        {"tag_id": 50, "size": 0.4, "world_from_marker": far_T.tolist()},  # not in the plan; b left out
    ]
    path = tmp_path / "installed.json"
    path.write_text(json.dumps(installed))
    out = tmp_path / "chk"
    assert main(["check", str(plan), "--installed", str(path), "--out", str(out), "--match-radius", "0.5"]) == 0
    text = capsys.readouterr().out
    report = json.loads((out / "check.json").read_text())
    rows = {(r["order"], r["status"]): r for r in report["tags"]}
    assert [r["status"] for r in report["tags"]] == ["shifted", "missing", "swapped", "swapped", "extra"]
    r1 = rows[1, "shifted"]
    assert r1["shift_m"] == pytest.approx(0.3, abs=2e-4) and r1["shift_deg"] < 0.1
    # hung 0.3 m along the marker's +x (to the right as you face the wall): move it back to the left
    assert r1["note"] == "move it 0.30 m left (as you face the wall)", r1["note"]
    assert r1["move"]["right_m"] == pytest.approx(-0.3, abs=2e-4) and abs(r1["move"]["up_m"]) < 1e-4
    r2 = rows[2, "missing"]
    assert r2["installed_id"] is None and r2["score_lost"] > 0 and r2["score_lost_seen"] > r2["score_lost"]
    for order, (mine, theirs) in ((3, (c, d)), (4, (d, c))):
        r = rows[order, "swapped"]
        assert r["planned_id"] == mine["tag_id"] and r["installed_id"] == theirs["tag_id"]
        assert r["shift_m"] < 1e-5 and abs(r["score_lost"]) < 1e-5  # same geometry: nothing lost, map is wrong
    extra = rows[None, "extra"]
    assert extra["installed_id"] == 50 and extra["score_lost"] <= 1e-12  # an extra tag never hurts
    s = report["summary"]
    assert s["mean_score_lost"] == pytest.approx(s["mean_score_planned"] - s["mean_score_installed"])
    # the mean may go either way: the extra tag adds what the missing one takes
    assert s["statuses"] == {"shifted": 1, "missing": 1, "swapped": 2, "extra": 1}
    worst = report["worst_locations"]
    assert worst and worst[0]["score_lost"] > 0 and worst[0]["storey"] == 0
    assert [w["score_lost"] for w in worst] == sorted((w["score_lost"] for w in worst), reverse=True)
    assert "camera locations that lost most" in text and f"storey 0 (floor 0.00 m) at ({worst[0]['x']:.2f}" in text
    for written in (text, (out / "check.csv").read_text(), (out / "check.json").read_text()):
        assert not negative_zeros(written), negative_zeros(written)
    assert missing_marks(out / "check_map.png") > 0  # the missing tag is marked on the map
    assert len((out / "check.csv").read_text().strip().splitlines()) == 1 + 5
    layout = json.loads((out / "tagmaps" / "wpilib_field_layout.json").read_text())
    assert sorted(t["ID"] for t in layout["tags"]) == sorted([a["tag_id"], c["tag_id"], d["tag_id"], 50])


def test_check_html_shows_the_installed_tags_in_3d(plan, browser, tmp_path, capsys):
    """check.html (report/check_page.py): the cards, and the planned and installed tags in 3D."""
    a, b = markers_of(plan)[:2]
    T = np.array(a["world_from_marker"])
    installed = [{"tag_id": a["tag_id"], "position": (T[:3, 3] + 0.3 * T[:3, 0]).tolist(), "normal": a["normal"]},
                 {"tag_id": b["tag_id"], "size": b["size"], "world_from_marker": b["world_from_marker"]}]
    (tmp_path / "hung.json").write_text(json.dumps(installed))
    out = tmp_path / "check"
    assert main(["check", str(plan), "--installed", str(tmp_path / "hung.json"), "--out", str(out), "--quiet"]) == 0
    assert "check.html" in capsys.readouterr().out
    page = check_page(browser, out / "check.html")
    assert page["images"] == ["check_map.png"]
    assert "#1: planned id" in page["text"] and page["text"].count("status missing") == 2
    assert view_call(browser, "mp-view3d-check", "error") is None
    tags = view_call(browser, "mp-view3d-check", "projectedTags()")
    assert [(t["kind"], t["label"], t["card"]) for t in tags] == [
        *(("planned", str(i), f"tag{i}") for i in (1, 2, 3, 4)),  # #3 and #4 missing
        ("found", f"id {a['tag_id']}", "tag1"), ("found", f"id {b['tag_id']}", "tag2")]
    view_call(browser, "mp-view3d-check", "focusTag('found', 0)")  # the shifted tag selects the card of its spot
    assert click_tag(browser, "mp-view3d-check", "found", 0) == ["tag1"]


def test_directions_in_the_installers_terms():
    """Hand-made installed poses against a planned one on a wall facing +y: the words say how to
    move and turn the tag as a person facing the wall sees it (their right is the wall's -x)."""
    from markerplace.geometry import world_from_marker_pose
    from markerplace.plan.installed_vs_plan import correction, directions

    P = world_from_marker_pose(np.array([2.0, 0.0, 1.5]), np.array([0.0, 1.0, 0.0]))
    x_right = P[:3, 0]
    assert np.allclose(x_right, [-1, 0, 0])  # facing the wall (looking along -y), right is -x
    hung = world_from_marker_pose(np.array([2.2, 0.03, 1.4]), np.array([0.0, 1.0, 0.0]))  # 0.2 m to the left, low, proud
    assert directions(correction(P, hung)) == "move it 0.20 m right and 0.10 m up and 0.03 m into the wall (as you face the wall)"
    turned = P.copy()
    a = np.radians(90)  # rotated 90 deg counter-clockwise on the wall (as seen facing it)
    turned[:3, :3] = P[:3, :3] @ np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    assert directions(correction(P, turned)) == "turn it 90 deg clockwise (as you face the wall)"
    upside = P.copy()
    upside[:3, :2] *= -1
    assert "upside down" in directions(correction(P, upside))
    yawed = world_from_marker_pose(np.array([2.0, 0.0, 1.5]), np.array([np.sin(np.radians(-10)), np.cos(np.radians(10)), 0]))
    words = directions(correction(P, yawed))
    assert "faces 10 deg to your right" in words, words  # its normal turned towards -x: the person's right
    assert directions(correction(P, P)) == ""


@pytest.mark.parametrize("case, message", [
    ("nodir", "is not a folder"),
    ("notplan", "is not a plan folder"),
    ("nofile", "no such file"),
    ("badjson", "not valid JSON"),
    ("twice", "listed twice"),
    ("nonormal", "entry 0"),
])
def test_check_errors_are_one_line(plan, case, message, tmp_path, capsys):
    folder, installed = str(plan), tmp_path / "i.json"
    installed.write_text(json.dumps([{"tag_id": 0, "position": [1, 1, 1.5], "normal": [1, 0, 0]}]))
    if case == "nodir":
        folder = str(tmp_path / "missing")
    elif case == "notplan":
        folder = str(tmp_path)
    elif case == "nofile":
        installed = tmp_path / "absent.json"
    elif case == "badjson":
        installed.write_text("[{")
    elif case == "twice":
        installed.write_text(json.dumps([{"tag_id": 0, "position": [1, 1, 1.5], "normal": [1, 0, 0]}] * 2))
    elif case == "nonormal":
        installed.write_text(json.dumps([{"tag_id": 0, "position": [1, 1, 1.5]}]))
    code = main(["check", folder, "--installed", str(installed), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
