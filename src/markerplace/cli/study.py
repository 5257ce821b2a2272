"""The ``study`` subcommand: the paper's parameter study (Table II) and sensitivity study of one
scene (:func:`markerplace.pipelines.study.run_study`)."""

from __future__ import annotations

import argparse
import logging
from markerplace.cli.bounds import EVAL_K, SHIFT, TAG_SCALE, V
from markerplace.cli.options import add_plan_args, add_scene_args, plan_config_for_budgets
from markerplace.pipelines.evaluate import RunInputs, open_evaluation_folder
from markerplace.pipelines.study import StudyPlan, run_study
from markerplace.plan.config import validate
from markerplace.scene.spec import SceneSpec
from markerplace.testbed.config import EvaluateConfig, StudyConfig, TestSetConfig, validate_evaluate_config
from markerplace.validation import parse_float_list, parse_int_list

log = logging.getLogger(__name__)

__all__ = ["add_study_parser"]


def cmd_study(args: argparse.Namespace) -> int:
    """Handler of ``markerplace study``: prints the study's tables."""
    ks = parse_int_list(args.k, "--k", EVAL_K)
    config = EvaluateConfig(test=TestSetConfig(tests=args.tests, seed=args.test_seed),
                            study=StudyConfig(methods=("none", "omp"), ks=ks), seed=args.seed)
    validate_evaluate_config(config)
    plan = StudyPlan(vs=parse_float_list(args.vs, "--vs", V), shifts=parse_float_list(args.shifts, "--shifts", SHIFT),
                     scales=parse_float_list(args.scales, "--scales", TAG_SCALE),
                     detection_off=not args.no_detection_study, similarity_off=not args.no_similarity_study)
    plan_config = plan_config_for_budgets(args, ks)
    validate(plan_config)
    spec = SceneSpec(args.scene, args.up, args.unit_scale, args.seed)
    runs = 1 + len(plan.shifts) + len(plan.scales) + int(plan.detection_off)
    inputs = RunInputs(force=args.force, adopt=args.adopt, progress=not getattr(args, "quiet", False))
    run_config = open_evaluation_folder("study", args.out, spec, plan_config, config, inputs, runs * len(ks))
    text = run_study(spec, run_config, config, args.out, plan, progress=inputs.progress)
    print(text)
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
    p.add_argument("--tests", type=int, default=300, help="test images per test set (default 300)")
    p.add_argument("--k", default="5,10,15,20", help="comma list of marker budgets (default 5,10,15,20)")
    p.add_argument("--test-seed", type=int, default=None, help="seed of the test poses alone (default --seed)")
    p.add_argument("--vs", default="99,70,50", help="OMP v values compared with the planned -v (default 99,70,50)")
    p.add_argument("--shifts", default="0.1,0.25,0.5", help="tag shifts along the wall, metres (default 0.1,0.25,0.5)")
    p.add_argument("--scales", default="0.5,0.75,1.25", help="printed size factors (default 0.5,0.75,1.25)")
    p.add_argument("--no-detection-study", action="store_true", help="leave out the run without tag detection")
    p.add_argument("--no-similarity-study", action="store_true", help="leave out OMP without the similarity analysis")
    add_plan_args(p, "study")
    p.set_defaults(func=cmd_study)
    return p
