"""Settings of an ``evaluate`` run (the paper's experiments; defaults as published), in four
parts: which test images, what is compared (the study), how images are localized, and how
recall is counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from markerplace.errors import UserError
from markerplace.testbed.metrics import THRESHOLDS
from markerplace.testbed.marker_sets import NO_MARKERS, method_names
from markerplace.testbed.poses import TEST_SETS

__all__ = ["TestSetConfig", "StudyConfig", "LocalizationConfig", "DiagnosticsConfig", "EvaluateConfig", "validate_evaluate_config"]


@dataclass(frozen=True)
class TestSetConfig:
    """Which test images.

    Attributes:
        tests: test images per test set (paper: 200 room ... 10000 apartment).
        sets: ``weighted`` (towards low scores) and/or ``uniform``.
        seed: seed of the test poses and the shift signs alone; None = the run's ``seed``.
        min_clearance: test cameras need this clearance (metres) from non-free cells.
    """

    __test__ = False

    tests: int = 200
    sets: tuple[str, ...] = TEST_SETS
    seed: int | None = None
    min_clearance: float = 0.1


@dataclass(frozen=True)
class StudyConfig:
    """What is compared.

    Attributes:
        methods: ``none`` (no markers) and placement methods by name (default: ``none`` and
            every registered method: ``omp``, ``random``, ``uniform``, the paper's comparison).
        runs: placements per randomized method (random, uniform), seeds ``placement_seed + run``.
        ks: marker budgets (OMP is computed once with max k; prefixes are the smaller budgets).
        tag_scale: printed tag size = planned size * tag_scale (sensitivity study; the planner's
            marker model still uses the nominal size).
        shift: markers are moved along their wall by +-shift metres, alternating sign with a
            seeded first sign (sensitivity study).
        tag_ids: which tag36h11 code each drawn marker shows. ``order`` (default; every
            result before this option was measured so): a placement's markers show ids 0..k-1
            in placement order. ``candidate``: a marker on candidate spot c shows id c in every
            placement, any other marker an id above the candidates, one per pose; then two
            placements with the same spots in an image's view draw the same image, whose render
            is shared (:mod:`markerplace.testbed.render_store`), which makes the ceiling's
            single-tag runs and runs of several k cheaper. The codes differ, so results differ
            from ``order`` by test-image noise.
    """

    methods: tuple[str, ...] = field(default_factory=method_names)
    runs: int = 5
    ks: tuple[int, ...] = (5, 10, 15, 20)
    tag_scale: float = 1.0
    shift: float = 0.0
    tag_ids: str = "order"


@dataclass(frozen=True)
class LocalizationConfig:
    """How test images are localized.

    Attributes:
        localizer: registered localizer name (:data:`markerplace.localization.localizer.LOCALIZERS`).
        use_tags: tag detection in the localizer (paper's "marker detection"; off = --no-tags).
        tag_corners: also use the tag corners as 2D-3D correspondences.
        vlad_clusters: k-means clusters of the VLAD codebook (trained on the no-marker map).
    """

    localizer: str = "sift_pnp"
    use_tags: bool = True
    tag_corners: bool = False
    vlad_clusters: int = 64


@dataclass(frozen=True)
class DiagnosticsConfig:
    """Extra analyses of an evaluation (off by default: each costs localizations).

    Attributes:
        ceiling: the oracle ceiling (:mod:`markerplace.testbed.ceiling`): every candidate
            evaluated alone on the test images, the greedy best k evaluated as a placement.
        calibration: map images localized against the rest of the map without and with each
            placement's tags, and how well the score predicts that
            (:mod:`markerplace.testbed.calibration`).
    """

    ceiling: bool = False
    calibration: bool = False


@dataclass(frozen=True)
class EvaluateConfig:
    """Every setting of an ``evaluate`` run, saved resolved in its ``config.json``.

    Attributes:
        test: which test images.
        study: what is compared.
        localization: how test images are localized.
        diagnostics: the oracle ceiling and the score's calibration on map images.
        thresholds: recall thresholds (metres, degrees).
        seed: seed of the localizer's RANSAC, of the VLAD codebook's k-means, of the
            held-out ceiling's random splits and, unless ``test.seed`` is set, of the test
            poses and the shift signs.
    """

    test: TestSetConfig = field(default_factory=TestSetConfig)
    study: StudyConfig = field(default_factory=StudyConfig)
    localization: LocalizationConfig = field(default_factory=LocalizationConfig)
    diagnostics: DiagnosticsConfig = field(default_factory=DiagnosticsConfig)
    thresholds: tuple[tuple[float, float], ...] = THRESHOLDS
    seed: int = 0

    @property
    def pose_seed(self) -> int:
        """Seed of the test poses and shift signs: ``test.seed``, else ``seed``."""
        return self.seed if self.test.seed is None else self.test.seed


#: ``--tag-ids`` choices (:attr:`StudyConfig.tag_ids`).
TAG_IDS = ("order", "candidate")


def validate_evaluate_config(config: EvaluateConfig) -> None:
    """Raise :class:`UserError` (one line) for settings that cannot work."""
    from markerplace.localization.localizer import LOCALIZERS
    from markerplace.validation import check_evaluate_config

    sets, methods = config.test.sets, config.study.methods
    if not sets or any(t not in TEST_SETS for t in sets):
        raise UserError(f"--test-sets {','.join(sets)!r} is not valid: use a comma list of {', '.join(TEST_SETS)}")
    if any(m not in method_names() for m in methods):
        raise UserError(f"--methods {','.join(methods)!r} is not valid: use a comma list of {', '.join(method_names())}")
    LOCALIZERS.lookup(config.localization.localizer)
    diag = config.diagnostics
    if (diag.ceiling or diag.calibration) and NO_MARKERS not in methods:
        raise UserError("--ceiling and --calibration compare with no markers: keep 'none' in --methods")
    if diag.ceiling and (config.study.tag_scale != 1.0 or config.study.shift != 0.0):
        raise UserError("--ceiling places tags as planned: leave out --tag-scale and --shift (or --ceiling)")
    if config.study.tag_ids not in TAG_IDS:
        raise UserError(f"--tag-ids {config.study.tag_ids!r} is not valid: use one of {', '.join(TAG_IDS)}")
    check_evaluate_config(config)  # numbers: finite and in range (markerplace.validation)
