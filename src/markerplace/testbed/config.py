"""Settings of an ``evaluate`` run (the paper's experiments; defaults as published), in four
parts: which test images, what is compared (the study), how images are localized, and how
recall is counted.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

from markerplace.errors import UserError
from markerplace.localization.localizer import LOCALIZERS
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.settings import SEED_MAX, setting
from markerplace.simulation.conditions import CLEAN, CONDITIONS
from markerplace.simulation.config import LocalizationConfig
from markerplace.simulation.marker_sets import NO_MARKERS, method_names
from markerplace.simulation.metrics import THRESHOLDS
from markerplace.simulation.pose_sampling import ALL_TEST_SETS, TEST_SETS, WHERE_SET
from markerplace.validation import check_evaluate_config, parse_int_list

#: ``--tag-ids`` choices (:attr:`StudyConfig.tag_ids`).
TAG_IDS = ("order", "candidate")


def _name_list(text) -> tuple[str, ...]:
    """``a,b`` (or a config file's list) -> ("a", "b")."""
    return tuple(v.strip() for v in str(text).split(",") if v.strip())


def _int_list(text) -> tuple[int, ...]:
    """``--k``: comma list of positive marker budgets."""
    ks = next(f for f in fields(StudyConfig) if f.name == "ks")
    return parse_int_list(text, "--k", ks.metadata["setting"].bound())


def _placement_help() -> str:
    return PLACEMENT_METHODS.help()


__all__ = ["TestSetConfig", "StudyConfig", "DiagnosticsConfig", "EvaluateConfig", "validate_evaluate_config"]


@dataclass(frozen=True)
class TestSetConfig:
    """Which test images.

    Attributes:
        tests: test images per test set (paper: 200 room ... 10000 apartment).
        sets: ``weighted`` (towards low scores), ``uniform`` and, with ``--where``, ``where``.
        seed: seed of the test poses and the shift signs alone; None = the run's ``seed``.
        min_clearance: test cameras need this clearance (metres) from non-free cells.
        conditions: query conditions (:mod:`markerplace.simulation.conditions`): every test set
            is localized under each (``clean``: as the map is rendered, the default, every
            result before conditions existed); the map stays clean.
    """

    __test__ = False

    tests: int = setting(200, flag="--tests", commands=("evaluate",), bounds=(1, 100_000), metavar="N", help="test images per test set",
                         hint="test images per test set, e.g. 200")
    sets: tuple[str, ...] = setting(TEST_SETS, flag="--test-sets", commands=("evaluate",), convert=_name_list,
                                    help="comma list of weighted (towards low scores), uniform and, with --where, "
                                         "where (drawn from the where file's pose weights)",
                                    doc="`weighted` draws test poses with the paper's weights w = 2 l* - mean(l) - l "
                                        "(more where scores are low); `uniform` draws uniformly; `where` (only with "
                                        "`--where FILE` or a `--plan` made with one) draws them in proportion to "
                                        "the file's pose weights ([where.md](where.md))")
    seed: int | None = setting(None, flag="--test-seed", commands=("evaluate", "study"), bounds=(0, SEED_MAX), metavar="N", shown_default="--seed",
                               hint=f"a seed in 0..{SEED_MAX}, e.g. 3",
                               help="seed of the test poses (and --shift signs) alone; default: --seed. Draws a new "
                                    "test set without changing a built-in scene")
    min_clearance: float = 0.1
    conditions: tuple[str, ...] = setting((CLEAN,), flag="--conditions", commands=("evaluate",), convert=_name_list,
                                          help=lambda: "comma list of query conditions, the test images taken as a "
                                          "phone would (the map stays clean): " + CONDITIONS.help(),
                                          doc="comma list of query conditions; each test set is localized under "
                                              "each, reported per condition (docs/design.md, *Query conditions*): "
                                              "`clean` (as the map), `exposure`, `white_balance`, `lighting`, "
                                              "`noise`, `blur`, `occluders`")


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
            is shared (:mod:`markerplace.simulation.render_store`), which makes the ceiling's
            single-tag runs and runs of several k cheaper. The codes differ, so results differ
            from ``order`` by test-image noise.
    """

    methods: tuple[str, ...] = setting(default_factory=method_names, flag="--methods", commands=("evaluate",), convert=_name_list,
                                       shown_default="all",
                                       help=lambda: "comma list of none (no markers) and placement methods: "
                                       + _placement_help(),
                                       doc="comma list of `none` (no markers) and registered placement methods by "
                                           "name (`omp`, `random`, `uniform`, `human`; `--help` lists them); "
                                           "default: none + every registered method")
    runs: int = setting(5, flag="--runs", commands=("evaluate",), bounds=(1, 1000), hint="placements per random/uniform baseline, e.g. 5",
                        help="placements per randomized method (seeds --placement-seed + run); the baselines of "
                             "the paired comparisons")
    ks: tuple[int, ...] = setting((5, 10, 15, 20), flag="--k", commands=("evaluate", "study"), convert=_int_list, bounds=(1, 10_000), integer=True,
                                  hint="positive marker counts, e.g. 5,10,15,20",
                                  help="comma list of marker budgets; OMP is greedy, so its k = 5 placement is the "
                                       "prefix of its k = 20 one")
    tag_scale: float = setting(1.0, flag="--tag-scale", commands=("evaluate",), bounds=(0.1, 5.0), metavar="S",
                               hint="a factor in [0.1, 5], e.g. 1.25",
                               help="print tags S times the planned size (sensitivity study)")
    shift: float = setting(0.0, flag="--shift", commands=("evaluate",), bounds=(0.0, 5.0), units="m", metavar="D",
                           hint="a distance in [0, 5] metres, e.g. 0.1",
                           help="move every marker along its wall by +-D metres, alternating sign (sensitivity study)")
    tag_ids: str = setting("order", flag="--tag-ids", commands=("evaluate",), choices=lambda: TAG_IDS,
                           help="tag codes drawn: order (ids 0..k-1 in each placement's order, as every documented "
                                "result) or candidate (id = candidate spot, the same in every placement, so "
                                "placements share renders: cheaper ceilings and multi-k runs, results differ by "
                                "noise)")


@dataclass(frozen=True)
class DiagnosticsConfig:
    """Extra analyses of an evaluation (off by default: each costs localizations).

    Attributes:
        ceiling: the oracle ceiling (:mod:`markerplace.testbed.ceiling`): every candidate
            evaluated alone on the test images, the greedy best k evaluated as a placement.
        calibration: map images localized against the rest of the map without and with each
            placement's tags, and how well the score predicts that
            (:mod:`markerplace.simulation.success_fit`).
        predicted: each placement's predicted recall under the success model plans use (fitted
            on map images unless ``expected-recall`` is evaluated, which fits it anyway) against
            its measured recall, and the calibration error (:mod:`markerplace.testbed.predicted_per_placement`).
    """

    ceiling: bool = setting(False, flag="--ceiling", commands=("evaluate",), const=True,
                            help="oracle ceiling: every candidate evaluated alone on the test images, the greedy "
                                 "best k evaluated as a placement (a diagnostic that uses the test images, never a "
                                 "method); writes ceiling.md and adds 'ceiling' rows",
                            doc="the oracle ceiling (a diagnostic that uses the test images, never a method): every "
                                "candidate evaluated alone on the test images, then per test set the k candidates "
                                "that localize the most test images picked greedily from those outcomes and "
                                "evaluated as a placement (`ceiling` rows); `ceiling.md` sets every method against "
                                "it, and says how much of the ceiling's lead is selection on the test images (picks "
                                "made on a random half of them scored on the other half, against picks made on that "
                                "half: the `held out` and `in sample` rows, 100 splits seeded by `--seed`)")
    calibration: bool = setting(False, flag="--calibration", commands=("evaluate",), const=True,
                                help="localize every map image against the rest of the map (leave one location out) "
                                     "without and with each placement's tags, and report how well the score "
                                     "predicts success per marker model: calibration.md, calibration.png, "
                                     "map_outcomes.npz",
                                doc="every map image localized against the map without its own location, without "
                                    "tags and with each evaluated placement's tags: `calibration.md` (per marker "
                                    "model: AUC of the score as a predictor of success, without and with tags, the "
                                    "fitted logistic, observed vs fitted success per score decile), "
                                    "`calibration.png`, `map_outcomes.npz`")
    predicted: bool = setting(False, flag="--predicted", commands=("evaluate",), const=True,
                              help="set each placement's predicted recall (the success model plans use, on the "
                                   "poses as each test set draws them) against its measured recall per k, with the "
                                   "calibration error (mean |predicted - measured|, points): predicted.csv, a "
                                   "section of tables.md and report.html. Fits the model on the map images (one "
                                   "calibration run, cached) unless expected-recall is in --methods",
                              doc="each evaluated placement's predicted recall (the success model of "
                                  "`expected-recall` and of plans' recall curves, fitted on map images; the "
                                  "feasible poses weighted as each test set draws them) against its measured "
                                  "recall on the clean test images at the main threshold, per method and k, and "
                                  "the calibration error (mean absolute difference over the placements, in "
                                  "percentage points, per test set and method): `predicted.csv`, a section of "
                                  "`tables.md` and `report.html`, the error in the printed summary "
                                  "(docs/design.md section 6c). Free when `expected-recall` is in `--methods`; "
                                  "otherwise one calibration run (cached; about 70 s on `room`)")


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




def validate_evaluate_config(config: EvaluateConfig, where: bool = False) -> None:
    """Raise :class:`UserError` (one line) for settings that cannot work; ``where``: a where
    file is given (``--where`` or the ``--plan``'s), so the ``where`` test set is valid."""
    sets, methods = config.test.sets, config.study.methods
    if not sets or any(t not in ALL_TEST_SETS for t in sets):
        raise UserError(f"--test-sets {','.join(sets)!r} is not valid: use a comma list of {', '.join(TEST_SETS)} "
                        f"(and {WHERE_SET} with --where FILE)")
    if WHERE_SET in sets and not where:
        raise UserError(f"--test-sets {WHERE_SET} draws test images from the places of use: give --where FILE (or "
                        "--plan of a plan made with --where)")
    if any(m not in method_names() for m in methods):
        raise UserError(f"--methods {','.join(methods)!r} is not valid: use a comma list of {', '.join(method_names())}")
    conds = config.test.conditions
    if not conds or any(c not in CONDITIONS for c in conds) or len(set(conds)) != len(conds):
        raise UserError(f"--conditions {','.join(conds)!r} is not valid: use a comma list of distinct "
                        f"{', '.join(CONDITIONS.names())}")
    LOCALIZERS.lookup(config.localization.localizer)
    diag = config.diagnostics
    if (diag.ceiling or diag.calibration) and NO_MARKERS not in methods:
        raise UserError("--ceiling and --calibration compare with no markers: keep 'none' in --methods")
    if diag.ceiling and (config.study.tag_scale != 1.0 or config.study.shift != 0.0):
        raise UserError("--ceiling places tags as planned: leave out --tag-scale and --shift (or --ceiling)")
    if config.study.tag_ids not in TAG_IDS:
        raise UserError(f"--tag-ids {config.study.tag_ids!r} is not valid: use one of {', '.join(TAG_IDS)}")
    check_evaluate_config(config)  # numbers: finite and in range (markerplace.validation)
