"""Query conditions (markerplace.simulation.conditions): deterministic per seed, a measured change in
the documented range, the map's light untouched, the CLI's check, and an evaluation that
reports a row per condition while the clean results and caches stay those of a clean run."""

import csv
import json

import numpy as np
import pytest

from markerplace.imaging import degrade
from markerplace.render.renderer import Lighting, RenderResult
from markerplace.simulation import conditions as cond
from markerplace.simulation.conditions import CONDITIONS, QueryCondition, degrade_render, set_name, split_set

POSE = np.eye(4)
K = np.array([[300.0, 0.0, 159.5], [0.0, 300.0, 119.5], [0.0, 0.0, 1.0]])  # for 320 x 240 images


def _image():
    """A textured image in 30..110 (no clipping by +1 EV or a 0.25 white-balance shift)."""
    rng = np.random.default_rng(5)
    base = rng.integers(30, 110, (60, 80, 3)).astype(np.uint8)
    return np.ascontiguousarray(np.repeat(np.repeat(base, 4, axis=0), 4, axis=1))  # 240 x 320, 4 px blocks


def _apply(name, index, rgb=None, test_set="weighted", seed=0):
    """(degraded rgb, drawn parameters, lighting asked for) of image ``index`` under ``name``."""
    rgb = _image() if rgb is None else rgb
    lights = []

    def render(light):
        lights.append(light)
        return RenderResult(rgb, np.full(rgb.shape[:2], 10.0, np.float32), None, POSE)

    res, params = degrade_render(POSE, QueryCondition(name, test_set, seed).image(index), render, K)
    return res.rgb, params, lights[0]


def test_names_and_registry():
    assert cond.condition_names() == ("clean", "exposure", "white_balance", "lighting", "noise", "blur", "occluders")
    assert set_name("weighted", "clean") == "weighted" and set_name("uniform", "blur") == "uniform@blur"
    assert split_set("uniform@blur") == ("uniform", "blur") and split_set("weighted") == ("weighted", "clean")
    for c in CONDITIONS.values():
        assert c.summary and c.__doc__ and c.default_conf.__doc__


@pytest.mark.parametrize("name", ["clean", "exposure", "white_balance", "lighting", "noise", "blur", "occluders"])
def test_each_condition_is_deterministic_given_its_seed(name):
    a, pa, la = _apply(name, 3)
    b, pb, lb = _apply(name, 3)
    assert np.array_equal(a, b) and pa == pb and la == lb
    if name in ("clean", "lighting"):  # image filters only; lighting changes the render
        assert np.array_equal(a, _image())
    else:
        assert not np.array_equal(a, _image())
    if name != "clean":  # other images, test sets and test seeds draw other parameters
        others = [_apply(name, 4)[1], _apply(name, 3, test_set="uniform")[1], _apply(name, 3, seed=1)[1]]
        assert all(o != pa for o in others)
    key = QueryCondition(name, "weighted", 0).key()
    assert key == QueryCondition(name, "weighted", 0).key() != QueryCondition(name, "weighted", 1).key()


def test_exposure_changes_mean_intensity_within_one_stop():
    img = _image().astype(float)
    evs = []
    for i in range(20):
        out, p, _ = _apply("exposure", i)
        ratio = out.mean() / img.mean()
        assert ratio == pytest.approx(2 ** (p["ev"] / degrade.GAMMA), rel=0.01)
        evs.append(p["ev"])
    assert -1.0 <= min(evs) < -0.3 and 0.3 < max(evs) <= 1.0


def test_white_balance_shifts_red_against_blue_within_range():
    img = _image().astype(float)
    for i in range(10):
        out, p, _ = _apply("white_balance", i)
        out = out.astype(float)
        rg = np.log(out[..., 0].mean() / img[..., 0].mean())
        bg = np.log(out[..., 2].mean() / img[..., 2].mean())
        assert abs(p["shift"]) <= 0.25
        assert rg == pytest.approx(p["shift"] / degrade.GAMMA, abs=0.01)
        assert bg == pytest.approx(-p["shift"] / degrade.GAMMA, abs=0.01)
        assert np.array_equal(out[..., 1], img[..., 1])


