"""The ``evaluate`` subcommand: parses arguments and runs :func:`markerplace.pipelines.evaluate.run_evaluation`.

Wire it into the main parser with ``add_evaluate_parser(subparsers)``.
"""

from __future__ import annotations

import argparse
import logging

from markerplace.cli.options import plan_config_for_budgets
from markerplace.pipelines.evaluate import RunInputs, evaluate
from markerplace.scene.spec import SceneSpec
from markerplace.testbed.config import validate_evaluate_config

log = logging.getLogger("markerplace.cli.main")


def _int_list(text: str, option: str) -> tuple[int, ...]:
    from markerplace.validation import EVAL_K, parse_int_list

    return parse_int_list(text, option, EVAL_K)


def _name_list(text: str) -> tuple[str, ...]:
    return tuple(v.strip() for v in text.split(",") if v.strip())


def evaluate_config_from_args(args: argparse.Namespace):
    """Build an :class:`~markerplace.testbed.config.EvaluateConfig` from parsed ``evaluate`` arguments."""
    from markerplace.testbed.config import DiagnosticsConfig, EvaluateConfig, LocalizationConfig, StudyConfig, TestSetConfig

    return EvaluateConfig(
        test=TestSetConfig(tests=args.tests, sets=_name_list(args.test_sets), seed=args.test_seed),
        study=StudyConfig(methods=_name_list(args.methods), runs=args.runs, ks=_int_list(args.k, "--k"),
                          tag_scale=args.tag_scale, shift=args.shift, tag_ids=args.tag_ids),
        localization=LocalizationConfig(localizer=args.localizer, use_tags=not args.no_tags,
                                        tag_corners=args.tag_corners),
        diagnostics=DiagnosticsConfig(ceiling=args.ceiling, calibration=args.calibration),
        seed=args.seed,
    )


def cmd_evaluate(args: argparse.Namespace) -> int:
    """Handler of ``markerplace evaluate``: :func:`markerplace.pipelines.evaluate.evaluate`, then
    the recall table at (5 cm, 5 deg) and what it wrote."""
    config = evaluate_config_from_args(args)
    validate_evaluate_config(config)  # its budgets are valid before the plan settings use them
    inputs = RunInputs(force=args.force, adopt=args.adopt, progress=not getattr(args, "quiet", False))
    scene = SceneSpec(args.scene, args.up, args.unit_scale, args.seed)
    result = evaluate(scene, plan_config_for_budgets(args, config.study.ks), config, args.out, args.placements, inputs)
    print(result.summary)
    extra = "".join(f", {f}" for f, on in (("ceiling.md", args.ceiling), ("calibration.md, calibration.png, map_outcomes.npz",
                                                                          args.calibration)) if on)
    print(f"\nwrote {args.out}/recall.csv, tables.md, recall_vs_k.png, query_errors.npz, timings.json, config.json, "
          f"report.html{extra}")
    return 0


def add_evaluate_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``evaluate`` subcommand (with its handler) to ``subparsers``."""
    from markerplace.plan.place.methods import PLACEMENT_METHODS
    from markerplace.localization.localizer import LOCALIZERS
    from markerplace.testbed.config import TAG_IDS
    from markerplace.testbed.marker_sets import baseline_methods, method_names
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
    p.add_argument("--tests", type=int, default=200, help="test images per test set (default 200)")
    p.add_argument("--test-sets", default="weighted,uniform",
                   help="comma list of weighted (towards low scores) and uniform (default weighted,uniform)")
    p.add_argument("--methods", default=",".join(method_names()),
                   help=f"comma list of none (no markers) and placement methods: {PLACEMENT_METHODS.help()} (default all)")
    p.add_argument("--runs", type=int, default=5,
                   help=f"placements per randomized method ({'/'.join(baseline_methods())}) (default 5)")
    p.add_argument("--k", default="5,10,15,20", help="comma list of marker budgets (default 5,10,15,20)")
    p.add_argument("--test-seed", type=int, default=None,
                   help="seed of the test poses (and --shift signs) alone; default: --seed. Draws a new test "
                        "set without changing a built-in scene")
    p.add_argument("--placements", default=None,
                   help="folder of placement.json files (e.g. from `markerplace plan`) evaluated as extra methods")
    p.add_argument("--localizer", default="sift_pnp", choices=LOCALIZERS.names(),
                   help=f"localizer of the test images: {LOCALIZERS.help()} (default sift_pnp)")
    p.add_argument("--tag-ids", default=TAG_IDS[0], choices=TAG_IDS,
                   help="tag codes drawn: order (ids 0..k-1 in each placement's order, as every documented "
                        "result) or candidate (id = candidate spot, the same in every placement, so placements "
                        "share renders: cheaper ceilings and multi-k runs, results differ by noise) (default order)")
    g = p.add_argument_group("study switches")
    g.add_argument("--no-tags", action="store_true", help="localize without tag detection")
    g.add_argument("--tag-corners", action="store_true", help="also use detected tag corners as 2D-3D matches")
    g.add_argument("--tag-scale", type=float, default=1.0,
                   help="print tags this many times the planned size (sensitivity study; default 1)")
    g.add_argument("--shift", type=float, default=0.0,
                   help="move every marker along its wall by +-D metres, alternating sign (sensitivity study; default 0)")
    g = p.add_argument_group("diagnostics (each costs extra localizations)")
    g.add_argument("--ceiling", action="store_true",
                   help="oracle ceiling: every candidate evaluated alone on the test images, the greedy best k "
                        "evaluated as a placement (a diagnostic that uses the test images, never a method); "
                        "writes ceiling.md and adds 'ceiling' rows")
    g.add_argument("--calibration", action="store_true",
                   help="localize every map image against the rest of the map (leave one location out) without "
                        "and with each placement's tags, and report how well the score predicts success per marker "
                        "model: calibration.md, calibration.png, map_outcomes.npz")
    add_plan_args(p)
    p.set_defaults(func=cmd_evaluate)
    return p
