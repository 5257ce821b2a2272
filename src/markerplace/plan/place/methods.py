"""Placement methods: how k markers are chosen among the candidates, chosen by name.

:data:`PLACEMENT_METHODS` holds, in this order (the order of help texts and tables):

* ``omp``: :class:`OMP`, the paper's greedy (lazy greedy of :func:`~markerplace.plan.place.greedy.omp_greedy`);
* ``random``: :class:`RandomPlacement`, a seeded uniform sample of the candidates;
* ``uniform``: :class:`UniformPlacement`, evenly spaced along the free-space perimeter (seeded offset);
* ``human``: :class:`HumanPlacement`, the paper's human baseline (centres of the least-textured
  wall stretches, spread over rooms; :mod:`markerplace.plan.place.human`);
* ``expected-recall``: :class:`ExpectedRecall`, greedy on the expected number of poses that
  localize under a success model fitted on the map images (:mod:`markerplace.plan.place.expected_recall`).

A method works on the planner's :class:`~markerplace.plan.types.PlanData` (base information
per pose, one :class:`~markerplace.plan.types.MarkerCoverage` per candidate, then one per
existing marker) and returns a :class:`Choice`; :func:`markerplace.plan.place.stage.place` turns it
into markers with tag ids. ``evaluate`` reads each method's class attributes: a ``randomized``
method is placed ``--runs`` times (seeds ``--placement-seed + run``) and is a baseline of the
paired comparisons; a ``nested`` one is placed once with the largest k and its prefixes are the
smaller budgets.

Adding a method: write a :class:`PlacementMethod` subclass in this file (``name``, ``summary``,
``label``, ``randomized``, ``nested``, a frozen ``Config`` with ``default_conf = Config()`` and
:meth:`PlacementMethod.place`), decorated with ``@PLACEMENT_METHODS.register``; ``plan
--method``, ``evaluate --methods``, validation and the report tables list it from the registry,
and its ``Config`` is ``[placement.methods.NAME]`` of a ``--config`` file and ``--method-conf``
(``PlacementConfig.methods``). A method that places with a success model fitted on the map
images subclasses :class:`CalibratedMethod` (its ``Config`` a subclass of
:class:`CalibrationConfig`). Its test goes next to ``tests/plan/place/test_methods.py``.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from markerplace.errors import UserError
from markerplace.plan.place.baselines import random_placement, uniform_placement
from markerplace.plan.place.config import PlacementConfig
from markerplace.plan.place.expected_recall import expected_recall_greedy
from markerplace.plan.place.greedy import apply_coverages, omp_greedy
from markerplace.plan.place.human import HumanConfig, human_placement
from markerplace.plan.place.method_registry import PLACEMENT_METHODS, settings_name
from markerplace.plan.score.marker_models import MARKER_MODELS
from markerplace.plan.types import PlanData
from markerplace.registry import configure
from markerplace.settings import SEED_MAX, setting

log = logging.getLogger(__name__)



@dataclass(frozen=True, eq=False)
class Choice:
    """What a placement method chose.

    Attributes:
        order: (k,) int64 candidate indices (into ``data.coverages[:num_candidates]``), in
            placement order, distinct.
        gains: (k,) gain of each pick when it was chosen in the method's own objective: nats of
            localizability for ``omp``, expected poses that localize for ``expected-recall``
            (NaN where the method has no gains).
        q: the percentile the gains are taken at (NaN where the method has none).
        info_after: (N, 6, 6) information per pose with the existing and the chosen markers.
    """

    order: np.ndarray
    gains: np.ndarray
    q: float
    info_after: np.ndarray


class PlacementMethod:
    """Base class of placement methods; instances are built with ``cls(**conf_overrides)``.

    Class attributes:
        name: registry name (``--method NAME``).
        summary: a few words for help texts.
        label: short label in the recall tables (the paper's "Ours", "Rand.", "Unif.").
        randomized: the choice depends on the seed: ``evaluate`` places it ``--runs`` times and
            compares the other methods against the mean of its runs (a baseline).
        nested: the first k' picks of a k-marker choice are the k'-marker choice, so
            ``evaluate`` places it once with the largest k.
        calibrated: a :class:`CalibratedMethod` (set there, never by hand).
        default_conf: the method's own settings (a frozen ``Config``; in a plan run
            ``PlacementConfig.methods``, :func:`method_named`).

    Attributes:
        conf: ``default_conf`` with the overrides given at construction.
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    label: ClassVar[str] = ""
    randomized: ClassVar[bool] = False
    nested: ClassVar[bool] = False
    calibrated: ClassVar[bool] = False

    @dataclass(frozen=True)
    class Config:
        """No settings of its own."""

    default_conf: ClassVar = Config()

    def __init__(self, **conf):
        self.conf = configure(self.default_conf, conf)

    def place(self, data: PlanData, k: int, seed: int = 0, progress: bool = False,
              target: float | None = None) -> Choice:
        """Choose ``k`` of the ``data.num_candidates`` candidates.

        Args:
            data: the prepared plan (``coverages[num_candidates:]`` are existing markers, which
                count as placed).
            k: number of markers, 1 <= k <= ``data.num_candidates``.
            seed: seed of any randomness (``--placement-seed``, plus the run in ``evaluate``).
            progress: log each pick as it is made (where the method has picks worth logging).
            target: the plan's ``--target-recall`` (a share in (0, 1]) or None: a nested method
                may stop before ``k`` picks once its own objective says the target is reached
                (the plan keeps the first tags that reach it); others ignore it.

        Returns:
            :class:`Choice`.

        Raises:
            UserError: k out of range, or anything else the user can fix.
        """
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.conf})"


