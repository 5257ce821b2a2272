"""Placement methods chosen by name: registry, dispatch through place, evaluation and
report tables reading the registry, and a method added in a test (no scene: synthetic PlanData)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np
import pytest

from helpers.recall_problems import problem
from markerplace.errors import UserError
from markerplace.geometry import world_from_marker_pose
from markerplace.markers import Marker
from markerplace.plan.config import PlanConfig, validate
from markerplace.plan.place.baselines import random_placement, uniform_placement
from markerplace.plan.place.config import PlacementConfig
from markerplace.plan.place.greedy import apply_coverages, omp_greedy
from markerplace.plan.place.methods import OMP, PLACEMENT_METHODS, Choice, PlacementMethod, get_placement_method, method_from_config
from markerplace.plan.place.stage import place
from markerplace.plan.score.localizability import entropy
from markerplace.plan.types import PlanData
from markerplace.settings import apply
from markerplace.simulation import marker_sets as placements
from markerplace.testbed import config as tbconfig


def _data(seed: int = 0, N: int = 60, C: int = 14, n_existing: int = 1) -> PlanData:
    """A random placement problem (:func:`helpers.recall_problems.problem`) with a
    perimeter for the uniform baseline."""
    base, covs = problem(seed, N, C, n_existing)
    L = 40.0
    disc = SimpleNamespace(
        candidate_world_from_marker=np.stack([world_from_marker_pose(np.array([i, 0.0, 1.5]), np.array([0.0, 1.0, 0.0]))
                                              for i in range(C)]),
        perimeter_arclength=np.sort(np.random.default_rng([seed, 1]).uniform(0, L, C)), perimeter_length=L)
    return PlanData(disc, base, -entropy(base), covs, C, {})


def test_registry_lists_the_five_methods_in_order():
    assert PLACEMENT_METHODS.names() == ("omp", "random", "uniform", "human", "expected-recall")
    assert [c.label for c in PLACEMENT_METHODS.values()] == ["Ours", "Rand.", "Unif.", "Human", "E[recall]"]
    assert [c.randomized for c in PLACEMENT_METHODS.values()] == [False, True, True, False, False]
    assert [c.calibrated for c in PLACEMENT_METHODS.values()] == [False, False, False, False, True]
    assert PLACEMENT_METHODS["omp"].nested and PLACEMENT_METHODS["expected-recall"].nested


def test_unknown_method_is_a_one_line_user_error():
    with pytest.raises(UserError) as err:
        get_placement_method("greedy")
    assert str(err.value) == "--method 'greedy' is not known: use one of omp, random, uniform, human, expected-recall"
    with pytest.raises(UserError, match="--method 'greedy' is not known"):
        validate(PlanConfig(placement=PlacementConfig(method="greedy")))
    with pytest.raises(UserError, match="--marker-model 'x' is not known: use one of paper, corners"):
        validate(PlanConfig(placement=PlacementConfig(marker_model="x")))


def _omp(k: int = 20, **omp) -> PlacementConfig:
    """A PlacementConfig of OMP with ``omp`` (its settings) in ``methods.omp``."""
    return apply(PlacementConfig(k=k, method="omp"), {f"methods.omp.{key}": v for key, v in omp.items()})


def test_method_settings_come_from_placement_config():
    m = method_from_config(_omp(v=55.0, lazy=False))
    assert isinstance(m, OMP) and m.conf == OMP.Config(v=55.0, lazy=False)
    assert PlacementConfig().methods.omp == OMP.default_conf  # the one home of OMP's settings
    assert not any(hasattr(PlacementConfig(), key) for key in ("v", "lazy", "calibration_poses"))
    assert get_placement_method("omp", v=10.0).conf.v == 10.0
    with pytest.raises(TypeError):
        get_placement_method("random", v=10.0)


@pytest.mark.parametrize("v, lazy", [(90.0, True), (50.0, False), (100.0, True)])
def test_omp_through_the_registry_is_omp_greedy(v, lazy):
    data = _data(1)
    C = data.num_candidates
    pl = place(data, _omp(k=5, v=v, lazy=lazy), progress=False)
    ref = omp_greedy(data.base_info, data.coverages[:C], 5, v=v, lazy=lazy, existing=data.coverages[C:])
    assert pl.candidates.tolist() == ref.order and pl.candidates.dtype == np.int64
    np.testing.assert_array_equal(pl.gains, ref.gains)
    assert pl.q == ref.q
    np.testing.assert_array_equal(pl.info_after, ref.info_after)


@pytest.mark.parametrize("method", ["random", "uniform"])
@pytest.mark.parametrize("seed", [0, 3])
def test_baselines_through_the_registry_keep_their_seeded_choice(method, seed):
    data = _data(2)
    C = data.num_candidates
    pl = place(data, PlacementConfig(k=4, method=method, seed=seed), progress=False)
    if method == "random":
        ref = random_placement(C, 4, seed)
    else:
        ref = uniform_placement(data.disc.perimeter_arclength, data.disc.perimeter_length, 4, seed=seed)
    assert pl.candidates.tolist() == ref
    assert np.isnan(pl.gains).all() and np.isnan(pl.q)
    expected = apply_coverages(data.base_info, list(data.coverages[C:]) + [data.coverages[i] for i in ref])
    np.testing.assert_array_equal(pl.info_after, expected)
    other = place(data, PlacementConfig(k=4, method=method, seed=seed + 1), progress=False)
    assert other.candidates.tolist() != ref  # the seed is passed on


def test_tag_ids_skip_existing_and_sizes_come_from_the_config():
    data = _data(3)
    existing = [Marker(1, 0.3, np.eye(4))]
    pl = place(data, PlacementConfig(k=3, method="random", tag_size=0.25), existing=existing)
    assert [m.tag_id for m in pl.markers] == [0, 2, 3]
    assert all(m.size == 0.25 for m in pl.markers)


class ToyMethod(PlacementMethod):
    """The last k candidates, highest index first (deterministic, not nested)."""

    name = "toy"
    summary = "last candidates first"
    label = "Toy"

    @dataclass(frozen=True)
    class Config:
        v: float = 0.0  # its own v, not OMP's (--method-conf v=..., [placement.methods.toy])
        skip: int = 0

    default_conf = Config()

    def place(self, data, k, seed=0, progress=False, target=None):
        C = data.num_candidates
        order = np.arange(C - 1 - self.conf.skip, C - 1 - self.conf.skip - k, -1, dtype=np.int64)
        return Choice(order, np.full(k, self.conf.v), float("nan"),
                      apply_coverages(data.base_info, [data.coverages[i] for i in order]))


class ToyRandom(ToyMethod):
    name = "toyrand"
    summary = "a seeded toy"
    label = ""
    randomized = True

    def place(self, data, k, seed=0, progress=False, target=None):
        order = np.random.default_rng(seed).permutation(data.num_candidates)[:k].astype(np.int64)
        return Choice(order, np.full(k, np.nan), float("nan"), data.base_info.copy())


@pytest.fixture
def toy_methods(monkeypatch):
    monkeypatch.setitem(PLACEMENT_METHODS, "toy", ToyMethod)
    monkeypatch.setitem(PLACEMENT_METHODS, "toyrand", ToyRandom)


def test_a_method_registered_in_a_test_reaches_plan_and_evaluate(toy_methods, capsys):
    """Registering is all it takes: plan --method, evaluate --methods, build_placements, the size
    estimate, help texts and the report tables all see it."""
    from markerplace.cli.evaluate_command import evaluate_config_from_args
    from markerplace.cli.main import build_parser, plan_config_from_args
    from markerplace.testbed.reporting.tables import display_name, method_table

    data = _data(4)
    args = build_parser().parse_args(["plan", "tiny", "--out", "unused", "--method", "toy", "--method-conf", "v=7",
                                      "-v", "50", "-k", "3"])
    config = plan_config_from_args(args)
    validate(config)
    pl = place(data, config.placement, progress=False)
    assert pl.candidates.tolist() == [13, 12, 11] and pl.gains.tolist() == [7.0] * 3  # the toy's own v
    assert config.placement.methods.omp.v == 50.0 and config.placement.methods.toy == ToyMethod.Config(v=7.0)
    with pytest.raises(SystemExit):
        build_parser().parse_args(["plan", "--help"])
    assert "toy (last candidates first)" in " ".join(capsys.readouterr().out.split())

    args = build_parser().parse_args(["evaluate", "tiny", "--out", "unused", "--methods", "none,omp,toy,toyrand",
                                      "--k", "2,3", "--runs", "2"])
    ecfg = evaluate_config_from_args(args)
    tbconfig.validate_evaluate_config(ecfg)
    assert placements.method_names() == ("none", "omp", "random", "uniform", "human", "expected-recall", "toy", "toyrand")
    assert placements.baseline_methods() == ("random", "uniform", "toyrand")
    assert tbconfig.EvaluateConfig().study.methods == placements.method_names()
    runs = placements.build_placements(data, config.placement, ecfg)
    assert [(r.method, r.run, r.k) for r in runs] == [
        ("none", 0, 0), ("omp", 0, 2), ("omp", 0, 3), ("toy", 0, 2), ("toy", 0, 3),
        ("toyrand", 0, 2), ("toyrand", 0, 3), ("toyrand", 1, 2), ("toyrand", 1, 3)]
    assert placements.marker_set_count(ecfg) == 2 + 2 + 2 * 2
    toy3 = next(r for r in runs if r.method == "toy" and r.k == 3)
    assert [m.tag_id for m in toy3.markers] == [0, 1, 2]
    assert display_name("toy") == "Toy" and display_name("toyrand") == "toyrand"
    rows = [dict(scene="s", method=m, run=0, k=k, test_set="uniform", threshold="5cm/5deg", recall=0.5, n_tests=10)
            for m, k in [("none", 0), ("toy", 2), ("omp", 2), ("extra", 2)]]
    table = method_table(rows, "uniform", "5cm/5deg", [2])
    assert table.index("Ours") < table.index("Toy") < table.index("extra")


def test_unknown_evaluate_method_lists_the_registry(toy_methods):
    with pytest.raises(UserError) as err:
        tbconfig.validate_evaluate_config(tbconfig.EvaluateConfig(study=tbconfig.StudyConfig(methods=("none", "best"))))
    assert "use a comma list of none, omp, random, uniform, human, expected-recall, toy, toyrand" in str(err.value)


def test_build_placements_order_and_seeds_are_unchanged():
    """none, omp once at max k (prefixes), then random and uniform per (run, k) with seed + run
    (human needs a scene's SIFT points, which the synthetic data has not: tests/plan/place/test_human.py)."""
    data = _data(5)
    pc = PlacementConfig(seed=4)
    study = tbconfig.StudyConfig(methods=("none", "omp", "random", "uniform"), ks=(2, 4), runs=2)
    runs = placements.build_placements(data, pc, tbconfig.EvaluateConfig(study=study))
    assert [(r.method, r.run, r.k) for r in runs] == [("none", 0, 0), ("omp", 0, 2), ("omp", 0, 4)] + [
        (m, run, k) for m in ("random", "uniform") for run in range(2) for k in (2, 4)]
    omp = place(data, replace(pc, k=4, method="omp"), progress=False)
    for r in runs[1:3]:
        np.testing.assert_array_equal([m.world_from_marker for m in r.markers],
                                      [m.world_from_marker for m in omp.markers[:r.k]])
    for r in runs[3:]:
        ref = place(data, replace(pc, k=r.k, method=r.method, seed=4 + r.run), progress=False)
        np.testing.assert_array_equal([m.world_from_marker for m in r.markers], [m.world_from_marker for m in ref.markers])
