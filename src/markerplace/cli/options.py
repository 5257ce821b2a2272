"""Options and settings shared by ``plan`` and ``evaluate``: the scene arguments, the
discretization, scoring, placement and runtime options, and the
:class:`~markerplace.plan.config.PlanConfig` built from them.

``--start`` X,Y is given in the user's (file) frame, metres; :func:`markerplace.pipelines.size_guard.check_first_guess`
moves it into the scene's internal frame after the run-size guard. Lengths are metres.
Used by :mod:`markerplace.cli.main` (``plan``), :mod:`markerplace.cli.evaluate_command` and
:mod:`markerplace.cli.study_command`.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import fields, replace
from typing import Sequence

import tomllib

from markerplace.config_file import checked_value, read_config_file
from markerplace.errors import UserError
from markerplace.markers import check_tag_budget
from markerplace.plan.config import PlanConfig
from markerplace.plan.discretize.candidate_rules import parse_allow as parse
from markerplace.plan.place.config import K_ALL
from markerplace.plan.place.method_registry import settings_name
from markerplace.plan.place.methods import PLACEMENT_METHODS, method_conf
from markerplace.settings import add_setting_args, apply, values_from_args, walk

log = logging.getLogger(__name__)

__all__ = ["add_scene_args", "add_plan_args", "add_adopt_arg", "add_force_arg", "parse_allow",
           "plan_config_from_args", "plan_config_for_budgets", "method_conf_values"]


def add_scene_args(p: argparse.ArgumentParser, optional: str | None = None) -> None:
    """The scene argument and its options; ``optional``: the scene may be left out, and this
    says what gives it then (``evaluate --plan``)."""
    if optional:
        p.add_argument("scene", nargs="?", default=None,
                       help=f"built-in scene name (see `markerplace scene list`) or a mesh file (.glb, .gltf, .obj, "
                            f".ply); left out: {optional}")
    else:
        p.add_argument("scene", help="built-in scene name (see `markerplace scene list`) or a mesh file (.glb, .gltf, .obj, .ply)")
    p.add_argument("--up", default=None, help="up axis of the mesh file: z, y, -y, x, -x, -z (default: y for glTF, its specification; z for OBJ/PLY)")
    p.add_argument("--unit-scale", type=float, default=None, help="multiply mesh coordinates by this to get metres (e.g. 0.01 for cm, 0.001 for mm)")
    p.add_argument("--seed", type=int, default=0, help="seed of the procedural generator for built-in scenes (default 0)")




def parse_allow(text: str | None) -> tuple[str, ...]:
    """``--allow`` (:func:`markerplace.plan.discretize.candidate_rules.parse_allow`)."""
    return parse(text)


def plan_config_from_args(args: argparse.Namespace):
    """Build a :class:`~markerplace.plan.config.PlanConfig` from ``plan``/``evaluate``/``study``
    arguments: the defaults, then ``--config FILE`` (``plan``; :mod:`markerplace.config_file`),
    then every option of a config field that was given (:mod:`markerplace.settings`).

    With a target recall (``--target-recall`` or the file's ``target_recall``) and no k from
    the command line or the file, k is :data:`~markerplace.plan.place.config.K_ALL`: the plan is
    bounded by the candidates and the free tag ids alone."""
    command = getattr(args, "command", None) or "plan"
    config, file_k = PlanConfig(), False
    if getattr(args, "config", None):
        read = read_config_file(args.config, apply(config, {"placement.k": None}))  # None: the file gives no k
        file_k = read.placement.k is not None
        config = read if file_k else apply(read, {"placement.k": config.placement.k})
    given = values_from_args(args, config, command)
    given.update(method_conf_values(getattr(args, "method_conf", None), apply(config, given), command))
    config = apply(config, given)
    if config.placement.target_recall is not None and not file_k and "placement.k" not in given:
        config = apply(config, {"placement.k": K_ALL})
    return config


def method_conf_values(items: Sequence[str] | None, config, command: str = "plan") -> dict:
    """config path -> value of each ``--method-conf [METHOD.]KEY=VALUE`` (``items``, in the order
    given; a later one wins): ``KEY`` a field of the method's ``Config``
    (``placement.methods.<method>.<KEY>``), ``METHOD`` the plan's ``--method`` when left out
    (``plan`` only: ``evaluate`` and ``study`` name it). ``VALUE`` is read as a TOML value (a
    number, ``true``/``false``, a list ``[1, 2]``), anything else as a text, and checked as a
    ``--config`` file's value is (:func:`markerplace.config_file.checked_value`).

    Raises:
        UserError: one line: no ``=``, an unknown method, a key the method's settings do not
            have (naming the ones they have), or a bad value.
    """
    out: dict = {}
    for item in items or ():
        target, eq, text = item.partition("=")
        target = target.strip()
        if not eq or not target:
            raise UserError(f"--method-conf {item!r}: give KEY=VALUE (a setting of --method) or METHOD.KEY=VALUE")
        head, dot, key = target.rpartition(".")
        if not dot:
            if command != "plan":
                raise UserError(f"--method-conf {item!r}: name the method (METHOD.KEY=VALUE, e.g. omp.v=80): "
                                f"{command} has no single --method")
            head, key = config.placement.method, target
        PLACEMENT_METHODS.lookup(head)  # one line naming the known methods
        conf = method_conf(head, config.placement)
        keys = [f.name for f in fields(conf)]
        if key not in keys:
            has = f"its settings are {', '.join(keys)}" if keys else "it has no settings of its own"
            raise UserError(f"--method-conf {item!r}: {head} has no setting {key!r}: {has}")
        path = f"placement.methods.{settings_name(head)}.{key}"
        leaf = next(leaf for leaf in walk(config) if leaf.path == path)
        try:
            value = tomllib.loads(f"v = {text.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            value = text.strip()  # a bare word: a text
        out[path] = checked_value(leaf, value, "--method-conf")
    return out


def plan_config_for_budgets(args: argparse.Namespace, ks: Sequence[int]):
    """The :class:`~markerplace.plan.config.PlanConfig` of ``evaluate``/``study`` arguments.

    Their ``--k`` is a comma list of budgets (``ks``, the parsed budgets, each >= 1): the plan
    places ``max(ks)`` markers and the smaller budgets are evaluated on their own placements or
    prefixes. ``args`` is not changed.
    """
    check_tag_budget(max(ks), [])  # placements get ids 0..k-1
    config = plan_config_from_args(args)
    return replace(config, placement=replace(config.placement, k=max(ks)))


def add_plan_args(p: argparse.ArgumentParser, command: str = "plan") -> None:
    """Options shared by `plan`, `evaluate` and `study`: one per config field of
    :class:`~markerplace.plan.config.PlanConfig` that has a flag (discretization, scoring,
    placement, runtime; :func:`markerplace.settings.add_setting_args`), then the run options
    ``--force``, ``--adopt`` and ``--quiet``."""
    disc = p.add_argument_group("discretization")
    placing = p.add_argument_group("scoring and placement")
    add_setting_args(p, PlanConfig(), command, {"discretize": disc, "placement": placing, "runtime": placing})
    placing.add_argument("--method-conf", action="append", metavar="[METHOD.]KEY=VALUE",
                         help="a setting of a placement method's own (its [placement.methods.METHOD] table), e.g. "
                              "v=80 or expected-recall.calibration_runs=5; METHOD defaults to --method (plan); "
                              "repeat it for more")
    placing.add_argument("--force", action="store_true",
                         help="run even when the size guard estimates more poses, memory or time than the limits "
                              "(200,000 poses, 80%% of this machine's memory, 12 h), or loading the model file more "
                              "memory than is free")
    add_adopt_arg(p)
    p.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help="no progress bars, warnings only")


def add_force_arg(p: argparse.ArgumentParser) -> None:
    """``--force`` of the commands without a size guard that load a model (``render``, ``scene
    export``, ``export``, ``check``): :func:`markerplace.scene.preflight.check_memory`."""
    p.add_argument("--force", action="store_true",
                   help="load the model file even when it is estimated to need more memory than is free")


def add_adopt_arg(p: argparse.ArgumentParser) -> None:
    """``--adopt``: write a run into a non-empty folder markerplace did not make
    (:mod:`markerplace.runtime.run_folder`)."""
    p.add_argument("--adopt", action="store_true",
                   help="use a non-empty --out folder that markerplace did not make: its run files are added, the "
                        "files already there are never replaced or deleted (default: such a folder is refused)")