def get_placement_method(name: str, **conf) -> PlacementMethod:
    """The method registered as ``name`` with ``conf`` overrides of its ``default_conf``.

    Raises:
        UserError: unknown name (one line listing the known ones).
    """
    return PLACEMENT_METHODS.lookup(name)(**conf)


def method_from_config(config: PlacementConfig) -> PlacementMethod:
    """The method ``config.method`` with its settings from ``config.methods``."""
    return method_named(config.method, config)


def method_conf(name: str, config: PlacementConfig):
    """The settings of the method ``name`` in ``config``: ``config.methods``' field of it (its
    ``default_conf`` when ``config`` was made before the method registered).

    Raises:
        UserError: unknown name (one line listing the known ones).
    """
    cls = PLACEMENT_METHODS.lookup(name)
    return getattr(config.methods, settings_name(name), cls.default_conf)


def method_named(name: str, config: PlacementConfig) -> PlacementMethod:
    """The method ``name`` with its settings from ``config.methods`` (:func:`method_conf`; for a
    method other than ``config.method`` too, e.g. each of ``evaluate --methods``)."""
    conf = method_conf(name, config)
    return PLACEMENT_METHODS.lookup(name)(**{f.name: getattr(conf, f.name) for f in dataclasses.fields(conf)})


def _with_markers(data: PlanData, order: np.ndarray) -> np.ndarray:
    """(N, 6, 6) base information plus the existing markers and the candidates in ``order``."""
    C = data.num_candidates
    return apply_coverages(data.base_info, list(data.coverages[C:]) + [data.coverages[i] for i in order])


@PLACEMENT_METHODS.register
class OMP(PlacementMethod):
    """The paper's Algorithm 1 (docs/design.md section 5): k greedy picks by the q-th percentile
    gain over all poses, q set from v; lazy evaluation gives exactly the plain greedy's picks."""

    name = "omp"
    summary = "the paper's greedy"
    label = "Ours"
    randomized = False
    nested = True

    @dataclass(frozen=True)
    class Config:
        """OMP's settings (``[placement.methods.omp]``; ``-v`` sets ``v``).

        Attributes:
            v: the most visible v percent of candidates compete, [0, 100] (default 90, the
                paper's).
            lazy: lazy greedy (the same picks as plain greedy, far fewer evaluations; default
                True).
        """

        v: float = setting(90.0, flag="-v", bounds=(0.0, 100.0), units="%", hint="a percentage such as 90",
                           help="OMP percentile parameter v in [0, 100]: the most visible v % of candidates compete "
                                "(q is derived from v as in the paper)")
        lazy: bool = True

    default_conf = Config()

    def place(self, data: PlanData, k: int, seed: int = 0, progress: bool = False,
              target: float | None = None) -> Choice:
        """Greedy picks (``seed`` unused: ties go to the lower candidate index)."""
        C = data.num_candidates

        def report(i: int, k: int, candidate: int, gain: float) -> None:
            log.info("omp pick %d/%d: candidate %d, gain %.3f", i + 1, k, candidate, gain)

        res = omp_greedy(data.base_info, data.coverages[:C], k, v=self.conf.v, lazy=self.conf.lazy,
                         existing=data.coverages[C:], progress=report if progress else None,
                         weights=data.pose_weight)
        return Choice(np.asarray(res.order, dtype=np.int64), np.asarray(res.gains, dtype=float), float(res.q),
                      res.info_after)


