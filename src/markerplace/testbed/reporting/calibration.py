"""``evaluate --calibration`` outputs: how well the localizability score predicts whether a map
image localizes (leave-one-location-out, :mod:`markerplace.simulation.success_fit`), per marker
model.

* ``calibration.md``: per marker model, the samples (map images without tags, and with each
  placement's tags where they change the score), the success rate, the ROC AUC of the score
  (without tags, with tags, pooled) and the fitted logistic ``P(success | s)``; then the
  calibration table (observed success rate per score decile against the fitted probability).
* ``calibration.png``: observed success rate per score bin and the fitted curve, one line per
  model.
* ``map_outcomes.npz``: the pooled ``<model>_score``, ``<model>_success``, ``<model>_tagged``
  arrays.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplace.plan.score.success_model import calibration_curve, fit_success_model, roc_auc
from markerplace.runtime.atomic_io import atomic_path, write_npz
from markerplace.testbed.reporting.tables import md_text

__all__ = ["write_calibration_report"]


def write_calibration_report(out: Path, scene_name: str, outcomes: dict, bins: int = 10) -> dict:
    """Write the three outputs into ``out`` from :func:`markerplace.simulation.success_fit.score_outcomes`'s
    result; returns, per model, its AUCs and fitted model (as JSON-ready dicts)."""
    out = Path(out)
    summary, arrays, curves = {}, {}, {}

    lines = [f"# {md_text(scene_name)}: does the score predict localization? (map images, leave-one-location-out)", "",
             "Each map image is localized against the map without the images of its own camera location, "
             "without markers and with each evaluated placement's tags (re-rendered where in view). Samples: "
             "every map image without tags, plus with each placement the images whose score its tags change. "
             "Success: within 5 cm / 5 deg. AUC: probability that a random success scores higher than a random "
             "failure (0.5 = no information).", "",
             "| marker model | samples | with tags | success rate | AUC without tags | AUC with tags | AUC pooled | "
             "fitted P(success) |", "|---|---|---|---|---|---|---|---|"]
    for model, o in outcomes.items():
        s, y, tagged = np.asarray(o["score"], float), np.asarray(o["success"], bool), np.asarray(o["tagged"], bool)
        auc0, auc1, auc = roc_auc(s[~tagged], y[~tagged]), roc_auc(s[tagged], y[tagged]), roc_auc(s, y)
        fit = fit_success_model(s, y) if len(s) >= 2 else None
        curve = calibration_curve(s, y, bins=bins)
        curves[model] = (curve, fit)
        summary[model] = {"samples": int(len(s)), "with_tags": int(tagged.sum()), "success_rate": float(y.mean()) if len(y) else float("nan"),
                          "auc_without_tags": auc0, "auc_with_tags": auc1, "auc": auc,
                          "fit": None if fit is None else fit.to_json(), "placements": len(o["placements"])}
        fit_text = "-" if fit is None else f"sigmoid({fit.intercept:.3f} + {fit.slope:.4f} s)"
        lines.append(f"| {model} | {len(s)} | {int(tagged.sum())} | {100 * y.mean():.1f} % | {_f(auc0)} | {_f(auc1)} | "
                     f"{_f(auc)} | {fit_text} |")
        arrays.update({f"{model}_score": s, f"{model}_success": y, f"{model}_tagged": tagged})
    for model, (curve, fit) in curves.items():
        lines += ["", f"## {model}: calibration (score deciles, pooled samples)", "",
                  "| mean score | images | observed success | fitted |", "|---|---|---|---|"]
        for m, r, n in zip(curve["score_mean"], curve["success_rate"], curve["count"]):
            p = "-" if fit is None else f"{100 * float(fit.probability(np.array([m]))[0]):.1f} %"
            lines.append(f"| {m:.2f} | {int(n)} | {100 * r:.1f} % | {p} |")
    with atomic_path(out / "calibration.md") as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    write_npz(out / "map_outcomes.npz", **arrays)
    _figure(out / "calibration.png", scene_name, curves)
    return summary


def _f(v: float) -> str:
    return "-" if not np.isfinite(v) else f"{v:.3f}"


def _figure(path: Path, scene_name: str, curves: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for i, (model, (curve, fit)) in enumerate(curves.items()):
        color = f"C{i}"
        ax.plot(curve["score_mean"], 100 * np.asarray(curve["success_rate"]), "o", color=color,
                label=f"{model}: observed (score deciles)")
        if fit is not None and len(curve["score_mean"]):
            xs = np.linspace(min(curve["score_mean"]), max(curve["score_mean"]), 200)
            ax.plot(xs, 100 * fit.probability(xs), "-", color=color, label=f"{model}: fitted, AUC {fit.auc:.2f}")
    ax.set_xlabel("localizability score (-entropy, nats)")
    ax.set_ylabel("map images localized (%)")
    ax.set_ylim(0, 100)
    ax.set_title(f"{scene_name}: score vs localization (leave one location out)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
