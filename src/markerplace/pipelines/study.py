"""``markerplace study``: the paper's parameter study (Table II) and sensitivity study on one
command, as a few evaluations that share one work folder (plan, map and query images, VLAD
codebook: everything their inputs have in common is computed once).

Groups (one setting changed from the default each; recall at the main threshold):

* ``v``: OMP with the planned v (default 90) and 99, 70, 50 (extra placements of the default run);
* ``detection``: tag detection in the localizer on (default) / off (a run with ``use_tags`` off);
* ``test data``: low-scoring (weighted, default) / uniform test images (two test sets of the
  default run; different images, so no paired difference);
* ``similarity``: OMP planned with / without the similarity analysis;
* ``shift``: every OMP tag moved along its wall by +-0.1, 0.25, 0.5 m (alternating sign);
* ``size``: every OMP tag printed at 0.5, 0.75, 1.25 times its planned size.

Every row that shares the default's test images gets the paired difference to the default per
k with a 95 % bootstrap interval (:func:`markerplace.testbed.reporting.paired.bootstrap_difference`).
Outputs: ``study.md`` (the tables), ``study.csv`` (every recall), ``study_<group>.png`` (recall
vs k per group), and one folder per evaluation (``runs/<name>/``, each with its own tables).
"""

from __future__ import annotations

import csv
import logging
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from markerplace.pipelines.evaluate import RUN_OUTPUTS, STAGE_OUTPUTS, RunInputs, open_evaluation_folder, run_evaluation
from markerplace.pipelines.plan import prepare
from markerplace.plan.config import validate
from markerplace.plan.place.stage import place
from markerplace.report.figures import recall_vs_k
from markerplace.runtime.atomic_io import atomic_path
from markerplace.settings import apply, setting
from markerplace.simulation.metrics import hit_mask, main_threshold, threshold_label
from markerplace.testbed.config import DiagnosticsConfig, validate_evaluate_config
from markerplace.testbed.reporting.paired import bootstrap_difference, format_difference
from markerplace.validation import parse_float_list

log = logging.getLogger(__name__)

__all__ = ["StudyPlan", "study", "study_outputs", "study_runs", "run_study"]


def _float_list(name: str):
    """``--vs``/``--shifts``/``--scales``: a comma list of numbers, each within the field's bounds."""

    def convert(text) -> tuple[float, ...]:
        leaf = next(f for f in fields(StudyPlan) if f.name == name).metadata["setting"]
        return parse_float_list(text, leaf.flag, leaf.bound())

    return convert


@dataclass(frozen=True)
class StudyPlan:
    """The settings a study varies (defaults: the paper's), each with its ``study`` option.

    Attributes:
        tests: test images per test set of every evaluation of the study.
        vs: OMP's v values besides the planned one (paper: 99, 70, 50 against 90).
        shifts: position deviations along the wall, metres (paper: up to 1 m).
        scales: printed size factors (paper: sizes around the planned one).
        detection_off: include the run without tag detection.
        similarity_off: include OMP planned without the similarity analysis.
    """

    tests: int = setting(300, flag="--tests", bounds=(1, 100_000), metavar="N", hint="test images per set, e.g. 300",
                         help="test images per test set of every evaluation of the study")
    vs: tuple[float, ...] = setting((99.0, 70.0, 50.0), flag="--vs", convert=_float_list("vs"), bounds=(0.0, 100.0),
                                    units="%", hint="percentages such as 99,70,50",
                                    help="OMP v values compared with the planned -v (each 0-100)")
    shifts: tuple[float, ...] = setting((0.1, 0.25, 0.5), flag="--shifts", convert=_float_list("shifts"),
                                        bounds=(0.0, 5.0), units="m", hint="distances in metres, e.g. 0.1,0.25",
                                        help="tag shifts along the wall, metres (each 0-5)")
    scales: tuple[float, ...] = setting((0.5, 0.75, 1.25), flag="--scales", convert=_float_list("scales"),
                                        bounds=(0.1, 5.0), hint="factors such as 0.5,0.75,1.25",
                                        help="printed size factors (each 0.1-5)")
    detection_off: bool = setting(True, flag="--no-detection-study", const=False,
                                  help="leave out the run without tag detection")
    similarity_off: bool = setting(True, flag="--no-similarity-study", const=False,
                                   help="leave out OMP planned without the similarity analysis")


def _hits(run_dir: Path, test_set: str, threshold: tuple[float, float]) -> dict:
    """(method, run, k) -> (n,) bool hits of one evaluation at ``threshold`` for ``test_set``."""
    with np.load(run_dir / "query_errors.npz", allow_pickle=False) as z:
        methods, runs, ks = z[f"{test_set}_method"], z[f"{test_set}_run"], z[f"{test_set}_k"]
        t, r = z[f"{test_set}_t_err"], z[f"{test_set}_r_err"]
    return {(str(m), int(u), int(k)): hit_mask(t[i], r[i], *threshold) for i, (m, u, k) in enumerate(zip(methods, runs, ks))}


