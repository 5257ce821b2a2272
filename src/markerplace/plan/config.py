"""Every setting of a plan run: one sub-config per stage, composed into :class:`PlanConfig`.

Each stage takes only its own sub-config (:class:`~markerplace.plan.discretize.stage.DiscretizeConfig`,
:class:`~markerplace.imaging.config.ImagingConfig`, :class:`~markerplace.plan.similarity.config.SimilarityConfig`,
:class:`~markerplace.plan.score.localizability.NoiseConfig`, :class:`~markerplace.plan.place.config.PlacementConfig`,
:class:`~markerplace.runtime.executor.RuntimeConfig`); :class:`PlanConfig` is what a run saves as ``config.json``.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from markerplace.errors import UserError
from markerplace.imaging.config import ImagingConfig
from markerplace.plan.discretize.stage import DiscretizeConfig
from markerplace.plan.place.config import CALIBRATION_POSES, PlacementConfig
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.plan.place.predicted_recall import wants_success_model
from markerplace.plan.score.localizability import NoiseConfig
from markerplace.plan.score.marker_models import MARKER_MODELS
from markerplace.plan.similarity.config import SimilarityConfig
from markerplace.runtime.executor import RuntimeConfig
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
    if p.calibration_poses not in CALIBRATION_POSES:
        raise UserError(f"--calibration-poses {p.calibration_poses!r} is not one of {', '.join(CALIBRATION_POSES)}")
    check_plan_config(config)  # every numeric setting: finite and in range (markerplace.validation)
    if p.target_recall is not None:
        if not p.target_recall > 0.0:
            raise UserError(f"--target-recall {p.target_recall:g} must be above 0: give a share of camera poses in "
                            "(0, 1], e.g. 0.9")
        if not PLACEMENT_METHODS.lookup(p.method).nested:
            nested = ", ".join(n for n, c in PLACEMENT_METHODS.items() if c.nested)
            raise UserError(f"--target-recall needs a method whose first tags are its smaller plans ({nested}), "
                            f"not --method {p.method}")


def warn_unused_settings(config: PlanConfig) -> None:
    """Log a warning for each setting that has no effect with the chosen method."""
    p = config.placement
    if p.calibration_poses != "map" and not wants_success_model(p):
        log.warning("--calibration-poses %s has no effect with --method %s (it fits expected-recall's success "
                    "model; so do --target-recall and --recall-curve)", p.calibration_poses, p.method)
