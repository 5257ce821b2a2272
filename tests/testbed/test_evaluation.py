"""Test poses, recall and recall tables of the testbed (no rendering)."""

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.geometry import world_from_cam_poses
from markerplace.simulation import metrics
from markerplace.simulation import pose_sampling as tposes
from markerplace.testbed.reporting import tables


def _feasible(n_side=6, spacing=0.5, yaws=8):
    xs = (np.arange(n_side) + 1.0) * spacing
    xy = np.array([(x, y) for x in xs for y in xs])
    pos = np.repeat(np.c_[xy, np.full(len(xy), 1.5)], yaws, axis=0)
    yaw = np.tile(np.arange(yaws) * 2 * np.pi / yaws, len(xy))
    return world_from_cam_poses(pos, yaw), yaw


def _open_grid(size_m=4.0, res=0.05):
    n = int(size_m / res)
    occ = np.zeros((n, n), dtype=np.int8)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = 1
    return occ, (0.0, 0.0), res


# --- recall ------------------------------------------------------------------------------------

def test_recall_hand_made_errors_inclusive_and_failures_are_misses():
    t = np.array([0.01, 0.05, 0.049, 0.2, np.inf, np.nan])
    r = np.array([1.0, 5.0, 5.01, 1.0, np.inf, np.nan])
    # (0.05, 5): hits are [0.01, 1] and [0.05, 5] (inclusive); 5.01 deg and 0.2 m miss;
    # the two failures count as misses and stay in the denominator.
    assert metrics.recall(t, r, 0.05, 5.0) == pytest.approx(2 / 6)
    assert metrics.recall(t, r, 0.01, 1.0) == pytest.approx(1 / 6)
    assert metrics.recall(t, r, 1.0, 30.0) == pytest.approx(4 / 6)
    assert metrics.recalls(t, r) == pytest.approx([1 / 6, 2 / 6, 3 / 6, 4 / 6])
    assert np.isnan(metrics.recall([], [], 0.05, 5.0))


def test_pose_errors_batch_translation_rotation_and_failure():
    true, _ = _feasible(n_side=1, yaws=3)
    est = true.copy()
    est[0, :3, 3] += [0.03, 0.04, 0.0]
    est[1] = world_from_cam_poses(true[1:2, :3, 3], [np.arctan2(true[1, 1, 2], true[1, 0, 2]) + np.radians(7)])[0]
    est[2] = np.nan
    t, r = metrics.pose_errors_batch(est, true)
    assert t[0] == pytest.approx(0.05) and r[0] == pytest.approx(0.0, abs=1e-5)
    assert t[1] == pytest.approx(0.0, abs=1e-9) and r[1] == pytest.approx(7.0)
    assert np.isinf(t[2]) and np.isinf(r[2])


def test_threshold_labels():
    assert [metrics.threshold_label(t) for t in metrics.THRESHOLDS] == ["1cm/1deg", "5cm/5deg", "10cm/10deg", "1m/30deg"]


# --- test poses --------------------------------------------------------------------------------

def test_weights_follow_paper_formula_and_are_non_negative():
    rng = np.random.default_rng(3)
    scores = rng.normal(-20, 4, size=500)
    w = tposes.test_pose_weights(scores)
    assert np.allclose(w, 2 * scores.max() - scores.mean() - scores)
    assert (w >= 0).all()
    assert w[np.argmin(scores)] == w.max() and w[np.argmax(scores)] == pytest.approx(scores.max() - scores.mean())
    # constant scores -> zero weights -> uniform fallback
    p = tposes.sampling_probabilities(np.full(4, 2.0), "weighted")
    assert np.allclose(p, 0.25)
    with pytest.raises(UserError):
        tposes.sampling_probabilities(scores, "lowest")


def test_weighted_sampling_prefers_low_scores():
    poses, _ = _feasible()
    scores = np.linspace(-30, 0, len(poses))  # pose i has score rising with i
    occ, origin, res = _open_grid()
    free = tposes.free_space_checker(occ, origin, res, 0.1)
    w_cfg = tposes.TestPoseConfig(num=2000, mode="weighted", seed=1)
    u_cfg = tposes.TestPoseConfig(num=2000, mode="uniform", seed=1)
    w = tposes.sample_test_poses(poses, scores, 0.5, w_cfg, free)
    u = tposes.sample_test_poses(poses, scores, 0.5, u_cfg, free)
    low = scores < np.median(scores)
    frac_w = low[w.source_index].mean()
    frac_u = low[u.source_index].mean()
    # expected fraction for the weighted set is ~0.64 (linear weights); uniform ~0.5
    assert frac_w > 0.59 and abs(frac_u - 0.5) < 0.05
    assert scores[w.source_index].mean() < scores[u.source_index].mean() - 2.0