def _omp_variants(scene_spec, plan_config, work: Path, plan: StudyPlan, progress: bool) -> dict:
    """OMP placements with the other v values and without similarity (internal frame)."""
    k = plan_config.placement.k
    data = prepare(scene_spec, plan_config, work / "plan", progress=progress, k=k)
    out = {f"omp-v{v:g}": place(data, apply(plan_config.placement, {"method": "omp", "k": k, "methods.omp.v": v}),
                                progress=False).markers for v in plan.vs}
    if plan.similarity_off:
        nosim = replace(plan_config, placement=replace(plan_config.placement, similarity=False))
        data = prepare(scene_spec, nosim, work / "plan", progress=progress)
        out["omp-nosim"] = place(data, replace(nosim.placement, method="omp", k=k), progress=False).markers
    return out


def study_runs(config, plan: StudyPlan) -> dict:
    """The study's evaluations and their settings, each checked before any runs.

    Args:
        config: :class:`~markerplace.testbed.config.EvaluateConfig` of the default run; its
            methods, test sets, shift, size and diagnostics are set here.
        plan: what the study varies.

    Returns:
        run name (``default``, ``no-detection``, ``shift-<D>``, ``size-<S>``) -> its config. The
        default run evaluates none and OMP on both test sets; the others OMP on the weighted set
        with one setting changed. None runs the oracle ceiling or the calibration: the study
        compares settings, and those diagnostics refuse shifted or rescaled tags.
    """
    base_cfg = replace(config, test=replace(config.test, sets=("weighted", "uniform")),
                       study=replace(config.study, methods=("none", "omp"), shift=0.0, tag_scale=1.0),
                       diagnostics=DiagnosticsConfig())
    runs = {"default": base_cfg}
    weighted = replace(base_cfg.test, sets=("weighted",))
    if plan.detection_off:
        runs["no-detection"] = replace(base_cfg, test=weighted,
                                       localization=replace(base_cfg.localization, use_tags=False))
    for d in plan.shifts:
        runs[f"shift-{d:g}"] = replace(base_cfg, test=weighted,
                                       study=replace(base_cfg.study, methods=("omp",), shift=d))
    for s in plan.scales:
        runs[f"size-{s:g}"] = replace(base_cfg, test=weighted,
                                      study=replace(base_cfg.study, methods=("omp",), tag_scale=s))
    for cfg in runs.values():
        validate_evaluate_config(cfg)
    return runs


def study(scene_spec, plan_config, config, plan: StudyPlan, out_dir: str | Path,
          inputs: RunInputs = RunInputs()) -> str:
    """``markerplace study``: the settings checked, the study folder opened (with the run-size
    guard's first guess for all its evaluations), then :func:`run_study`; returns ``study.md``."""
    validate_evaluate_config(config)
    validate(plan_config)
    runs = 1 + len(plan.shifts) + len(plan.scales) + int(plan.detection_off)
    run_config = open_evaluation_folder("study", out_dir, scene_spec, plan_config, config, inputs,
                                        runs * len(config.study.ks), study_outputs(study_runs(config, plan)))
    return run_study(scene_spec, run_config, config, out_dir, plan, progress=inputs.progress)


def study_outputs(run_names) -> tuple[str, ...]:
    """What ``study`` writes into its folder with the evaluations ``run_names`` (``fnmatch``
    patterns, see :data:`markerplace.pipelines.evaluate.EVALUATE_OUTPUTS`), checked in an
    adopted folder before any work."""
    return ("study.csv", "study.md", "study_*.png", "runs/", "work/", "work/plan/", "work/cache/",
            *(f"work/plan/{p}" for p in STAGE_OUTPUTS),
            *(f"runs/{name}/{p}" for name in run_names for p in ("", *RUN_OUTPUTS)))


