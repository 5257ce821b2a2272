"""The ``evaluate`` subcommand: parses arguments and runs :func:`markerplace.testbed.experiment.run_evaluation`.

Wire it into the main parser with ``add_evaluate_parser(subparsers)``.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from markerplace.errors import UserError

log = logging.getLogger("markerplace.cli.main")


def evaluate_config_from_args(args: argparse.Namespace):
    """Build an :class:`~markerplace.testbed.config.EvaluateConfig` from parsed ``evaluate``
    arguments: an option per config field (:mod:`markerplace.settings`), ``seed`` from the
    scene's ``--seed``."""
    from dataclasses import replace

    from markerplace.settings import apply, values_from_args
    from markerplace.testbed.config import EvaluateConfig

    config = EvaluateConfig()
    return replace(apply(config, values_from_args(args, config, "evaluate")), seed=args.seed)


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Handler of ``markerplace evaluate``: prints the recall table at (5 cm, 5 deg)."""
    from markerplace.cli.options import check_cluster_answers, plan_config_for_budgets, plan_inputs_in_scene_frame
    from markerplace.testbed.config import validate_evaluate_config
    from markerplace.testbed.marker_sets import find_placement_files, method_names
    from markerplace.markers import load_markers
    from markerplace.scene.spec import SceneSpec
    from markerplace.plan.planner import validate
    from markerplace.testbed.experiment import run_evaluation
    from markerplace.runtime.run_folder import open_run_folder

    config = evaluate_config_from_args(args)
    validate_evaluate_config(config)
    if not config.study.methods and not args.placements:
        raise UserError(f"--methods is empty: give a comma list such as {','.join(method_names())} (or --placements DIR)")
    plan_config = plan_config_for_budgets(args, config.study.ks)
    validate(plan_config)
    # every input file is read before any work: a bad --placements fails in a second, not after the plan
    placement_files = find_placement_files(args.placements) if args.placements else {}
    for path in placement_files.values():
        load_markers(path, "--placements")
    open_run_folder(args.out, "evaluate", adopt=args.adopt)
    check_cluster_answers(args)
    spec = SceneSpec(args.scene, args.up, args.unit_scale, args.seed)
    run_config = plan_inputs_in_scene_frame(plan_config, spec.load(), args.force, config, len(placement_files))
    result = run_evaluation(spec, run_config, config, args.out, placements_dir=args.placements,
                            progress=not getattr(args, "quiet", False))
    print(result.summary)
    extra = "".join(f", {f}" for f, on in (("ceiling.md", args.ceiling), ("calibration.md, calibration.png, map_outcomes.npz",
                                                                          args.calibration)) if on)
    print(f"\nwrote {args.out}/recall.csv, tables.md, recall_vs_k.png, query_errors.npz, timings.json, config.json, "
          f"report.html{extra}")
    return 0


def add_evaluate_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``evaluate`` subcommand (with its handler) to ``subparsers``."""
    from markerplace.plan.place.methods import PLACEMENT_METHODS
    from markerplace.settings import add_setting_args
    from markerplace.testbed.config import EvaluateConfig
    from markerplace.cli.options import add_plan_args, add_scene_args

    methods = ", ".join(f"{name} = {cls.label or name}" for name, cls in PLACEMENT_METHODS.items())

    p = subparsers.add_parser(
        "evaluate",
        help="simulation testbed: place markers with each method, render, localize test images, report recall",
        description=f"Compare marker placements in simulation (the paper's experiments): no markers and the "
                    f"placement methods ({methods}); recall at (1 cm, 1 deg), (5 cm, 5 deg), (10 cm, 10 deg), "
                    "(1 m, 30 deg). --seed also seeds the test poses unless --test-seed is given.",
    )
    add_scene_args(p)
    p.add_argument("--out", required=True, help="run directory (outputs, caches; an interrupted run resumes)")
    p.add_argument("--placements", default=None, metavar="DIR",
                   help="folder of placement.json files (e.g. from `markerplace plan`) evaluated as extra methods")
    study = p.add_argument_group("study switches")
    diagnostics = p.add_argument_group("diagnostics (each costs extra localizations)")
    add_setting_args(p, EvaluateConfig(), "evaluate", {"localization": study, "diagnostics": diagnostics},
                     defaults=True)
    add_plan_args(p, "evaluate")
    p.set_defaults(func=cmd_evaluate)
    return p
