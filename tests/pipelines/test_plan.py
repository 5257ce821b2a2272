"""`markerplace plan` end to end on the tiny scene: outputs, stage reuse, errors, exported meshes."""

import csv
import json

import numpy as np
import pytest

from helpers import FAST
from markerplace.cli.main import main


@pytest.fixture(scope="module")
def tiny_plan(run_plan):
    return run_plan(2)


def test_plan_writes_every_output(tiny_plan):
    for name in ("placement.json", "placement.csv", "scores.npz", "scores.png", "gain_first.png",
                 "placement.png", "config.json", "discretization.npz", "observations/descriptors.npy"):
        assert (tiny_plan / name).stat().st_size > 0, name
    plan = json.loads((tiny_plan / "placement.json").read_text())
    assert plan["method"] == "omp" and len(plan["markers"]) == 2
    m = plan["markers"][0]
    for key in ("order", "tag_id", "family", "size", "position", "normal", "yaw_deg", "world_from_marker", "gain"):
        assert key in m
    assert m["order"] == 1 and m["family"] == "tag36h11" and m["gain"] > 0
    T = np.array(m["world_from_marker"])
    assert np.allclose(T[:3, 2], m["normal"], atol=1e-3) and np.allclose(T[:3, 3], m["position"], atol=1e-3)
    assert abs(m["position"][2] - 1.5) < 1e-6  # on the eye-level plane
    assert plan["markers"][0]["gain"] >= plan["markers"][1]["gain"]  # greedy gains never increase
    rows = list(csv.DictReader((tiny_plan / "placement.csv").open()))
    assert [int(r["tag_id"]) for r in rows] == [mk["tag_id"] for mk in plan["markers"]]
    sheets = sorted(p.name for p in (tiny_plan / "tags").glob("*.svg"))
    assert sheets == [f"{mk['order']:02d}_tag{mk['tag_id']}.svg" for mk in plan["markers"]]
    scores = np.load(tiny_plan / "scores.npz")
    assert scores["score_after"].shape == scores["score_before"].shape
    assert np.all(scores["score_after"] >= scores["score_before"] - 1e-9)
    assert scores["score_after"].mean() > scores["score_before"].mean()
    config = json.loads((tiny_plan / "config.json").read_text())
    assert config["placement"]["k"] == 2 and config["discretize"]["grid_spacing"] == 1.0


def test_second_run_reuses_stages_and_baselines_work(tiny_plan):
    obs_meta = (tiny_plan / "observations.meta.json").stat().st_mtime_ns
    assert main(["plan", "tiny", "-k", "3", "--method", "random", "--out", str(tiny_plan), *FAST]) == 0
    assert (tiny_plan / "observations.meta.json").stat().st_mtime_ns == obs_meta
    plan = json.loads((tiny_plan / "placement.json").read_text())
    assert plan["method"] == "random" and len(plan["markers"]) == 3
    assert main(["plan", "tiny", "-k", "3", "--method", "uniform", "--out", str(tiny_plan), *FAST]) == 0
    assert len({tuple(m["position"]) for m in json.loads((tiny_plan / "placement.json").read_text())["markers"]}) == 3


def test_existing_markers_count_as_placed(tiny_plan, tmp_path):
    first = json.loads((tiny_plan / "placement.json").read_text())["markers"][:1]
    existing = tmp_path / "existing.json"
    existing.write_text(json.dumps({"markers": first}))
    out = tmp_path / "with_existing"
    assert main(["plan", "tiny", "-k", "1", "--existing", str(existing), "--out", str(out), *FAST]) == 0
    plan = json.loads((out / "placement.json").read_text())
    assert plan["markers"][0]["position"] != first[0]["position"]
    assert plan["markers"][0]["tag_id"] != first[0]["tag_id"]


@pytest.mark.parametrize("args, message", [
    (["tiny", "-k", "2", "-v", "150"], "outside [0, 100]"),
    (["tiny", "-k", "0"], "at least 1"),
    (["tiny", "-k", "500"], "only"),
    (["tiny", "-k", "2", "--yaws", "0"], "--yaws"),
    (["tiny", "-k", "2", "--grid-spacing", "0"], "--grid-spacing"),
    (["tiny", "-k", "2", "--start", "0.0,0.0"], "start"),
    (["tiny", "-k", "2", "--height", "4.0"], "no walls"),
    (["missing_file.glb", "-k", "2"], "no such file"),
])
def test_plan_errors_are_one_line(args, message, tmp_path, capsys):
    code = main(["plan", args[0], "--out", str(tmp_path / "o"), *FAST, *args[1:]])  # case options win
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert len(err) == 1 and err[0].startswith("markerplace: error:") and message in err[0], err


def test_exported_mesh_plans_like_the_builtin(tiny_plan, tmp_path):
    glb = tmp_path / "tiny.glb"
    assert main(["scene", "export", "tiny", str(glb)]) == 0
    out = tmp_path / "from_glb"
    assert main(["plan", str(glb), "-k", "2", "--out", str(out), *FAST]) == 0
    builtin_out = tmp_path / "builtin"
    assert main(["plan", "tiny", "-k", "2", "--out", str(builtin_out), *FAST]) == 0
    a = json.loads((builtin_out / "placement.json").read_text())["markers"]
    b = json.loads((out / "placement.json").read_text())["markers"]
    assert len(a) == len(b) == 2
    for ma, mb in zip(a, b):
        assert np.allclose(ma["position"], mb["position"], atol=0.02)
        assert np.allclose(ma["normal"], mb["normal"], atol=0.02)


def test_every_candidate_offered_is_seen_by_some_pose(tmp_path):
    """prepare() drops candidates that no camera pose sees (occlusion included) and counts them:
    no method can place a tag nobody sees."""
    from dataclasses import replace

    from markerplace.pipelines.plan import prepare
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.discretize.stage import DiscretizeConfig
    from markerplace.runtime.executor import RuntimeConfig
    from markerplace.scene.spec import SceneSpec

    config = PlanConfig(discretize=replace(DiscretizeConfig(), grid_spacing=1.0, num_yaws=2),
                        runtime=RuntimeConfig(workers=1))
    data = prepare(SceneSpec("tiny"), config, tmp_path, progress=False)
    C = data.num_candidates
    assert C == len(data.disc.candidate_position) >= 4
    assert all(len(cov.pose_idx) > 0 for cov in data.coverages[:C])
    removed = data.disc.summary["candidates_removed"]
    assert removed["not seen"] >= 1  # with 2 yaws on a 1 m grid some walls face no camera
    from markerplace.plan.discretize.candidate_rules import RULES

    assert set(removed) == {*RULES, "not seen"}
    assert removed["furniture"] >= 1 and removed["pictures"] >= 1  # tiny's bookshelf, cabinet and picture
