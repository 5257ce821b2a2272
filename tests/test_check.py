"""`markerplace check PLAN_DIR --installed FILE`: installed tags vs the plan, from the cached stages."""

from __future__ import annotations

import json

import numpy as np
import pytest

from markerplace.cli.main import main

FAST = ["--grid-spacing", "1.0", "--yaws", "4", "--workers", "1", "--quiet"]


@pytest.fixture(scope="module")
def plan(tmp_path_factory):
    out = tmp_path_factory.mktemp("check") / "tiny"
    assert main(["plan", "tiny", "-k", "4", "--out", str(out), *FAST]) == 0
    return out


def markers_of(plan):
    return json.loads((plan / "placement.json").read_text())["markers"]


def test_installed_coverages_are_the_plans_own(plan):
    """The same code as --existing and the candidates: a tag at a candidate pose covers the same
    poses with the same information as that candidate in the plan."""
    from markerplace.markers import Marker
    from markerplace.plan.check import installed_coverages
    from markerplace.plan.folder import read_plan_folder
    from markerplace.plan.planner import prepare
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
    assert "no camera location lost anything" in capsys.readouterr().out


def test_shifted_missing_swapped_and_extra_tags(plan, tmp_path, capsys):
    from markerplace.plan.discretization import load

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
    assert "move it 0.30 m" in r1["note"]
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
    assert (out / "check_map.png").stat().st_size > 0
    assert len((out / "check.csv").read_text().strip().splitlines()) == 1 + 5
    layout = json.loads((out / "tagmaps" / "wpilib_field_layout.json").read_text())
    assert sorted(t["ID"] for t in layout["tags"]) == sorted([a["tag_id"], c["tag_id"], d["tag_id"], 50])


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
