"""The "How many tags" section of a plan's ``report.html``: predicted recall against k.

Reads ``predicted_recall`` and ``score_bound`` of ``placement.json``
(:mod:`markerplace.plan.place.predicted_recall`) and draws the curve as an inline SVG (no figure file,
no matplotlib): the predicted share of camera poses that localize after the first 1, 2, ..., k
tags of the plan's own order, the knee, the recall target (``--target-recall``) and the upper
bound of any k candidates. A plan without a fitted model gets one paragraph saying how to get it.
"""

from __future__ import annotations

from markerplace.report.html import esc, table

__all__ = ["recall_section", "curve_svg"]

_W, _H, _L, _R, _T, _B = 560, 260, 48, 16, 14, 36  # size and margins, px


def curve_svg(recall: list[float], knee: int | None = None, target: float | None = None,
              bound: float | None = None) -> str:
    """An inline ``<svg>`` of predicted recall (shares in [0, 1]) at k = 0..K, the knee circled,
    the target as a dashed line and the bound (of any K tags) as a mark at K."""
    K = max(len(recall) - 1, 1)
    lo = min([*recall, *([target] if target is not None else [])]) if recall else 0.0
    lo = max(0.0, min(lo, 1.0) - 0.05)
    span = max(1.0 - lo, 1e-6)

    def x(k: float) -> float:
        return _L + (_W - _L - _R) * k / K

    def y(r: float) -> float:
        return _T + (_H - _T - _B) * (1.0 - (r - lo) / span)

    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{_W}" height="{_H}" role="img" '
             'aria-label="predicted recall against the number of tags" style="font:11px sans-serif">',
             f'<rect x="{_L}" y="{_T}" width="{_W - _L - _R}" height="{_H - _T - _B}" fill="none" stroke="#999"/>']
    for frac in (0.0, 0.25, 0.5, 0.75, 1.0):
        r = lo + frac * span
        parts.append(f'<text x="{_L - 4}" y="{y(r) + 4:.1f}" text-anchor="end">{100 * r:.{0 if span >= 0.2 else 1}f} '
                     '%</text>')
    step = max(1, round(K / 10))
    for k in range(0, K + 1, step):
        parts.append(f'<text x="{x(k):.1f}" y="{_H - _B + 14}" text-anchor="middle">{k}</text>')
    parts.append(f'<text x="{(_L + _W - _R) / 2:.0f}" y="{_H - 6}" text-anchor="middle">tags placed (the plan\'s '
                 'order)</text>')
    if target is not None:
        parts.append(f'<line x1="{_L}" x2="{_W - _R}" y1="{y(target):.1f}" y2="{y(target):.1f}" stroke="#2a7" '
                     f'stroke-dasharray="5,4"/><text x="{_W - _R - 4}" y="{y(target) - 4:.1f}" text-anchor="end" '
                     f'fill="#2a7">target {100 * target:.0f} %</text>')
    pts = " ".join(f"{x(k):.1f},{y(r):.1f}" for k, r in enumerate(recall))
    parts.append(f'<polyline points="{pts}" fill="none" stroke="#246" stroke-width="2"/>')
    parts += [f'<circle cx="{x(k):.1f}" cy="{y(r):.1f}" r="2.5" fill="#246"/>' for k, r in enumerate(recall)]
    if knee is not None and 0 <= knee < len(recall):
        parts.append(f'<circle cx="{x(knee):.1f}" cy="{y(recall[knee]):.1f}" r="7" fill="none" stroke="#c33" '
                     f'stroke-width="2"/><text x="{x(knee) + 9:.1f}" y="{y(recall[knee]) + 14:.1f}" fill="#c33">'
                     f'knee: {knee} tags</text>')
    if bound is not None and recall:
        parts.append(f'<line x1="{x(K) - 6:.1f}" x2="{x(K) + 6:.1f}" y1="{y(bound):.1f}" y2="{y(bound):.1f}" '
                     f'stroke="#c60" stroke-width="2"/><text x="{x(K) - 8:.1f}" y="{y(bound) - 4:.1f}" '
                     f'text-anchor="end" fill="#c60">bound {100 * bound:.1f} %</text>')
    return "".join(parts) + "</svg>"


