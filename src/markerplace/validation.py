"""Checks of option values before any work starts: every numeric option has one bound.

Everything here raises :class:`~markerplace.errors.UserError` (one line, exit code 2) and runs
in milliseconds, before the expensive stages.

Every numeric command-line option has one :class:`Bound` (finite, in a range, with its unit and
an example) in :data:`BOUNDS`; :func:`check_args` applies them to a parsed command line (called
once by :func:`markerplace.cli.main.main` for every subcommand), and :func:`check_plan_config` /
:func:`check_evaluate_config` apply the same bounds to the library's config objects.
:func:`parse_floats` and :func:`parse_int_list` parse the comma-separated options (``--pose``,
``--start``, ``--k``); :func:`check_pose_in_scene` and :func:`check_render_sees_something` refuse
a ``render`` pose outside the model or seeing nothing of it. Lengths are metres, angles degrees.

The other up-front checks: output paths in :mod:`markerplace.output_checks`, the run-size guard
in :mod:`markerplace.pipelines.size_guard`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

from markerplace.errors import UserError

SEED_MAX = 2**32 - 1


@dataclass(frozen=True)
class Bound:
    """Allowed values of one numeric option.

    Attributes:
        option: the flag as the user types it (``--grid-spacing``).
        lo, hi: inclusive range.
        unit: unit printed after the numbers (``m``, ``px``, ``deg``, ``%``), or ``""``.
        hint: what to give instead, e.g. ``"the camera grid spacing in metres, e.g. 0.5"``.
        integer: the option is an integer (messages say "at least"/"at most").
    """

    option: str
    lo: float
    hi: float
    unit: str
    hint: str
    integer: bool = False

    def check(self, value: Any) -> Any:
        """Return ``value`` unchanged, or raise :class:`UserError` naming the option, the value,
        the range with its unit and what to give instead."""
        unit = f" {self.unit}" if self.unit else ""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise UserError(f"{self.option} {value!r} is not a number: give {self.hint}") from None
        if isinstance(value, float) and not math.isfinite(value):
            raise UserError(f"{self.option} {value} is not a finite number: give {self.hint}")
        if self.integer and value != int(value):
            raise UserError(f"{self.option} {value} must be a whole number: give {self.hint}")
        if self.integer:
            if value < self.lo:
                raise UserError(f"{self.option} {_fmt(value)} must be at least {_fmt(self.lo)}{unit}: give {self.hint}")
            if value > self.hi:
                raise UserError(f"{self.option} {_fmt(value)} must be at most {_fmt(self.hi)}{unit}: give {self.hint}")
        elif not self.lo <= value <= self.hi:
            raise UserError(f"{self.option} {_fmt(value)}{unit} is outside [{_fmt(self.lo)}, {_fmt(self.hi)}]{unit}: "
                            f"give {self.hint}")
        return value


def _fmt(v: float) -> str:
    """A short text of a number (huge integers abbreviated)."""
    if isinstance(v, int):
        text = str(v)
        return text if len(text) <= 15 else f"{text[:4]}...({len(text.lstrip('-'))} digits)"
    if v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return f"{v:g}"


OCCUPANCY_CELL = 0.05
"""Occupancy cell size of the discretization, metres: finer camera or marker spacing means nothing."""

UNIT_SCALE = Bound("--unit-scale", 1e-6, 1e6, "", "the size of one file unit in metres, e.g. 0.01 for cm")
SEED = Bound("--seed", 0, SEED_MAX, "", f"a seed in 0..{SEED_MAX}, e.g. 0", integer=True)
PLACEMENT_SEED = Bound("--placement-seed", 0, SEED_MAX, "", f"a seed in 0..{SEED_MAX}, e.g. 0", integer=True)
TEST_SEED = Bound("--test-seed", 0, SEED_MAX, "", f"a seed in 0..{SEED_MAX}, e.g. 3", integer=True)
K = Bound("-k", 1, 10_000, "", "the number of markers to place, e.g. 20", integer=True)
V = Bound("-v", 0.0, 100.0, "%", "a percentage such as 90")
TAG_SIZE = Bound("--tag-size", 0.02, 3.0, "m", "the black-square edge in metres, e.g. 0.4")
PLANE_HEIGHT = Bound("--height", 0.1, 10.0, "m", "the eye-level plane height above the floor in metres, e.g. 1.5")
LEVEL = Bound("--level", 0, 1000, "", "a storey index, 0 = lowest", integer=True)
GRID_SPACING = Bound("--grid-spacing", OCCUPANCY_CELL, 50.0, "m",
                     f"the camera grid spacing in metres, e.g. 0.5 (not finer than the {OCCUPANCY_CELL:g} m occupancy grid)")
CLEARANCE = Bound("--clearance", 0.0, 5.0, "m", "the distance of cameras from obstacles in metres, e.g. 0.3")
YAWS = Bound("--yaws", 1, 360, "", "camera yaws per location, e.g. 8", integer=True)
MARKER_SPACING = Bound("--marker-spacing", OCCUPANCY_CELL, 100.0, "m",
                       f"the spacing of candidate markers in metres, e.g. 1.0 (not finer than {OCCUPANCY_CELL:g} m)")
WORKERS = Bound("--workers", 0, 256, "", "0 (automatic) or a number of processes, e.g. 2", integer=True)
IMAGE_WIDTH = Bound("--width", 16, 4096, "px", "an image width in pixels, e.g. 600", integer=True)
IMAGE_HEIGHT = Bound("--height", 16, 4096, "px", "an image height in pixels, e.g. 450", integer=True)
HFOV = Bound("--hfov", 1.0, 170.0, "deg", "a horizontal field of view in degrees, e.g. 90")
TESTS = Bound("--tests", 1, 100_000, "", "test images per test set, e.g. 200", integer=True)
RUNS = Bound("--runs", 1, 1000, "", "placements per random/uniform baseline, e.g. 5", integer=True)
EVAL_K = Bound("--k", 1, 10_000, "", "positive marker counts, e.g. 5,10,15,20", integer=True)
TAG_SCALE = Bound("--tag-scale", 0.1, 5.0, "", "a factor in [0.1, 5], e.g. 1.25")
SHIFT = Bound("--shift", 0.0, 5.0, "m", "a distance in [0, 5] metres, e.g. 0.1")
COORDINATE = Bound("coordinate", -1e7, 1e7, "m", "world coordinates in metres")
YAW_DEG = Bound("yaw", -1e6, 1e6, "deg", "a yaw in degrees")

VOXEL = Bound("--voxel", 0.001, 1.0, "m", "a TSDF voxel edge in metres, e.g. 0.02")
DEPTH_MAX = Bound("--depth-max", 0.1, 100.0, "m", "a depth cut-off in metres, e.g. 4")
EVERY = Bound("--every", 1, 1_000_000, "", "a frame step N (every N-th frame is fused), e.g. 1", integer=True)
MAX_DT = Bound("--max-dt", 1e-6, 10.0, "s", "a time difference in seconds, e.g. 0.02")
CHECK_WORKERS = Bound("--workers", 1, 256, "", "a number of processes, e.g. 1", integer=True)
MATCH_RADIUS = Bound("--match-radius", 0.05, 20.0, "m", "a distance in metres, e.g. 1.5")

_SCENE_OPTIONS = {"unit_scale": UNIT_SCALE, "seed": SEED}
_PLAN_OPTIONS = {**_SCENE_OPTIONS, "v": V, "tag_size": TAG_SIZE, "height": PLANE_HEIGHT, "level": LEVEL,
                 "grid_spacing": GRID_SPACING, "clearance": CLEARANCE, "yaws": YAWS, "marker_spacing": MARKER_SPACING,
                 "placement_seed": PLACEMENT_SEED, "workers": WORKERS}

BOUNDS: dict[str, dict[str, Bound]] = {
    "scene export": {"seed": SEED, "voxel": VOXEL},
    "fuse": {"voxel": VOXEL, "depth_max": DEPTH_MAX, "every": EVERY, "max_dt": MAX_DT},
    "render": {**_SCENE_OPTIONS, "width": IMAGE_WIDTH, "height": IMAGE_HEIGHT, "hfov": HFOV},
    "plan": {**_PLAN_OPTIONS, "k": K},
    "evaluate": {**_PLAN_OPTIONS, "tests": TESTS, "runs": RUNS, "test_seed": TEST_SEED, "tag_scale": TAG_SCALE,
                 "shift": SHIFT},
    "study": {**_PLAN_OPTIONS, "tests": TESTS, "test_seed": TEST_SEED},
    "check": {"match_radius": MATCH_RADIUS, "workers": CHECK_WORKERS},
}
"""Subcommand -> argparse ``dest`` -> bound, for every numeric option (``render --height`` is
pixels, ``plan --height`` metres). Comma-separated options are parsed by :func:`parse_floats` /
:func:`parse_int_list` and checked there."""


def command_name(args) -> str:
    """``"plan"``, ``"render"``, ``"evaluate"``, ``"scene export"``, ... of a parsed command line."""
    name = getattr(args, "command", None) or ""
    if name == "scene":
        name = f"scene {getattr(args, 'scene_command', '') or ''}".strip()
    return name


def check_args(args) -> None:
    """Check every numeric option of a parsed command line against :data:`BOUNDS` (None =
    default, skipped), parse-check ``--pose``, ``--start`` and the ``--k`` lists, and check
    ``--cluster`` (:func:`markerplace.runtime.cluster.parse_cluster`; ``--workers`` does not go
    with it). Whether a scheduler answers is checked once the output paths are
    (:func:`markerplace.runtime.cluster.check_scheduler`)."""
    for dest, bound in BOUNDS.get(command_name(args), {}).items():
        value = getattr(args, dest, None)
        if value is not None:
            bound.check(value)
    if getattr(args, "pose", None) is not None:
        parse_floats(args.pose, "--pose", ("X", "Y", "Z", "YAW_DEG"), (COORDINATE, COORDINATE, COORDINATE, YAW_DEG))
    if getattr(args, "start", None) is not None:
        parse_floats(args.start, "--start", ("X", "Y"), (COORDINATE, COORDINATE))
    if command_name(args) in ("evaluate", "study") and isinstance(getattr(args, "k", None), str):
        parse_int_list(args.k, "--k", EVAL_K)
    if getattr(args, "cluster", None) is not None:
        from markerplace.runtime.cluster import parse_cluster

        parse_cluster(args.cluster)
        if getattr(args, "workers", 0):
            raise UserError(f"--workers {args.workers} has no effect with --cluster {args.cluster}: the cluster's "
                            "workers do the work (give their number in local:N); leave --workers out")


def parse_floats(text: str, option: str, names: Sequence[str], bounds: Sequence[Bound]) -> list[float]:
    """Parse ``"a,b,..."`` into ``len(names)`` finite numbers within ``bounds``.

    Raises:
        UserError: wrong count, not numbers, or a value not finite / out of its bound.
    """
    form = ",".join(names)
    parts = str(text).split(",")
    try:
        if len(parts) != len(names):
            raise ValueError
        values = [float(p) for p in parts]
    except ValueError:
        raise UserError(f"{option} {text!r} must be {form} ({len(names)} comma-separated numbers)") from None
    for name, value, bound in zip(names, values, bounds):
        if not math.isfinite(value) or not bound.lo <= value <= bound.hi:
            raise UserError(f"{option} {text!r}: {name} = {value:g} is not a finite number within "
                            f"[{bound.lo:g}, {bound.hi:g}] {bound.unit}; give {form}, {bound.hint}")
    return values


def parse_int_list(text: str, option: str, bound: Bound) -> tuple[int, ...]:
    """Parse a comma-separated list of integers, each within ``bound`` (not empty, no empty item)."""
    items = [v.strip() for v in str(text).split(",")]
    if not any(items):
        raise UserError(f"{option} {text!r} is empty: give e.g. 5,10,15,20")
    if not all(items):
        raise UserError(f"{option} {text!r} has an empty item: give integers separated by single commas, e.g. 5,10,15,20")
    try:
        values = tuple(int(v) for v in items)
    except ValueError:
        raise UserError(f"{option} {text!r} must be a comma-separated list of integers, e.g. 5,10,15,20") from None
    for v in values:
        bound.check(v)
    return values


def parse_float_list(text: str, option: str, bound: Bound) -> tuple[float, ...]:
    """Parse a comma-separated list of finite numbers, each within ``bound`` (``""`` is the empty
    list; an empty item between commas is refused)."""
    items = [v.strip() for v in str(text).split(",")]
    if not any(items):
        return ()
    if not all(items):
        raise UserError(f"{option} {text!r} has an empty item: give numbers separated by single commas, e.g. 0.1,0.25")
    try:
        values = tuple(float(v) for v in items)
    except ValueError:
        raise UserError(f"{option} {text!r} must be a comma-separated list of numbers, e.g. 0.1,0.25") from None
    for v in values:
        Bound(option, bound.lo, bound.hi, bound.unit, bound.hint).check(v)
    return values


def check_plan_config(config) -> None:
    """Numeric settings of a :class:`~markerplace.plan.config.PlanConfig` (the same bounds as the
    command line)."""
    d, p = config.discretize, config.placement
    K.check(p.k)
    V.check(p.v)
    TAG_SIZE.check(p.tag_size)
    PLACEMENT_SEED.check(p.seed)
    PLANE_HEIGHT.check(d.height)
    if d.level is not None:  # None: every storey (--level all)
        LEVEL.check(d.level)
    GRID_SPACING.check(d.grid_spacing)
    CLEARANCE.check(d.clearance)
    YAWS.check(d.num_yaws)
    MARKER_SPACING.check(d.marker_spacing)
    WORKERS.check(config.runtime.workers)
    if d.start is not None:
        for v in d.start:
            if not math.isfinite(float(v)):
                raise UserError(f"--start {d.start} must be two finite numbers (metres)")


def check_evaluate_config(config) -> None:
    """Numeric settings of an :class:`~markerplace.testbed.config.EvaluateConfig`."""
    test, study = config.test, config.study
    TESTS.check(test.tests)
    RUNS.check(study.runs)
    if not study.ks:
        raise UserError("--k is empty: give positive marker counts, e.g. 5,10,15,20")
    for k in study.ks:
        EVAL_K.check(k)
    TAG_SCALE.check(study.tag_scale)
    SHIFT.check(study.shift)
    SEED.check(config.seed)
    if test.seed is not None:
        TEST_SEED.check(test.seed)
    if config.localization.vlad_clusters < 2:
        raise UserError(f"VLAD clusters {config.localization.vlad_clusters} must be at least 2")


def check_pose_in_scene(scene, position, offset=(0.0, 0.0, 0.0), margin: float = 0.0) -> None:
    """Refuse a camera position (internal frame, metres) outside the model's bounding box
    (grown by ``margin``); the message gives the box in the user's frame (+ ``offset``)."""
    import numpy as np

    lo, hi = scene.bounds
    p = np.asarray(position, dtype=float)
    if np.all(p >= lo - margin) and np.all(p <= hi + margin):
        return
    off = np.asarray(offset, dtype=float)
    lo_u, hi_u, p_u = lo + off, hi + off, p + off
    box = ", ".join(f"{a} {lo_u[i]:.2f}..{hi_u[i]:.2f}" for i, a in enumerate("xyz"))
    raise UserError(f"--pose position ({p_u[0]:.2f}, {p_u[1]:.2f}, {p_u[2]:.2f}) is outside the model "
                    f"({box} m): give a point inside it")


def check_render_sees_something(result, pose_text: str | None) -> None:
    """Refuse a render in which no pixel hit the model (an all-black image, depth 0)."""
    import numpy as np

    depth = getattr(result, "depth", None)
    if depth is not None and not np.any(np.asarray(depth) > 0):
        where = f"--pose {pose_text}" if pose_text else "the default pose"
        raise UserError(f"the camera at {where} sees nothing of the model (every pixel is empty): "
                        "give a pose inside the model, looking at its walls")
