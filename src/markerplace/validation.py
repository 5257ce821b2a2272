"""Checks of option values before any work starts: every numeric option has one bound.

Everything here raises :class:`~markerplace.errors.UserError` (one line, exit code 2) and runs
in milliseconds, before the expensive stages.

A :class:`~markerplace.settings.Bound` (finite, in a range, with its unit and an example) checks
one numeric option. The bounds of options that set a config field live on the field
(:func:`markerplace.settings.setting`); the other options' are here (``--unit-scale``, ``--seed``,
``render``, ``fuse``, ``check``). :mod:`markerplace.cli.bounds` gathers both per subcommand and
applies them to a parsed command line; :func:`check_plan_config` / :func:`check_evaluate_config`
apply the fields' bounds to the library's config objects. :func:`parse_floats`,
:func:`parse_int_list`, :func:`parse_level` and :func:`parse_xy` parse the comma-separated and
special options (``--pose``, ``--start``, ``--k``, ``--level``); :func:`check_pose_in_scene` and
:func:`check_render_sees_something` refuse a ``render`` pose outside the model or seeing nothing
of it. Lengths are metres, angles degrees.

The other up-front checks: output paths in :mod:`markerplace.output_paths`, the run-size guard
in :mod:`markerplace.pipelines.size_guard`.
"""

from __future__ import annotations

import argparse
import math
from typing import Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.settings import SEED_MAX, Bound, check_bounds

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
FRAME_STEP = Bound("--frame-step", 1, 1_000_000, "", "a frame step N (every N-th frame is a camera pose), e.g. 4",
                   integer=True)
SPLIT_BLOCK = Bound("--block", 2, 1_000_000, "", "frames per block of the map / query split, e.g. 50", integer=True)
SPLIT_GAP = Bound("--gap-frames", 1, 1_000_000, "", "frames left out at each end of a query block, e.g. 10",
                  integer=True)
SPLIT_MAP_STEP = Bound("--map-step", 1, 1_000_000, "", "a frame step of the map blocks, e.g. 2", integer=True)
SPLIT_QUERY_STEP = Bound("--query-step", 1, 1_000_000, "", "a frame step of the query blocks, e.g. 2", integer=True)
MATCH_RADIUS = Bound("--match-radius", 0.05, 20.0, "m", "a distance in metres, e.g. 1.5")

def parse_level(text: str):
    """``--level``: ``all`` (None) or a storey index >= 0 (argparse type: raises
    :class:`argparse.ArgumentTypeError`)."""
    if str(text).strip().lower() == "all":
        return None
    try:
        level = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a storey: give N >= 0 or 'all'") from None
    if level < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a storey: give N >= 0 (0 = lowest) or 'all'")
    return level


def parse_xy(text: str | None):
    """``--start`` X,Y: two finite coordinates, metres (None stays None)."""
    if text is None:
        return None
    return tuple(parse_floats(text, "--start", ("X", "Y"), (COORDINATE, COORDINATE)))


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
    """Numeric settings of a :class:`~markerplace.plan.config.PlanConfig`: every bounded field
    (the same bounds as the command line, :func:`markerplace.settings.check_bounds`)."""
    check_bounds(config)
    d = config.discretize
    if d.start is not None:
        for v in d.start:
            if not math.isfinite(float(v)):
                raise UserError(f"--start {d.start} must be two finite numbers (metres)")


def check_evaluate_config(config) -> None:
    """Numeric settings of an :class:`~markerplace.testbed.config.EvaluateConfig`."""
    if not config.study.ks:
        raise UserError("--k is empty: give positive marker counts, e.g. 5,10,15,20")
    check_bounds(config)
    SEED.check(config.seed)
    if config.localization.vlad_clusters < 2:
        raise UserError(f"VLAD clusters {config.localization.vlad_clusters} must be at least 2")


def check_pose_in_scene(scene, position, offset=(0.0, 0.0, 0.0), margin: float = 0.0) -> None:
    """Refuse a camera position (internal frame, metres) outside the model's bounding box
    (grown by ``margin``); the message gives the box in the user's frame (+ ``offset``)."""
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
    depth = getattr(result, "depth", None)
    if depth is not None and not np.any(np.asarray(depth) > 0):
        where = f"--pose {pose_text}" if pose_text else "the default pose"
        raise UserError(f"the camera at {where} sees nothing of the model (every pixel is empty): "
                        "give a pose inside the model, looking at its walls")