def test_noise_std_follows_the_signal():
    flat = np.full((200, 200, 3), 100, np.uint8)
    for i in range(5):
        out, p, _ = _apply("noise", i, flat)
        assert 0.2 <= p["shot"] <= 0.8 and p["read"] == 2.0
        assert out.astype(float).var() == pytest.approx(p["shot"] * 100 + 4 + 1 / 12, rel=0.05)


def test_blur_spreads_a_point_along_its_direction_by_the_drawn_length():
    point = np.zeros((41, 41, 3), np.uint8)
    point[20, 20] = 255
    for i in range(6):
        out, p, _ = _apply("blur", i, point)
        assert 2.0 <= p["length"] <= 8.0 and 0.0 <= p["defocus"] <= 0.7
        w = out[..., 0].astype(float)
        ys, xs = np.mgrid[:41, :41]
        u = (xs - 20) * np.cos(p["angle"]) + (ys - 20) * np.sin(p["angle"])
        v = -(xs - 20) * np.sin(p["angle"]) + (ys - 20) * np.cos(p["angle"])
        var_u, var_v = (w * u ** 2).sum() / w.sum(), (w * v ** 2).sum() / w.sum()
        # segment (L^2 / 12) plus defocus (sigma^2) along; defocus alone across (+ splatting)
        assert var_u == pytest.approx(p["length"] ** 2 / 12 + p["defocus"] ** 2, abs=0.4)
        assert var_v == pytest.approx(p["defocus"] ** 2, abs=0.4)


def test_occluders_are_person_sized_and_stand_in_front():
    img = _image()
    for i in range(6):
        out, p, _ = _apply("occluders", i)
        people = p["people"]
        assert 1 <= len(people) <= 2 and all(1.0 <= q["distance"] <= 4.0 for q in people)
        changed = np.any(out != img, axis=2)
        near = min(people, key=lambda q: q["distance"])
        cols = np.flatnonzero(changed.any(axis=0))
        # at least the nearest person's width: fx * 0.5 m / distance pixels (clipped by the border)
        width = 300.0 * 0.5 / near["distance"]
        centre = near["u"] * 319
        visible = min(centre + width / 2, 319) - max(centre - width / 2, 0)
        assert len(cols) >= visible - 2
        rows = np.flatnonzero(changed[:, int(np.clip(round(centre), 0, 319))])
        # from 0.25 m above the optical axis (1.75 m tall, camera at 1.5 m) to the floor, 1.5 m below
        top, bottom = 119.5 - 300.0 * 0.25 / near["distance"], 119.5 + 300.0 * 1.5 / near["distance"]
        assert abs(rows.min() - top) <= 1.5 and abs(rows.max() - min(bottom, 239)) <= 1.5
    # nothing is pasted where the scene is nearer than the person
    from markerplace.imaging.degrade import occlude

    person = {"distance": 2.0, "u": 0.5, "colour": [50, 50, 50], "folds": np.ones((4, 8)).tolist()}
    depth = np.full((240, 320), 5.0, np.float32)
    depth[:, :160] = 1.0  # a wall 1 m away on the left half
    out = occlude(img, depth, K, [person])
    changed = np.any(out != img, axis=2)
    assert not changed[:, :160].any() and changed[:, 160:].sum() > 1000
    assert np.all(out[changed] == 50)  # colour x folds at 1.0


def test_lighting_draws_a_light_set_up_within_its_ranges():
    for i in range(10):
        _, p, light = _apply("lighting", i)
        assert isinstance(light, Lighting)
        assert 0.3 <= light.ambient <= 0.6 and 0.0 <= light.headlight <= 0.2 and 0.2 <= light.sun <= 0.5
        assert np.linalg.norm(light.sun_dir) == pytest.approx(1.0)
        assert np.sin(np.radians(20)) - 1e-9 <= light.sun_dir[2] <= np.sin(np.radians(70)) + 1e-9
        assert 0.5 <= np.linalg.norm(np.subtract(light.cut_point, POSE[:2, 3])) <= 3.0 and 0.3 <= light.dim <= 0.7


