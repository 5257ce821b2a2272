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
IMAGE_WIDTH = Bound("--width", 16, 4096, "px", "an image width in pixels, e.g. 600", integer=True)
IMAGE_HEIGHT = Bound("--height", 16, 4096, "px", "an image height in pixels, e.g. 450", integer=True)
HFOV = Bound("--hfov", 1.0, 170.0, "deg", "a horizontal field of view in degrees, e.g. 90")
COORDINATE = Bound("coordinate", -1e7, 1e7, "m", "world coordinates in metres")
YAW_DEG = Bound("yaw", -1e6, 1e6, "deg", "a yaw in degrees")

VOXEL = Bound("--voxel", 0.001, 1.0, "m", "a TSDF voxel edge in metres, e.g. 0.02")
DEPTH_MAX = Bound("--depth-max", 0.1, 100.0, "m", "a depth cut-off in metres, e.g. 4")
EVERY = Bound("--every", 1, 1_000_000, "", "a frame step N (every N-th frame is fused), e.g. 1", integer=True)
MAX_DT = Bound("--max-dt", 1e-6, 10.0, "s", "a time difference in seconds, e.g. 0.02")
CHECK_WORKERS = Bound("--workers", 1, 256, "", "a number of processes, e.g. 1", integer=True)
MATCH_RADIUS = Bound("--match-radius", 0.05, 20.0, "m", "a distance in metres, e.g. 1.5")

_SCENE_OPTIONS = {"unit_scale": UNIT_SCALE, "seed": SEED}

_FIELD_BOUNDS = {
    "K": ("plan", "placement.k"), "V": ("plan", "placement.v"), "TAG_SIZE": ("plan", "placement.tag_size"),
    "PLACEMENT_SEED": ("plan", "placement.seed"), "PLANE_HEIGHT": ("plan", "discretize.height"),
    "LEVEL": ("plan", "discretize.level"), "GRID_SPACING": ("plan", "discretize.grid_spacing"),
    "CLEARANCE": ("plan", "discretize.clearance"), "YAWS": ("plan", "discretize.num_yaws"),
    "MARKER_SPACING": ("plan", "discretize.candidates.marker_spacing"), "WORKERS": ("plan", "runtime.workers"),
    "TESTS": ("evaluate", "test.tests"), "RUNS": ("evaluate", "study.runs"), "EVAL_K": ("evaluate", "study.ks"),
    "TAG_SCALE": ("evaluate", "study.tag_scale"), "SHIFT": ("evaluate", "study.shift"),
    "TEST_SEED": ("evaluate", "test.seed"),
}
"""Bounds of config fields, by their old names here: each is built from its field's
:func:`~markerplace.settings.setting` (the one home of the bound)."""


def _configs() -> dict:
    """The root configs of ``plan`` and ``evaluate`` (defaults), imported when first needed."""
    from markerplace.plan.planner import PlanConfig
    from markerplace.testbed.config import EvaluateConfig

    return {"plan": PlanConfig(), "evaluate": EvaluateConfig()}


def field_bound(root: str, path: str) -> Bound:
    """The :class:`Bound` of the config field ``path`` of ``root`` (``plan``/``evaluate``)."""
    from markerplace.settings import walk

    leaf = next(leaf for leaf in walk(_configs()[root]) if leaf.path == path)
    return leaf.setting.bound()


_BOUNDS: dict[str, dict[str, Bound]] = {}


def _bounds() -> dict[str, dict[str, Bound]]:
    """Subcommand -> argparse ``dest`` -> bound, for every numeric option (``render --height`` is
    pixels, ``plan --height`` metres); the options of config fields come from the fields.
    Comma-separated options are parsed by :func:`parse_floats` / :func:`parse_int_list` and
    checked there."""
    if not _BOUNDS:
        from markerplace.settings import bounds_by_dest

        configs = _configs()
        plan = {**_SCENE_OPTIONS, **bounds_by_dest(configs["plan"], "evaluate")}
        evaluate = bounds_by_dest(configs["evaluate"], "evaluate")
        _BOUNDS.update({
            "scene export": {"seed": SEED, "voxel": VOXEL},
            "fuse": {"voxel": VOXEL, "depth_max": DEPTH_MAX, "every": EVERY, "max_dt": MAX_DT},
            "render": {**_SCENE_OPTIONS, "width": IMAGE_WIDTH, "height": IMAGE_HEIGHT, "hfov": HFOV},
            "plan": {**_SCENE_OPTIONS, **bounds_by_dest(configs["plan"], "plan")},
            "evaluate": {**plan, **evaluate},
            "study": {**plan, "tests": evaluate["tests"], "test_seed": evaluate["test_seed"]},
            "check": {"match_radius": MATCH_RADIUS, "workers": CHECK_WORKERS},
        })
    return _BOUNDS


def __getattr__(name: str):
    """``BOUNDS`` and the bounds of config fields (:data:`_FIELD_BOUNDS`), built on first use."""
    if name == "BOUNDS":
        return _bounds()
    if name in _FIELD_BOUNDS:
        return field_bound(*_FIELD_BOUNDS[name])
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


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
    (:func:`markerplace.cli.options.check_cluster_answers`)."""
    for dest, bound in _bounds().get(command_name(args), {}).items():
        value = getattr(args, dest, None)
        if value is not None:
            bound.check(value)
    if getattr(args, "pose", None) is not None:
        parse_floats(args.pose, "--pose", ("X", "Y", "Z", "YAW_DEG"), (COORDINATE, COORDINATE, COORDINATE, YAW_DEG))
    if getattr(args, "start", None) is not None:
        parse_floats(args.start, "--start", ("X", "Y"), (COORDINATE, COORDINATE))
    if command_name(args) in ("evaluate", "study") and isinstance(getattr(args, "k", None), str):
        parse_int_list(args.k, "--k", field_bound("evaluate", "study.ks"))
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
    """Numeric settings of a :class:`~markerplace.plan.planner.PlanConfig`: every bounded field
    (the same bounds as the command line, :func:`markerplace.settings.check_bounds`)."""
    from markerplace.settings import check_bounds

    check_bounds(config)
    d = config.discretize
    if d.start is not None:
        for v in d.start:
            if not math.isfinite(float(v)):
                raise UserError(f"--start {d.start} must be two finite numbers (metres)")


def check_evaluate_config(config) -> None:
    """Numeric settings of an :class:`~markerplace.testbed.config.EvaluateConfig`."""
    from markerplace.settings import check_bounds

    if not config.study.ks:
        raise UserError("--k is empty: give positive marker counts, e.g. 5,10,15,20")
    check_bounds(config)
    SEED.check(config.seed)
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
