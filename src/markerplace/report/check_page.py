"""``check.html``: what ``markerplace check`` found, as one self-contained page.

The page holds the summary, ``check_map.png``, the 3D view of :mod:`markerplace.report.view3d`
(the planned tags in orange, the tags as found or installed in blue, and the camera path of a
photo walk when there is one) and one card per planned spot and per extra tag (status, shift,
what to do as you face the wall). Clicking a tag in the 3D view selects its card: a planned tag's
card is ``tag<order>``, a found tag's the card of the spot it was found at (``extra<id>`` for an
extra tag). :func:`markerplace.pipelines.check.run_check` writes it next to ``check.json``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.report.html import esc, img, png_file_uri, table, write_page
from markerplace.report.view3d import scene_view_html

log = logging.getLogger(__name__)

__all__ = ["write_check_page", "card_id"]


def card_id(row) -> str:
    """The page id of a :class:`~markerplace.plan.installed_vs_plan.TagRow`'s card."""
    return f"tag{row.order}" if row.order else f"extra{row.installed_id}"


def _num(v, digits: int, unit: str = "") -> str:
    return "-" if v is None else f"{v:.{digits}f}{unit}"


def _card(row) -> str:
    head = (f"#{row.order}: planned id {row.planned_id}" if row.order else f"extra tag id {row.installed_id}")
    facts = [["status", row.status], ["found id", "-" if row.installed_id is None else row.installed_id],
             ["shift", f"{_num(row.shift_m, 3, ' m')}, {_num(row.shift_deg, 1, ' deg')}"],
             ["score lost (nats, mean over all poses)", f"{row.score_lost:.4f}"]]
    if row.move:
        m = row.move
        facts.append(["move (as you face the wall)", f"right {m['right_m']:+.3f} m, up {m['up_m']:+.3f} m, out "
                      f"{m['out_m']:+.3f} m, turn clockwise {m['turn_cw_deg']:+.1f} deg"])
    note = f"<p><b>{esc(row.note)}</b></p>" if row.note else ""
    return f'<div class="tag" id="{card_id(row)}"><h3>{esc(head)}</h3>{note}{table(None, facts)}</div>'


def write_check_page(out: str | Path, scene, result, planned: Sequence, found: Sequence,
                     camera_path: np.ndarray | None = None, title: str | None = None) -> Path:
    """Write ``out/check.html`` and return its path.

    Args:
        out: the check's output folder (holding ``check_map.png``).
        scene: the plan's scene (internal frame).
        result: the :class:`~markerplace.plan.installed_vs_plan.CheckResult`.
        planned: the planned :class:`~markerplace.markers.Marker` list (internal frame, placement order).
        found: the tags as installed or found (internal frame).
        camera_path: (P, 3) camera positions of a photo walk (internal frame, metres), or None.
        title: the page title (default ``Check: <scene name>``).
    """
    out = Path(out)
    rows = list(result.rows)
    where = {int(r.installed_id): card_id(r) for r in rows if r.installed_id is not None}
    view = scene_view_html(scene, planned, found, camera_path,
                           planned_labels=[str(i + 1) for i in range(len(planned))],
                           planned_cards=[f"tag{i + 1}" for i in range(len(planned))],
                           found_labels=[f"id {m.tag_id}" for m in found],
                           found_cards=[where.get(int(m.tag_id)) for m in found], view_id="mp-view3d-check")
    counts = {}
    for r in rows:
        counts[r.status] = counts.get(r.status, 0) + 1
    drop = np.asarray(result.score_planned, float) - np.asarray(result.score_installed, float)
    title = title or f"Check: {getattr(scene, 'name', '?')}"
    summary = (f"<p>{len(planned)} planned tags, {len(found)} found: "
               + esc(", ".join(f"{n} {s}" for s, n in counts.items()))
               + f". Mean score lost over {len(drop)} camera poses: {drop.mean() if len(drop) else 0.0:.3f} nats. "
               "check.json and check.csv hold the same rows; tagmaps/ the tags as installed.</p>")
    body = [f"<h1>{esc(title)}</h1>", summary]
    if (out / "check_map.png").is_file():
        body.append(img(png_file_uri(out / "check_map.png"), "check_map.png",
                        "Score lost per camera location; tags numbered by placement order, magenta crosses missing."))
    body += ["<h2>In 3D</h2>", view, "<h2>Tags</h2>", *(_card(r) for r in rows)]
    path = write_page(out / "check.html", title, "\n".join(body))
    log.info("check.html: %d rows", len(rows))
    return path
