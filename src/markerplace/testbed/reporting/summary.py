"""Metrics of an evaluation, computed from its stored predictions: recall tables, paired
differences, fixed/broken counts, recall vs k, per-query errors.

Predictions (the estimated pose of every test image, per placement and test set) are stored
apart from these metrics (:mod:`markerplace.simulation.prediction_store`), so the tables can be
recomputed with other thresholds without localizing again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplace.report.figures import recall_vs_k
from markerplace.runtime.atomic_io import atomic_path, write_json, write_npz
from markerplace.runtime.cache import config_dict
from markerplace.simulation import metrics
from markerplace.simulation.conditions import set_name, split_set
from markerplace.testbed.environment import environment
from markerplace.testbed.reporting.page import write_evaluation_report
from markerplace.testbed.reporting.paired import condition_markdown, paired_differences, paired_markdown, paired_table
from markerplace.testbed.reporting.predicted_tables import error_summary, log_predicted, predicted_markdown, predicted_rows, write_predicted_csv
from markerplace.testbed.reporting.tables import main_tables_markdown, recall_curves, tables_markdown, write_recall_csv

__all__ = ["write_outputs"]


def write_outputs(out: Path, scene_name: str, placements, predictions: dict, test_poses: dict,
                  base_score: np.ndarray, config, plan_config, scene=None, where: dict | None = None,
                  predicted: dict | None = None) -> tuple[list[dict], str]:
    """recall.csv, query_errors.npz, tables.md, recall_vs_k.png, config.json and report.html
    (:func:`markerplace.testbed.reporting.page.write_evaluation_report`) from predictions.

    Args:
        out: the run folder.
        scene_name: scene label of the tables.
        placements: the evaluated :class:`~markerplace.simulation.marker_sets.PlacementRun` list.
        predictions: ``(method, run, k, image set) -> (N, 4, 4)`` estimated ``world_from_cam``
            per test image (all NaN where localization failed); an image set is a test set
            under a query condition (:func:`~markerplace.simulation.conditions.set_name`): rows,
            tables and ``query_errors.npz``'s ``<image set>_*`` arrays are per image set.
        test_poses: test set -> :class:`~markerplace.simulation.pose_sampling.TestPoses` (truth).
        base_score: (M,) localizability score of each feasible pose without markers.
        where: the ``--where`` file as read (GeoJSON), recorded in config.json; None: none.
        config, plan_config: the evaluate and plan settings.
        scene: the scene (internal frame), to render report.html's gallery (None: no images).
        predicted: ``evaluate --predicted``: (test set, method, run, k) -> (predicted,
            predicted on the drawn poses) (:func:`markerplace.testbed.predicted_per_placement.predict_recalls`):
            adds ``predicted.csv``, a section of tables.md and report.html, log lines and the
            calibration error to the summary (:mod:`markerplace.testbed.reporting.predicted_tables`);
            None: none of it (every output as without the option).

    Returns:
        The recall rows and the markdown of the main table (first test set, main threshold).
    """
    results = {key: metrics.pose_errors_batch(est, test_poses[split_set(key.test_set)[0]].world_from_cam)
               for key, est in predictions.items()}
    labels = [metrics.threshold_label(t) for t in config.thresholds]
    rows = []
    arrays: dict[str, np.ndarray] = {}
    names = [set_name(ts, c) for ts in config.test.sets for c in config.test.conditions]
    for name in names:
        ts, cond = split_set(name)
        keys = list(dict.fromkeys((p.method, p.run, p.k) for p in placements if (p.method, p.run, p.k, name) in results))
        for method, run, k in keys:
            t_err, r_err = results[(method, run, k, name)]
            for label, (tm, rm) in zip(labels, config.thresholds):
                rows.append(dict(scene=scene_name, method=method, run=run, k=k, test_set=ts, condition=cond,
                                 threshold=label, recall=metrics.recall(t_err, r_err, tm, rm), n_tests=len(t_err)))
        arrays[f"{name}_method"] = np.array([k[0] for k in keys], dtype=str)
        arrays[f"{name}_run"] = np.array([k[1] for k in keys], dtype=np.int64)
        arrays[f"{name}_k"] = np.array([k[2] for k in keys], dtype=np.int64)
        arrays[f"{name}_t_err"] = np.array([results[k + (name,)][0] for k in keys]).reshape(len(keys), -1)
        arrays[f"{name}_r_err"] = np.array([results[k + (name,)][1] for k in keys]).reshape(len(keys), -1)
        arrays[f"{name}_world_from_cam"] = test_poses[ts].world_from_cam
        arrays[f"{name}_score"] = np.asarray(base_score)[test_poses[ts].source_index]
    write_recall_csv(out / "recall.csv", rows)
    write_npz(out / "query_errors.npz", **arrays)
    main = metrics.threshold_label(metrics.main_threshold(config.thresholds))
    ks = sorted(set(config.study.ks))
    md = tables_markdown(rows, ks, main, labels)
    summary = main_tables_markdown(rows, ks, main).strip()
    t_main, r_main = next(t for t in config.thresholds if metrics.threshold_label(t) == main)
    hits = {name: {(m, run, k): metrics.hit_mask(*res, t_main, r_main)
                   for (m, run, k, t), res in results.items() if t == name} for name in names}
    md += paired_markdown(hits, ks, main, seed=config.seed)
    md += condition_markdown(hits, main, seed=config.seed)
    ts0 = names[0]  # the first test set, clean unless --conditions leaves clean out
    diffs = paired_differences(hits[ts0], ks, seed=config.seed)
    if diffs:  # the printed summary carries the intervals too: a recall table alone can be noise
        summary += (f"\n\nPaired differences, `{ts0}` test set, {main} (method minus the baseline's run mean, "
                    f"recall points, 95 % bootstrap interval; bold: above zero, italic: below):\n\n"
                    + paired_table(diffs, ks))
    if predicted is not None:
        compared = predicted_rows(rows, predicted, main)
        write_predicted_csv(out / "predicted.csv", compared)
        log_predicted(compared)
        md += predicted_markdown(compared, main)
        summary += "\n\n" + (error_summary(compared) if compared else
                               "Predicted recall: no placement to compare (none made of candidates on clean test images)")
    with atomic_path(out / "tables.md") as tmp:
        tmp.write_text(md)
    curves = recall_curves(rows, scene_name, ts0, main, ks)
    if curves:
        recall_vs_k(out / "recall_vs_k.png", [0] + ks, curves, f"{scene_name}: recall at {main} ({ts0} test set)")

    write_json(out / "config.json", {"evaluate": config_dict(config), "plan": config_dict(plan_config),
                                     "environment": environment(), **({} if where is None else {"where": where})})

    write_evaluation_report(out, scene_name, placements, predictions, test_poses, config, plan_config.imaging.camera,
                            scene=scene)
    return rows, summary