@PLACEMENT_METHODS.register
class RandomPlacement(PlacementMethod):
    """k distinct candidates drawn uniformly (:func:`~markerplace.plan.place.baselines.random_placement`,
    ``numpy.random.default_rng(seed)``)."""

    name = "random"
    summary = "seeded uniform sample of candidates"
    label = "Rand."
    randomized = True

    @dataclass(frozen=True)
    class Config:
        """No settings of its own (the seed is an argument of :meth:`place`)."""

    default_conf = Config()

    def place(self, data: PlanData, k: int, seed: int = 0, progress: bool = False,
              target: float | None = None) -> Choice:
        order = np.asarray(random_placement(data.num_candidates, k, seed), dtype=np.int64)
        return Choice(order, np.full(len(order), np.nan), float("nan"), _with_markers(data, order))


@PLACEMENT_METHODS.register
class UniformPlacement(PlacementMethod):
    """k candidates evenly spaced along the free-space perimeter with a seeded offset
    (:func:`~markerplace.plan.place.baselines.uniform_placement`, the paper's 'uniform')."""

    name = "uniform"
    summary = "evenly spaced along the free-space perimeter"
    label = "Unif."
    randomized = True

    @dataclass(frozen=True)
    class Config:
        """No settings of its own (the seed is an argument of :meth:`place`)."""

    default_conf = Config()

    def place(self, data: PlanData, k: int, seed: int = 0, progress: bool = False,
              target: float | None = None) -> Choice:
        order = np.asarray(uniform_placement(data.disc.perimeter_arclength, data.disc.perimeter_length, k, seed=seed),
                           dtype=np.int64)
        return Choice(order, np.full(len(order), np.nan), float("nan"), _with_markers(data, order))


@PLACEMENT_METHODS.register
class HumanPlacement(PlacementMethod):
    """The paper's real-experiment baseline, tags "placed by a human" who "prioritizes centers in
    less textured areas": the centres of the least-textured flat wall stretches (SIFT points per
    m^2 of wall in the map images), no two on one stretch, shared over rooms by free area
    (:func:`~markerplace.plan.place.human.human_placement`; deterministic, the seed is unused)."""

    name = "human"
    summary = "centres of the least-textured wall stretches, spread over rooms"
    label = "Human"
    randomized = False

    Config = HumanConfig
    default_conf = Config()

    def place(self, data: PlanData, k: int, seed: int = 0, progress: bool = False,
              target: float | None = None) -> Choice:
        order = human_placement(data, k, self.conf, progress=progress)
        return Choice(order, np.full(len(order), np.nan), float("nan"), _with_markers(data, order))


CALIBRATION_POSES = ("map", "offgrid")
"""Images a calibrated method may fit its success model on (``--calibration-poses``)."""


@dataclass(frozen=True)
class CalibrationConfig:
    """The settings of a success-model fit (:func:`markerplace.simulation.success_fit.calibrate_plan`
    reads these fields, and only these, of a :class:`CalibratedMethod`'s ``Config``).

    Attributes:
        tag_model: marker model of the scores it fits and optimizes (``corners``, default:
            it predicts map-image localization better than ``paper``, docs/results/office.md).
        calibration_runs: seeded random tag sets the map images are localized with, besides
            none (default 3).
        calibration_k: tags per calibration set (default 20, at most the candidates).
        calibration_seed: seed of the calibration sets and of the off-grid poses (default 0).
        calibration_poses: ``map`` (default: the map images, each without its own location) or
            ``offgrid`` (test-like renders, ``--calibration-poses``).
        calibration_images: off-grid images drawn (``offgrid`` only; default 1000).
    """

    tag_model: str = setting("corners", choices=lambda: MARKER_MODELS.names())
    calibration_runs: int = setting(3, bounds=(0, 1000), hint="a number of tag sets, e.g. 3")
    calibration_k: int = setting(20, bounds=(1, 10_000), hint="tags per set, e.g. 20")
    calibration_seed: int = setting(0, bounds=(0, SEED_MAX), hint=f"a seed in 0..{SEED_MAX}, e.g. 0")
    calibration_poses: str = setting("map", choices=lambda: CALIBRATION_POSES)
    calibration_images: int = setting(1000, bounds=(1, 100_000), hint="a number of images, e.g. 1000")