def test_where_sampling_follows_the_pose_weights_with_the_usual_jitter():
    """``--test-sets where``: source poses in proportion to the where weights (none where the
    weight is 0), perturbed as every test set; it needs weights."""
    poses, yaws = _feasible()
    weights = np.zeros(len(poses))
    weights[:40] = 3.0
    weights[40:48] = 1.0  # 3 : 1 per pose, 40 : 8 poses -> 15 : 1 by set
    occ, origin, res = _open_grid()
    free = tposes.free_space_checker(occ, origin, res, 0.1)
    cfg = tposes.TestPoseConfig(num=1600, mode="where", seed=2)
    tp = tposes.sample_test_poses(poses, np.zeros(len(poses)), 0.5, cfg, free, weights)
    assert tp.source_index.max() < 48
    assert np.mean(tp.source_index < 40) == pytest.approx(15 / 16, abs=0.02)
    assert np.abs(tp.offset_xy).max() <= 0.25 and np.degrees(np.abs(tp.offset_yaw)).max() <= 22.5
    np.testing.assert_allclose(tposes.sampling_probabilities(np.zeros(4), "where", np.array([1.0, 0, 3, 0])),
                               [0.25, 0, 0.75, 0])
    with pytest.raises(UserError, match="needs --where FILE"):
        tposes.sampling_probabilities(np.zeros(4), "where")
    assert tposes.ALL_TEST_SETS.index("weighted") == 0 and tposes.ALL_TEST_SETS.index("uniform") == 1  # seeds kept


def test_perturbation_bounds_and_free_space():
    poses, yaws = _feasible()
    occ, origin, res = _open_grid()
    occ[:, :40] = 1  # wall: x < 2.0 m is occupied
    free = tposes.free_space_checker(occ, origin, res, 0.1)
    cfg = tposes.TestPoseConfig(num=300, mode="uniform", seed=7)
    tp = tposes.sample_test_poses(poses, np.zeros(len(poses)), 0.5, cfg, free)
    assert len(tp) == 300
    src = poses[tp.source_index]
    d = tp.world_from_cam[:, :3, 3] - src[:, :3, 3]
    assert np.all(np.abs(d[:, :2]) <= 0.25 + 1e-12) and np.allclose(d[:, 2], 0)
    assert np.allclose(d[:, :2], tp.offset_xy)
    dyaw = np.arctan2(tp.world_from_cam[:, 1, 2], tp.world_from_cam[:, 0, 2]) - yaws[tp.source_index]
    dyaw = (dyaw + np.pi) % (2 * np.pi) - np.pi
    assert np.all(np.abs(dyaw) <= np.radians(22.5) + 1e-9) and np.allclose(dyaw, tp.offset_yaw)
    assert np.abs(tp.offset_yaw).max() > np.radians(15) and np.abs(tp.offset_xy).max() > 0.2  # really jittered
    # every kept camera is in free space with clearance: x >= 2.0 + 0.1
    assert tp.world_from_cam[:, 0, 3].min() > 2.1 - res
    assert free(tp.world_from_cam[:, :2, 3]).all()
    # level cameras: optical axis horizontal, y axis down
    assert np.allclose(tp.world_from_cam[:, 2, 2], 0) and np.allclose(tp.world_from_cam[:, 2, 1], -1)


def test_same_seed_same_poses_and_round_trip(tmp_path):
    poses, _ = _feasible()
    scores = np.random.default_rng(0).normal(size=len(poses))
    occ, origin, res = _open_grid()
    free = tposes.free_space_checker(occ, origin, res, 0.1)
    cfg = tposes.TestPoseConfig(num=50, seed=11)
    a = tposes.sample_test_poses(poses, scores, 0.5, cfg, free)
    b = tposes.sample_test_poses(poses, scores, 0.5, cfg, free)
    c = tposes.sample_test_poses(poses, scores, 0.5, tposes.TestPoseConfig(num=50, seed=12), free)
    assert np.array_equal(a.world_from_cam, b.world_from_cam)
    assert not np.array_equal(a.world_from_cam, c.world_from_cam)
    a.save(tmp_path / "t.npz")
    loaded = tposes.TestPoses.load(tmp_path / "t.npz")
    assert np.array_equal(loaded.world_from_cam, a.world_from_cam) and np.array_equal(loaded.source_index, a.source_index)