def run_study(scene_spec, plan_config, config, out_dir: str | Path, plan: StudyPlan = StudyPlan(),
              progress: bool = True) -> str:
    """Run the study (see the module docstring) and return ``study.md``'s text.

    Args:
        scene_spec: the scene.
        plan_config: planning settings (v, marker model, runtime, ...): the default OMP.
        config: :class:`~markerplace.testbed.config.EvaluateConfig` of the default run (tests,
            ks, thresholds, seed); its methods and test sets are set by the study.
        out_dir: study folder.
        plan: what the study varies.
        progress: progress bars.
    """
    out = Path(out_dir)
    work = out / "work"
    ks = sorted(set(config.study.ks))
    plan_config = replace(plan_config, placement=replace(plan_config.placement, k=max(ks)))
    runs = study_runs(config, plan)
    extra = _omp_variants(scene_spec, plan_config, work, plan, progress)
    for name, cfg in runs.items():
        log.info("study: evaluation %r", name)
        run_evaluation(scene_spec, plan_config, cfg, out / "runs" / name, progress=progress, work_dir=work,
                       extra_placements=extra if name == "default" else {})

    threshold = main_threshold(config.thresholds)
    label = threshold_label(threshold)
    hits = {name: {ts: _hits(out / "runs" / name, ts, threshold) for ts in cfg.test.sets}
            for name, cfg in runs.items()}
    default_w = hits["default"]["weighted"]
    groups = _groups(hits, plan, plan_config.placement.methods.omp.v)
    md = _markdown(groups, default_w, ks, label, config.seed)
    _write_csv(out / "study.csv", groups, ks)
    _figures(out, groups, ks, label)
    with atomic_path(out / "study.md") as tmp:
        tmp.write_text(md)
    return md


def _groups(hits: dict, plan: StudyPlan, v_default: float) -> list[tuple[str, list]]:
    """(group, [(row label, {(k): hits}, paired with the default?)])."""
    def series(h: dict, method: str) -> dict:
        out = {0: h[("none", 0, 0)]} if ("none", 0, 0) in h else {}
        out.update({k: v for (m, _, k), v in h.items() if m == method})
        return out

    dw, du = hits["default"]["weighted"], hits["default"]["uniform"]
    base = series(dw, "omp")
    groups = [("v", [(f"v = {v_default:g} (default)", base, True)] + [(f"v = {v:g}", {0: base[0], **series(dw, f"omp-v{v:g}")}, True)
                                                      for v in plan.vs])]
    if "no-detection" in hits:
        groups.append(("detection", [("tag detection on (default)", base, True),
                                     ("tag detection off", series(hits["no-detection"]["weighted"], "omp"), True)]))
    groups.append(("test data", [("low-scoring test data (default)", base, True),
                                 ("uniform test data", series(du, "omp"), False)]))
    if plan.similarity_off:
        groups.append(("similarity", [("similarity analysis (default)", base, True),
                                      ("similarity analysis off", {0: base[0], **series(dw, "omp-nosim")}, True)]))
    groups.append(("shift", [("no shift (default)", base, True)] + [
        (f"shifted +-{d:g} m", {0: base[0], **series(hits[f"shift-{d:g}"]["weighted"], "omp")}, True) for d in plan.shifts]))
    groups.append(("size", [("planned size (default)", base, True)] + [
        (f"printed x{s:g}", {0: base[0], **series(hits[f"size-{s:g}"]["weighted"], "omp")}, True) for s in plan.scales]))
    return groups


def _markdown(groups: list, default: dict, ks: list, label: str, seed: int) -> str:
    cols = [0] + ks
    lines = [f"# Parameter and sensitivity study: recall at {label} (%)", "",
             "Low-scoring (weighted) test images unless a row says otherwise; k = 0 is no markers. Under each "
             "row, its difference to the default on the same test images with a 95 % bootstrap interval "
             "(percentage points; bold: above zero, italic: below zero).", ""]
    for group, rows in groups:
        lines += [f"## {group}", "", "| Setting | " + " | ".join(f"k={k}" for k in cols) + " |",
                  "|---|" + "---|" * len(cols)]
        default_row = rows[0][1]
        for name, series, paired in rows:
            cells = [f"{100 * series[k].mean():.1f}" if k in series else "-" for k in cols]
            lines.append(f"| {name} | " + " | ".join(cells) + " |")
            if series is not default_row and paired:
                diffs = []
                for k in cols:
                    if k == 0 or k not in series or k not in default_row:
                        diffs.append("")
                        continue
                    d, lo, hi = bootstrap_difference(series[k].astype(float), default_row[k].astype(float)[None], seed=seed)
                    diffs.append(format_difference(dict(diff=d, low=lo, high=hi)))
                lines.append("| (minus default) | " + " | ".join(diffs) + " |")
        lines.append("")
    return "\n".join(lines)


def _write_csv(path: Path, groups: list, ks: list) -> None:
    with atomic_path(path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["group", "setting", "k", "recall", "n_tests"])
            for group, rows in groups:
                for name, series, _ in rows:
                    for k in [0] + ks:
                        if k in series:
                            w.writerow([group, name, k, f"{series[k].mean():.6f}", len(series[k])])


def _figures(out: Path, groups: list, ks: list, label: str) -> None:
    cols = [0] + ks
    for group, rows in groups:
        curves = {name: (np.array([100 * series[k].mean() if k in series else np.nan for k in cols]), None)
                  for name, series, _ in rows}
        recall_vs_k(out / f"study_{group.replace(' ', '_')}.png", cols, curves, f"{group}: recall at {label}")