def _target_words(t: dict) -> str:
    if t["reached"]:
        return (f"Target {100 * t['target']:.1f} % reached with <b>{t['tags']}</b> tags (the fewest of the plan's "
                "order that reach it).")
    return (f"Target {100 * t['target']:.1f} % <b>not reachable</b> {esc(t['limit'])}: the best predicted recall is "
            f"<b>{100 * t['best_recall']:.1f} %</b> with {t['best_tags']} tags; the plan places those.")


def recall_section(doc: dict) -> str:
    """HTML of the section from a placement.json ``doc`` (empty for a file without the keys)."""
    pr, sb = doc.get("predicted_recall"), doc.get("score_bound")
    if pr is None and sb is None:
        return ""
    out = ["<h2>How many tags: predicted recall</h2>"]
    if pr is not None and pr.get("available"):
        rec, kn, ub = pr["recall"], pr.get("knee"), pr["upper_bound"]
        t = pr.get("target")
        m = pr["model"]
        weighted = " (weighted by --where: where the cameras will be)" if "where" in doc.get("summary", {}) else ""
        out.append(f"<p>Predicted recall: the share of the feasible camera poses{weighted} predicted to localize, "
                   f"P(success) = sigmoid({m['intercept']:.3f} + {m['slope']:.3f} s) of each pose's score s under "
                   f"the {esc(pr['marker_model'])} marker model, fitted on {m['n']} map-image localizations "
                   "(never test images), after the first 1, 2, ... tags of this plan.</p>")
        out.append(curve_svg(rec, kn, None if t is None else t["target"], ub["recall"]))
        knee_words = (f"Knee at <b>{kn}</b> tags ({100 * rec[kn]:.1f} %)" if kn is not None else
                      "No tag adds a whole point: no knee")
        out.append(f"<p>{knee_words}: {esc(pr['knee_rule'])}. With all {len(rec) - 1} tags: "
                   f"{100 * rec[-1]:.1f} % (no tags: {100 * rec[0]:.1f} %).</p>")
        if t is not None:
            out.append(f"<p>{_target_words(t)}</p>")
        out.append(f"<p class=\"note\">Upper bound: no {ub['k']} candidates reach more than "
                   f"<b>{100 * ub['recall']:.1f} %</b> predicted recall; this plan has {100 * ub['plan_recall']:.1f} "
                   f"%. Why it holds: {esc(ub['what'])}.</p>")
        rows = [[k, round(100 * r, 2), "" if k == 0 else round(100 * (r - rec[k - 1]), 2)] for k, r in enumerate(rec)]
        out.append("<details><summary>the curve's values</summary>"
                   + table(["tags", "predicted recall (%)", "added (points)"], rows) + "</details>")
    elif pr is not None:
        out.append(f"<p class=\"note\">No curve: {esc(pr.get('how', ''))}.</p>")
    if sb is not None:
        gain, best = sb["mean_score_plan"] - sb["mean_score_existing"], sb["mean_score_upper_bound"] - sb[
            "mean_score_existing"]
        share = f" (at least {100 * gain / best:.0f} % of the best possible gain)" if best > 1e-12 else ""
        out.append(f"<p class=\"note\">Mean localizability score: {sb['mean_score_plan']:.2f} nats with the plan; no "
                   f"{sb['k']} candidates reach more than {sb['mean_score_upper_bound']:.2f}{share}. The score sum is "
                   "monotone and submodular, so this bound (per pose: the plan's score plus its k largest gains, "
                   "capped at every candidate's) holds.</p>")
    return "".join(out)