def test_relit_render_changes_the_query_and_leaves_the_map_light():
    from markerplace.geometry import Intrinsics, world_from_cam_poses
    from markerplace.render.renderer import Renderer
    from markerplace.scene.spec import SceneSpec

    T = world_from_cam_poses(np.array([[1.0, 1.0, 1.5]]), np.array([0.7]))[0]
    with Renderer(SceneSpec("tiny").load(), Intrinsics()) as r:
        clean = r.render(T).rgb
        r.set_lighting(Lighting())  # the relit shader with the map's own light
        same = r.render(T).rgb
        r.set_lighting(Lighting(ambient=0.3, headlight=0.0, sun=0.5, sun_dir=(0.6, 0.0, 0.8), dim=0.6,
                                cut_point=tuple(T[:2, 3] + [1.0, 0.0]), cut_normal=(1.0, 0.0)))
        relit = r.render(T)
        r.set_lighting(None)
        after = r.render(T).rgb
    assert np.array_equal(after, clean)  # the map's light is back, bit for bit
    assert np.abs(same.astype(int) - clean.astype(int)).max() <= 1
    assert np.abs(relit.rgb.astype(float) - clean).mean() > 20
    assert relit.rgb.mean() < clean.mean()


def test_unknown_condition_is_a_one_line_error(tmp_path, capsys):
    from markerplace.cli.main import main

    assert main(["evaluate", "tiny", "--out", str(tmp_path / "e"), "--quiet", "--conditions", "clean,fog"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--conditions" in err[0] and "fog" in err[0]
    assert all(n in err[0] for n in cond.condition_names())


FAST = ["--tests", "12", "--k", "2", "--runs", "1", "--methods", "none,omp", "--test-sets", "weighted",
        "--grid-spacing", "1.0", "--yaws", "4", "--workers", "1", "--quiet"]


def test_evaluate_reports_a_row_per_condition_and_keeps_clean_caches(tmp_path):
    from markerplace.cli.main import main

    out = tmp_path / "eval"
    assert main(["evaluate", "tiny", "--out", str(out), "--conditions", "clean,blur", *FAST]) == 0
    rows = list(csv.DictReader((out / "recall.csv").open()))
    assert list(rows[0]) == ["scene", "method", "run", "k", "test_set", "condition", "threshold", "recall", "n_tests"]
    got = {(r["method"], r["k"], r["condition"]) for r in rows if r["threshold"] == "5cm/5deg"}
    assert got == {(m, k, c) for m, k in (("none", "0"), ("omp", "2")) for c in ("clean", "blur")}
    tables = (out / "tables.md").read_text()
    assert "## Test set `weighted`, condition `blur`" in tables and "## Recall per query condition" in tables
    assert "| `clean` | `blur` |" in tables
    # paired against clean: each placement under blur minus itself on the clean images
    assert "## Query conditions against clean, paired, at 5cm/5deg" in tables
    assert "### Test set `weighted`: the tags' gain over no markers under the condition minus their clean gain" in tables
    errs = np.load(out / "query_errors.npz")
    assert errs["weighted@blur_t_err"].shape == errs["weighted_t_err"].shape == (2, 12)
    # the map is clean: one map feature set; the blurred queries have their own features and predictions
    cache = out / "cache"
    assert (cache / "query_base_weighted_blur").is_dir() and not list(cache.glob("map_base_*"))
    preds = sorted((cache / "predictions").glob("*.npz"))
    sets = sorted(json.loads(p.with_name(p.name + ".meta.json").read_text())["test_set"] for p in preds)
    assert sets == ["weighted"] * 2 + ["weighted@blur"] * 2
    stamps = {p: p.stat().st_mtime_ns for p in preds + sorted((cache / "map_base").rglob("*")) if p.is_file()}
    # a clean-only run in the same folder reuses every clean cache (keys independent of the other
    # conditions) and writes the tables without a condition column
    assert main(["evaluate", "tiny", "--out", str(out), *FAST]) == 0
    assert all(p.stat().st_mtime_ns == t for p, t in stamps.items())
    clean = list(csv.DictReader((out / "recall.csv").open()))
    assert "condition" not in clean[0]
    assert [{k: v for k, v in r.items() if k != "condition"} for r in rows if r["condition"] == "clean"] == clean
