"""Every setting of a plan run: one sub-config per stage, composed into :class:`PlanConfig`.

Each stage takes only its own sub-config (:class:`~markerplace.plan.discretize.stage.DiscretizeConfig`,
:class:`~markerplace.imaging.config.ImagingConfig`, :class:`~markerplace.plan.similarity.config.SimilarityConfig`,
:class:`~markerplace.plan.score.localizability.NoiseConfig`, :class:`~markerplace.plan.place.config.PlacementConfig`,
:class:`~markerplace.runtime.executor.RuntimeConfig`); :class:`PlanConfig` is what a run saves as ``config.json``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, fields

from markerplace.errors import UserError
from markerplace.imaging.config import ImagingConfig
from markerplace.plan.discretize.stage import DiscretizeConfig
from markerplace.plan.place.config import PlacementConfig
from markerplace.plan.place.method_registry import settings_name
from markerplace.plan.place.methods import PLACEMENT_METHODS, method_conf
from markerplace.plan.place.predicted_recall import model_methods
from markerplace.plan.score.localizability import NoiseConfig
from markerplace.plan.score.marker_models import MARKER_MODELS
from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.runtime.executor import RuntimeConfig
from markerplace.settings import NO_CONST, walk
from markerplace.validation import check_plan_config

__all__ = ["PlanConfig", "validate", "warn_unused_settings"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlanConfig:
    """Every setting of a plan run, saved resolved as ``config.json`` in the run directory
    (``plan --config`` reads it back, or a TOML file with the same tables:
    :mod:`markerplace.config_file`).

    ``runtime`` (where the per-image work runs) changes speed, never results: it is left out of
    every cache key. The tag size lives in ``placement`` alone; the discretization gets it as
    an argument.
    """

    discretize: DiscretizeConfig = field(default_factory=DiscretizeConfig)
    imaging: ImagingConfig = field(default_factory=ImagingConfig)
    similarity: SimilarityConfig = field(default_factory=SimilarityConfig)
    noise: NoiseConfig = field(default_factory=NoiseConfig)
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    runtime: RuntimeConfig = field(default_factory=RuntimeConfig)


def validate(config: PlanConfig) -> None:
    """Raise :class:`UserError` for settings that cannot work."""
    p = config.placement
    PLACEMENT_METHODS.lookup(p.method)  # UserError naming the known ones
    MARKER_MODELS.lookup(p.marker_model)
    if not PLACEMENT_METHODS.lookup(p.recall_model).calibrated:
        calibrated = ", ".join(n for n, c in PLACEMENT_METHODS.items() if c.calibrated)
        raise UserError(f"placement.recall_model {p.recall_model!r} is not a calibrated method: use one of {calibrated}")
    check_choices(config)
    check_plan_config(config)  # every numeric setting: finite and in range (markerplace.validation)
    if p.target_recall is not None:
        if not p.target_recall > 0.0:
            raise UserError(f"--target-recall {p.target_recall:g} must be above 0: give a share of camera poses in "
                            "(0, 1], e.g. 0.9")
        if not PLACEMENT_METHODS.lookup(p.method).nested:
            nested = ", ".join(n for n, c in PLACEMENT_METHODS.items() if c.nested)
            raise UserError(f"--target-recall needs a method whose first tags are its smaller plans ({nested}), "
                            f"not --method {p.method}")


def check_choices(config) -> None:
    """Raise a one-line :class:`UserError` for a setting of ``config`` that is not one of its
    choices (a config built in code or read from ``config.json``; flags and ``--config`` files
    are checked as they are read)."""
    for leaf in walk(config):
        s = leaf.setting
        if s.choices is not None and s.const is NO_CONST and leaf.value not in tuple(s.choices()):
            raise UserError(f"{s.flag or leaf.path} {leaf.value!r} is not one of {', '.join(s.choices())}")


def warn_unused_settings(config: PlanConfig) -> None:
    """Log a warning for each method setting that has no effect: one of a method the plan
    neither places nor calibrates (:func:`~markerplace.plan.place.predicted_recall.model_methods`)."""
    p = config.placement
    used = set(model_methods(p))
    for name, cls in PLACEMENT_METHODS.items():
        conf = method_conf(name, p)
        if name in used or conf == cls.default_conf:
            continue
        flags = {leaf.path: leaf.setting.flag for leaf in walk(conf)}
        changed = [f"{flags.get(f.name) or f'placement.methods.{settings_name(name)}.{f.name} ='} "
                   f"{getattr(conf, f.name)}" for f in fields(conf)
                   if getattr(conf, f.name) != getattr(cls.default_conf, f.name)]
        log.warning("%s has no effect with --method %s (a setting of %s, which this plan neither places nor "
                    "calibrates)", ", ".join(changed), p.method, name)
