"""The bounds of every numeric command-line option, and :func:`check_args`, which applies them.

The bounds of options that set a config field live on the field
(:func:`markerplace.settings.setting`); this module gathers them per subcommand
(:func:`option_bounds`, built on first use) next to the hand-written ones of the other options
(:mod:`markerplace.validation`); :func:`field_bound` gives one field's. :func:`check_args` is
called once by :func:`markerplace.cli.main.main` for every subcommand: one-line :class:`~markerplace.errors.UserError`, exit code 2.
"""

from __future__ import annotations

from markerplace.errors import UserError
from markerplace.pipelines.study import StudyPlan
from markerplace.plan.config import PlanConfig
from markerplace.runtime.cluster import parse_cluster
from markerplace.runtime.executor import RuntimeConfig
from markerplace.settings import Bound, bounds_by_dest, walk
from markerplace.testbed.config import EvaluateConfig
from markerplace.validation import (
    COORDINATE,
    DEPTH_MAX,
    EVERY,
    FRAME_STEP,
    HFOV,
    IMAGE_HEIGHT,
    IMAGE_WIDTH,
    MATCH_RADIUS,
    MAX_DT,
    SEED,
    SPLIT_BLOCK,
    SPLIT_GAP,
    SPLIT_MAP_STEP,
    SPLIT_QUERY_STEP,
    UNIT_SCALE,
    VOXEL,
    YAW_DEG,
    parse_floats,
    parse_int_list,
)

__all__ = ["check_args", "command_name", "field_bound", "option_bounds"]

_SCENE_OPTIONS = {"unit_scale": UNIT_SCALE, "seed": SEED}

def _configs() -> dict:
    """The root configs of ``plan`` and ``evaluate`` (defaults), imported when first needed."""
    return {"plan": PlanConfig(), "evaluate": EvaluateConfig()}


def field_bound(root: str, path: str) -> Bound:
    """The :class:`Bound` of the config field ``path`` of ``root`` (``plan``/``evaluate``)."""
    leaf = next(leaf for leaf in walk(_configs()[root]) if leaf.path == path)
    return leaf.setting.bound()


_BOUNDS: dict[str, dict[str, Bound]] = {}


def option_bounds() -> dict[str, dict[str, Bound]]:
    """Subcommand -> argparse ``dest`` -> bound, for every numeric option (``render --height`` is
    pixels, ``plan --height`` metres); the options of config fields come from the fields.
    Comma-separated options are parsed by :func:`parse_floats` / :func:`parse_int_list` and
    checked there."""
    if not _BOUNDS:
        configs = _configs()
        plan = {**_SCENE_OPTIONS, **bounds_by_dest(configs["plan"], "evaluate")}
        evaluate = bounds_by_dest(configs["evaluate"], "evaluate")
        _BOUNDS.update({
            "scene export": {"seed": SEED, "voxel": VOXEL},
            "fuse": {"voxel": VOXEL, "depth_max": DEPTH_MAX, "every": EVERY, "max_dt": MAX_DT},
            "render": {**_SCENE_OPTIONS, "width": IMAGE_WIDTH, "height": IMAGE_HEIGHT, "hfov": HFOV},
            "plan": {**_SCENE_OPTIONS, **bounds_by_dest(configs["plan"], "plan"), "frame_step": FRAME_STEP},
            "evaluate": {**plan, **evaluate, "block": SPLIT_BLOCK, "gap_frames": SPLIT_GAP, "map_step": SPLIT_MAP_STEP,
                         "query_step": SPLIT_QUERY_STEP},
            "study": {**plan, **bounds_by_dest(configs["evaluate"], "study"), **bounds_by_dest(StudyPlan(), "study")},
            "check": {"match_radius": MATCH_RADIUS, **bounds_by_dest(RuntimeConfig(), "check")},
        })
    return _BOUNDS


def command_name(args) -> str:
    """``"plan"``, ``"render"``, ``"evaluate"``, ``"scene export"``, ... of a parsed command line."""
    name = getattr(args, "command", None) or ""
    if name == "scene":
        name = f"scene {getattr(args, 'scene_command', '') or ''}".strip()
    return name


def check_args(args) -> None:
    """Check every numeric option of a parsed command line against :func:`option_bounds` (None =
    default, skipped), parse-check ``--pose``, ``--start`` and the ``--k`` lists, and check
    ``--cluster`` (:func:`markerplace.runtime.cluster.parse_cluster`; ``--workers`` does not go
    with it, ``--cluster-wait`` only with it). Whether a scheduler answers is checked once the output paths are
    (:func:`markerplace.runtime.cluster.check_scheduler`)."""
    for dest, bound in option_bounds().get(command_name(args), {}).items():
        value = getattr(args, dest, None)
        if value is not None:
            bound.check(value)
    if getattr(args, "pose", None) is not None:
        parse_floats(args.pose, "--pose", ("X", "Y", "Z", "YAW_DEG"), (COORDINATE, COORDINATE, COORDINATE, YAW_DEG))
    if getattr(args, "start", None) is not None:
        parse_floats(args.start, "--start", ("X", "Y"), (COORDINATE, COORDINATE))
    if command_name(args) in ("evaluate", "study") and isinstance(getattr(args, "k", None), str):
        parse_int_list(args.k, "--k", field_bound("evaluate", "study.ks"))
    if getattr(args, "cluster_wait", None) is not None and getattr(args, "cluster", None) is None:
        raise UserError(f"--cluster-wait {args.cluster_wait:g} has no effect without --cluster: it is how long to "
                        "wait for the workers of a Dask cluster; leave it out, or give --cluster")
    if getattr(args, "cluster", None) is not None:
        parse_cluster(args.cluster)
        if getattr(args, "workers", 0):
            raise UserError(f"--workers {args.workers} has no effect with --cluster {args.cluster}: the cluster's "
                            "workers do the work (give their number in local:N); leave --workers out")
