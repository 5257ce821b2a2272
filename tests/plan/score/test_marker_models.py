"""Marker models chosen by name: registry, the two models' maths, and a model added in a test."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from helpers.poses import facing_marker
from markerplace.errors import UserError
from markerplace.geometry import Intrinsics, so3_exp, world_from_cam_pose, world_from_marker_pose
from markerplace.plan.score.localizability import NoiseConfig, information_gain
from markerplace.plan.score.marker_models import MARKER_MODELS, CornersModel, MarkerModel, PaperModel, get_marker_model

K = Intrinsics().K


def test_registry_lists_both_models_in_order():
    assert MARKER_MODELS.names() == ("paper", "corners")
    assert MARKER_MODELS["paper"] is PaperModel and MARKER_MODELS["corners"] is CornersModel
    assert "paper (relative-pose factor" in MARKER_MODELS.help()


def test_unknown_model_is_a_one_line_user_error():
    with pytest.raises(UserError) as err:
        get_marker_model("cornerz")
    assert str(err.value) == "--marker-model 'cornerz' is not known: use one of paper, corners"


def test_conf_overrides_and_unknown_settings():
    m = get_marker_model("corners", noise=NoiseConfig(pixel_sigma=2.0), min_side_px=20)
    assert isinstance(m, CornersModel) and m.conf.min_side_px == 20 and m.noise.pixel_sigma == 2.0
    assert CornersModel.default_conf.min_side_px == 10.0  # defaults untouched
    with pytest.raises(TypeError):
        get_marker_model("paper", min_side_px=20)  # the paper model has no such setting


def _golden_poses():
    T = np.stack([world_from_cam_pose(np.array([x, y, 1.5]), yaw)
                  for x, y, yaw in [(0, 0, 0.1), (0.5, -0.3, -0.2), (1.0, 0.4, 0.3), (-0.2, 0.2, 0.0)]])
    Tm = world_from_marker_pose(np.array([4.0, 0.3, 1.5]), np.array([-1.0, 0.1, 0.0]))
    return T, Tm


@pytest.mark.parametrize("name, traces, sums", [
    # recorded with marker_information_paper / marker_information_corners of
    # plan/score/localizability.py before the models moved here (commit ef0a0c7)
    ("paper", [9544761.38096548, 7804804.879878006, 6004849.8787530335, 10324741.881452968],
     [9342599.118489, 9929411.83092, 4612050.397548, 10534736.631584]),
    ("corners", [454758.7498698049, 572117.2037793573, 567096.0380146679, 452204.7675733988],
     [443290.296618, 779772.815149, 411857.778138, 462928.508525]),
])
def test_models_give_what_the_functions_gave(name, traces, sums):
    T, Tm = _golden_poses()
    M = get_marker_model(name, noise=NoiseConfig(pixel_sigma=1.3, marker_rel_sigma=2e-3)).information(T, Tm, 0.3, K)
    assert M.shape == (4, 6, 6)
    np.testing.assert_allclose(np.trace(M, axis1=1, axis2=2), traces, rtol=1e-10)
    np.testing.assert_allclose(M.reshape(4, -1).sum(1), sums, rtol=1e-9)
    np.testing.assert_allclose(M, np.swapaxes(M, 1, 2), atol=1e-6 * np.abs(M).max())


def test_corners_model_detectability() -> None:
    corners = get_marker_model("corners")
    T = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    size = 0.4
    near = corners.information(T[None], facing_marker(T, 2.0), size, K)[0]
    assert np.all(np.linalg.eigvalsh(near) > 0)  # 4 known points fix all 6 dof
    # Side in pixels ~ f * size / d: 300 * 0.4 / 13 = 9.2 px < 10 -> zero; 10 m -> 12 px.
    assert np.all(corners.information(T[None], facing_marker(T, 13.0), size, K)[0] == 0)
    assert np.abs(corners.information(T[None], facing_marker(T, 10.0), size, K)[0]).max() > 0
    strict = get_marker_model("corners", min_side_px=20)
    assert np.all(strict.information(T[None], facing_marker(T, 10.0), size, K)[0] == 0)
    # Behind the camera, or partly outside the image.
    T_back = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), np.pi)
    assert np.all(corners.information(T_back[None], facing_marker(T, 2.0), size, K)[0] == 0)
    assert np.all(corners.information(T[None], facing_marker(T, 1.0, lateral=0.95), size, K)[0] == 0)
    # Farther tags give less information; bigger tags more.
    far = corners.information(T[None], facing_marker(T, 5.0), size, K)[0]
    lam = 100.0 * np.eye(6)
    assert information_gain(lam, far) < information_gain(lam, near)
    big = corners.information(T[None], facing_marker(T, 5.0), 2 * size, K)[0]
    assert information_gain(lam, big) > information_gain(lam, far)


def test_paper_model_ignores_distance_and_size() -> None:
    """The factor's noise does not grow with distance: ln det M is the same at 2 m and 5 m (det of
    an adjoint is 1), and the tag size plays no part at all."""
    from markerplace.plan.score.localizability import logdet_spd

    paper = get_marker_model("paper")
    T = world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)
    m2 = paper.information(T[None], facing_marker(T, 2.0), 0.4, K)[0]
    m5 = paper.information(T[None], facing_marker(T, 5.0), 0.4, K)[0]
    assert logdet_spd(m2) == pytest.approx(logdet_spd(m5), rel=1e-9)
    assert not np.allclose(m2, m5)  # the direction of the information does change
    np.testing.assert_array_equal(paper.information(T[None], facing_marker(T, 5.0), 0.1, K)[0], m5)


def test_paper_model_is_frame_consistent() -> None:
    """Moving camera and marker together by a world transform leaves M unchanged."""
    paper = get_marker_model("paper")
    rng = np.random.default_rng(5)
    T = world_from_cam_pose(np.array([1.0, 0.5, 1.5]), 0.3)
    Tm = facing_marker(T, 3.0, lateral=0.5)
    G = np.eye(4)
    G[:3, :3] = so3_exp(rng.normal(size=3))
    G[:3, 3] = rng.normal(size=3)
    np.testing.assert_allclose(paper.information((G @ T)[None], G @ Tm, 0.4, K),
                               paper.information(T[None], Tm, 0.4, K), rtol=1e-9, atol=1e-3)


class ToyModel(MarkerModel):
    """Every seeing pose gets ``gain`` times the identity."""

    name = "toy"
    summary = "constant information"

    @dataclass(frozen=True)
    class Config:
        gain: float = 7.0

    default_conf = Config()

    def information(self, world_from_cam, world_from_marker, size, K):
        return np.broadcast_to(self.conf.gain * np.eye(6), (len(world_from_cam), 6, 6)).copy()


@pytest.fixture
def toy_model(monkeypatch):
    monkeypatch.setitem(MARKER_MODELS, "toy", ToyModel)
    return ToyModel


def test_registering_rejects_bad_classes():
    class NoName(ToyModel):
        name = ""

    class Unfrozen(ToyModel):
        name = "unfrozen"

        @dataclass
        class Config:
            gain: float = 1.0

        default_conf = Config()

    for cls in (NoName, Unfrozen):
        with pytest.raises(ValueError):
            MARKER_MODELS.register(cls)
    with pytest.raises(ValueError, match="twice"):
        MARKER_MODELS.register(PaperModel)
    assert MARKER_MODELS.names() == ("paper", "corners")


def test_a_model_registered_in_a_test_reaches_the_cli_and_the_planner(toy_model, capsys):
    """Registering is all it takes: the CLI accepts it, validation passes, the coverages use it."""
    from markerplace.cli.main import build_parser, plan_config_from_args
    from markerplace.plan.config import validate
    from markerplace.plan.score.stage import build_coverages

    args = build_parser().parse_args(["plan", "tiny", "--out", "unused", "--marker-model", "toy"])
    config = plan_config_from_args(args)
    validate(config)
    assert config.placement.marker_model == "toy"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["plan", "--help"])
    assert "toy (constant information)" in " ".join(capsys.readouterr().out.split())
    T = np.stack([world_from_cam_pose(np.array([0.0, 0.0, 1.5]), 0.0)] * 3)
    Tm = facing_marker(T[0], 2.0)[None]
    covs = build_coverages(T, Tm, [0.4], np.array([[True], [False], [True]]), config.placement.marker_model, config.noise,
                           config.imaging.camera.K)
    assert covs[0].pose_idx.tolist() == [0, 2]
    np.testing.assert_array_equal(covs[0].info, np.broadcast_to(7.0 * np.eye(6), (2, 6, 6)))
