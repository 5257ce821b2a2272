"""The ``evaluate`` subcommand: parses arguments and runs :func:`markerplace.pipelines.evaluate.run_evaluation`.

Wire it into the main parser with ``add_evaluate_parser(subparsers)``.
"""

from __future__ import annotations

import argparse
import logging
from dataclasses import replace

from markerplace.cli.frames_eval import add_frames_eval_args, cmd_evaluate_frames
from markerplace.cli.options import add_plan_args, add_scene_args, method_conf_values, plan_config_for_budgets
from markerplace.errors import UserError
from markerplace.pipelines.evaluate import RunInputs, evaluate
from markerplace.pipelines.from_plan import start_from_plan
from markerplace.plan.config import PlanConfig
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.plan.where import load_where
from markerplace.scene.spec import SceneSpec
from markerplace.settings import add_setting_args, apply, values_from_args
from markerplace.testbed.config import EvaluateConfig, validate_evaluate_config

log = logging.getLogger("markerplace.cli.main")


def evaluate_config_from_args(args: argparse.Namespace):
    """Build an :class:`~markerplace.testbed.config.EvaluateConfig` from parsed ``evaluate``
    arguments: an option per config field (:mod:`markerplace.settings`), ``seed`` from the
    scene's ``--seed`` (0 when left out)."""
    config = EvaluateConfig()
    return replace(apply(config, values_from_args(args, config, "evaluate")), seed=args.seed or 0)


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Handler of ``markerplace evaluate``: :func:`markerplace.pipelines.evaluate.evaluate`, then
    the recall table at (5 cm, 5 deg) and what it wrote. With ``--plan``, the scene, the plan's
    settings and its placement come from the plan folder (:mod:`markerplace.pipelines.from_plan`)."""
    config = evaluate_config_from_args(args)
    # its budgets are valid before the plan settings use them (a --plan may bring a where file)
    validate_evaluate_config(config, where=args.where is not None or args.plan is not None)
    inputs = RunInputs(force=args.force, adopt=args.adopt, progress=not getattr(args, "quiet", False))
    if args.frames is not None:
        return cmd_evaluate_frames(args, plan_config_for_budgets(args, config.study.ks), config, inputs.progress)
    if args.plan is not None:
        given = values_from_args(args, PlanConfig(), "evaluate")
        given.update(method_conf_values(args.method_conf, PlanConfig(), "evaluate"))
        start = start_from_plan(args.plan, given, config,
                                ks_given=args.k is not None, scene=args.scene, up=args.up,
                                unit_scale=args.unit_scale, seed=args.seed, where=args.where)
        result = evaluate(start.scene_spec, start.plan_config, start.config, args.out, args.placements, inputs,
                          plan=start.folder, where=start.where)
    elif args.scene is None:
        raise UserError("evaluate needs a scene (a built-in name or a mesh file) or --plan PLAN_DIR")
    else:
        scene = SceneSpec(args.scene, args.up, args.unit_scale, args.seed or 0)
        result = evaluate(scene, plan_config_for_budgets(args, config.study.ks), config, args.out, args.placements,
                          inputs, where=load_where(args.where) if args.where else None)
    print(result.summary)
    extra = "".join(f", {f}" for f, on in (("ceiling.md", args.ceiling), ("calibration.md, calibration.png, map_outcomes.npz",
                                                                          args.calibration),
                                           ("predicted.csv", args.predicted)) if on)
    print(f"\nwrote {args.out}/recall.csv, tables.md, recall_vs_k.png, query_errors.npz, timings.json, config.json, "
          f"report.html{extra}")
    return 0


def add_evaluate_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``evaluate`` subcommand (with its handler) to ``subparsers``."""
    methods = ", ".join(f"{name} = {cls.label or name}" for name, cls in PLACEMENT_METHODS.items())

    p = subparsers.add_parser(
        "evaluate",
        help="simulation testbed: place markers with each method, render, localize test images, report recall",
        description=f"Compare marker placements in simulation (the paper's experiments): no markers and the "
                    f"placement methods ({methods}); recall at (1 cm, 1 deg), (5 cm, 5 deg), (10 cm, 10 deg), "
                    "(1 m, 30 deg). --seed also seeds the test poses unless --test-seed is given.",
    )
    add_scene_args(p, optional="--plan's")
    p.set_defaults(seed=None)  # (--plan refuses a --seed other than its plan's, but only one that was given)
    p.add_argument("--out", required=True, help="run directory (outputs, caches; an interrupted run resumes)")
    p.add_argument("--plan", default=None, metavar="PLAN_DIR",
                   help="start from a finished `markerplace plan` folder: its scene, settings and placement (as its "
                        "method's), its cached stages reused; the folder is only read")
    p.add_argument("--placements", default=None, metavar="DIR",
                   help="folder of placement.json files (e.g. from `markerplace plan`) evaluated as extra methods")
    p.add_argument("--where", default=None, metavar="FILE",
                   help="GeoJSON file of where the cameras will be (docs/where.md): the methods weigh the camera "
                        "poses by it and --test-sets where draws test images from it (with --plan: the plan's)")
    study = p.add_argument_group("study switches")
    diagnostics = p.add_argument_group("diagnostics (each costs extra localizations)")
    add_setting_args(p, EvaluateConfig(), "evaluate", {"localization": study, "diagnostics": diagnostics},
                     defaults=True)
    add_plan_args(p, "evaluate")
    add_frames_eval_args(p)
    p.set_defaults(func=cmd_evaluate, k=None)  # (--k's default is the field's; None tells --plan it was left out)
    return p
