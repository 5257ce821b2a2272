"""The ``study`` subcommand: the paper's parameter study (Table II) and sensitivity study of one
scene (:func:`markerplace.pipelines.study.run_study`)."""

from __future__ import annotations

import argparse
import logging
from dataclasses import replace

from markerplace.cli.options import add_plan_args, add_scene_args, plan_config_for_budgets
from markerplace.pipelines.evaluate import RunInputs
from markerplace.pipelines.study import StudyPlan, study
from markerplace.scene.spec import SceneSpec
from markerplace.settings import add_setting_args, apply, values_from_args
from markerplace.testbed.config import EvaluateConfig, validate_evaluate_config

log = logging.getLogger(__name__)

__all__ = ["add_study_parser"]


def cmd_study(args: argparse.Namespace) -> int:
    """Handler of ``markerplace study``: :func:`markerplace.pipelines.study.study`, then its tables."""
    plan = apply(StudyPlan(), values_from_args(args, StudyPlan(), "study"))
    base = apply(EvaluateConfig(), values_from_args(args, EvaluateConfig(), "study"))  # --k, --test-seed
    config = replace(base, test=replace(base.test, tests=plan.tests), study=replace(base.study, methods=("none", "omp")),
                     seed=args.seed)
    validate_evaluate_config(config)  # its budgets are valid before the plan settings use them
    inputs = RunInputs(force=args.force, adopt=args.adopt, progress=not getattr(args, "quiet", False))
    scene = SceneSpec(args.scene, args.up, args.unit_scale, args.seed)
    print(study(scene, plan_config_for_budgets(args, config.study.ks), config, plan, args.out, inputs))
    print(f"wrote {args.out}/study.md, study.csv, study_*.png and runs/*/ (one evaluation each)")
    return 0


def add_study_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``study`` subcommand (with its handler) to ``subparsers``."""
    p = subparsers.add_parser(
        "study", help="the paper's parameter study (Table II: v, tag detection, test data, similarity) and "
                      "sensitivity study (tags shifted, printed smaller or larger) of one scene",
        description="Evaluations of OMP with one setting changed from the default each, sharing one work folder: "
                    "v, tag detection on/off, low-scoring vs uniform test images, similarity analysis on/off, tags "
                    "shifted along their walls, tags printed at other sizes. Tables with paired differences to the "
                    "default (95 % bootstrap intervals) and one figure per group.")
    add_scene_args(p)
    p.add_argument("--out", required=True, help="study folder (runs/, work/ caches; an interrupted study resumes)")
    add_setting_args(p, EvaluateConfig(), "study", defaults=True)  # --test-seed, --k
    add_setting_args(p, StudyPlan(), "study", defaults=True)  # --tests, --vs, --shifts, --scales, what to leave out
    add_plan_args(p, "study")
    p.set_defaults(func=cmd_study)
    return p