def test_another_stream_of_the_same_seed_draws_other_poses():
    poses, _ = _feasible()
    scores = np.random.default_rng(0).normal(size=len(poses))
    occ, origin, res = _open_grid()
    free = tposes.free_space_checker(occ, origin, res, 0.1)
    test = tposes.sample_test_poses(poses, scores, 0.5, tposes.TestPoseConfig(num=50, mode="uniform", seed=5), free)
    calib = tposes.sample_test_poses(poses, scores, 0.5,
                                     tposes.TestPoseConfig(num=50, mode="uniform", seed=5, stream=1), free)
    again = tposes.sample_test_poses(poses, scores, 0.5,
                                     tposes.TestPoseConfig(num=50, mode="uniform", seed=5, stream=1), free)
    assert np.array_equal(calib.world_from_cam, again.world_from_cam)  # deterministic
    # no pose in common: the off-grid calibration images are never test images
    d = np.linalg.norm(test.world_from_cam[:, None, :2, 3] - calib.world_from_cam[None, :, :2, 3], axis=-1)
    assert d.min() > 1e-9
    # stream 0 is the plain seed: test poses drawn before the option existed are unchanged
    rng = np.random.default_rng(5)
    first = rng.choice(len(poses), size=100, p=tposes.sampling_probabilities(scores, "uniform"))
    kept = first[free(poses[first, :2, 3] + rng.uniform(-0.5, 0.5, size=(100, 2)) * 0.5)]
    assert len(kept) >= 5 and np.array_equal(test.source_index[:5], kept[:5])


def test_no_free_space_is_a_user_error():
    poses, _ = _feasible(n_side=2)
    occ, origin, res = _open_grid()
    occ[:] = 1
    free = tposes.free_space_checker(occ, origin, res, 0.1)
    with pytest.raises(UserError, match="free space"):
        tposes.sample_test_poses(poses, np.zeros(len(poses)), 0.5, tposes.TestPoseConfig(num=5, max_rounds=3), free)


# --- tables ------------------------------------------------------------------------------------

def _rows():
    rows = []

    def add(method, run, k, rec, th="5cm/5deg", ts="weighted"):
        rows.append(dict(scene="room", method=method, run=run, k=k, test_set=ts, threshold=th, recall=rec, n_tests=200))

    add("none", 0, 0, 0.486)
    for k, rec in [(5, 0.555), (10, 0.621)]:
        add("omp", 0, k, rec)
    for run, recs in enumerate([(0.50, 0.60), (0.52, 0.62), (0.51, 0.58)]):
        add("random", run, 5, recs[0])
        add("random", run, 10, recs[1])
    add("none", 0, 0, 0.9, th="1m/30deg")
    add("omp", 0, 5, 0.95, th="1m/30deg")
    return rows


def test_format_mean_std():
    assert tables.format_mean_std([0.607]) == "60.7"
    assert tables.format_mean_std([0.50, 0.52, 0.51]) == "51.0 ± 1.0"
    assert tables.format_mean_std([]) == "-"


def test_method_table_shape_like_paper():
    md = tables.method_table(_rows(), "weighted", "5cm/5deg", [5, 10])
    lines = md.splitlines()
    assert lines[0] == "| Scene (no markers) | Method | k=5 | k=10 |"
    assert lines[2] == "| room (48.6) | Ours | **55.5** | **62.1** |"
    assert lines[3] == "|  | Rand. | 51.0 ± 1.0 | 60.0 ± 2.0 |"
    assert len(lines) == 4


def test_csv_round_trip_and_full_markdown(tmp_path):
    rows = _rows()
    tables.write_recall_csv(tmp_path / "recall.csv", rows)
    back = tables.read_recall_csv(tmp_path / "recall.csv")
    assert list(back[0]) == list(tables.CSV_COLUMNS)
    assert back[3]["recall"] == pytest.approx(rows[3]["recall"]) and back[3]["k"] == rows[3]["k"]
    md = tables.tables_markdown(back, [5, 10], "5cm/5deg", ["5cm/5deg", "1m/30deg"])
    assert "## Test set `weighted`" in md and "## All thresholds" in md
    assert "| room | weighted | Ours | 1m/30deg | 90.0 | 95.0 | - |" in md
    curves = tables.recall_curves(back, "room", "weighted", "5cm/5deg", [5, 10])
    assert np.allclose(curves["Ours"][0], [48.6, 55.5, 62.1]) and curves["Ours"][1] is None
    assert np.allclose(curves["Rand."][0], [48.6, 51.0, 60.0]) and np.allclose(curves["Rand."][1], [0, 1, 2])