class CalibratedMethod(PlacementMethod):
    """Base class of a method that places with a success model fitted on the map images: before
    it places, :func:`markerplace.simulation.success_fit.calibrate_plan` fits the model with the
    :class:`CalibrationConfig` fields of its ``Config`` (a subclass of it) and stores it in
    ``data.calibration[name]`` (``model``, a :class:`~markerplace.plan.score.success_model.SuccessModel`,
    and ``coverages`` under ``tag_model``), where :meth:`fit` finds it. Any calibrated method can
    be a plan's ``recall_model``."""

    calibrated: ClassVar[bool] = True
    Config = CalibrationConfig
    default_conf: ClassVar = CalibrationConfig()

    def fit(self, data: PlanData) -> dict:
        """The fitted model of this method in ``data`` (``model``, ``coverages``).

        Raises:
            UserError: the calibration stage did not run.
        """
        fit = data.calibration.get(self.name)
        if fit is None:
            raise UserError(f"--method {self.name} needs the calibration stage: run it through `markerplace plan` or "
                            "`markerplace evaluate` (markerplace.simulation.success_fit.calibrate_plan)")
        return fit


@PLACEMENT_METHODS.register
class ExpectedRecall(CalibratedMethod):
    """Beyond the paper: k greedy picks that maximize the expected number of feasible poses that
    localize, ``sum_p P(success | s_p)`` (:func:`~markerplace.plan.place.expected_recall.expected_recall_greedy`),
    with ``P`` a logistic :class:`~markerplace.plan.score.success_model.SuccessModel` of the score fitted
    on the scene's own map images, each localized against the rest of the map without and with
    seeded random tag sets (:func:`markerplace.simulation.success_fit.calibrate_plan`: map images
    only, never test images). Plain greedy (the objective is not submodular); deterministic.
    With a ``target`` it stops once the expected share of poses that localize reaches it, or when
    no candidate adds anything."""

    name = "expected-recall"
    summary = "greedy on the expected number of poses that localize (fitted on map images; beyond the paper)"
    label = "E[recall]"
    randomized = False
    nested = True

    @dataclass(frozen=True)
    class Config(CalibrationConfig):
        """Settings of ``expected-recall`` (``[placement.methods.expected_recall]``): the fit's
        (:class:`CalibrationConfig`), no others; ``--calibration-poses`` sets ``calibration_poses``."""

        calibration_poses: str = setting("map", flag="--calibration-poses", choices=lambda: CALIBRATION_POSES,
                                         help="images expected-recall fits its success model on: map (the map "
                                              "images, each without its own location) or offgrid (1000 test-like "
                                              "renders between the map poses, never test images)")

    default_conf = Config()

    def place(self, data: PlanData, k: int, seed: int = 0, progress: bool = False,
              target: float | None = None) -> Choice:
        fit = self.fit(data)
        C = data.num_candidates

        def report(i: int, k: int, candidate: int, gain: float) -> None:
            log.info("expected-recall pick %d/%d: candidate %d, +%.2f expected poses", i + 1, k, candidate, gain)

        covs = fit["coverages"]
        res = expected_recall_greedy(data.base_info, covs[:C], k, fit["model"], existing=covs[C:],
                                     progress=report if progress else None,
                                     stop_at=None if target is None else float(target) * len(data.base_info),
                                     weights=data.pose_weight)
        return Choice(np.asarray(res.order, dtype=np.int64), np.asarray(res.gains, dtype=float), float("nan"),
                      res.info_after)


__all__ = ["OMP", "PLACEMENT_METHODS", "CalibratedMethod", "CalibrationConfig", "ExpectedRecall", "Choice",
           "HumanPlacement", "PlacementMethod", "RandomPlacement", "UniformPlacement", "get_placement_method",
           "method_conf", "method_from_config", "method_named", "CALIBRATION_POSES"]
