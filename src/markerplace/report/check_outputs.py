"""What ``markerplace check`` writes (:func:`markerplace.pipelines.check.run_check` runs the
comparison of :mod:`markerplace.plan.installed_vs_plan` on a plan folder).

Outputs (default folder ``PLAN_DIR/check/``), every position in the user's frame (z up,
metres, the file's coordinates):

* ``check.json``: summary (mean and 10th-percentile score planned vs installed, nats), one row
  per planned spot and per extra tag (status, shift in metres and degrees, score lost, what to
  do in words and as ``move``: right/up/out metres and turns as you face the spot's wall,
  :func:`markerplace.plan.installed_vs_plan.correction`), and the camera locations that lost most (storey,
  floor height, x, y, score drop);
* ``check.csv``: the per-tag rows as a table;
* ``check_map.png``: per camera location the score lost (mean over yaws; dark = more lost), the
  installed tags numbered by their spot's placement order as on ``placement.png`` (an extra tag
  by ``+`` and its id), the planned spots as ticks and each missing tag as a magenta cross with
  its number, one panel per storey;
* ``check.html``: the same in one page with a 3D view of the planned and installed tags
  (:mod:`markerplace.report.check_page`, written by the pipeline after these);
* ``tagmaps/``: the known-tag maps of the tags as installed (what the robot should load;
  :mod:`markerplace.report.tagmaps`).

After ``--photos`` also: per tag row the standard deviation of its recovered pose
(``position_std_m``, ``rotation_std_deg``), the number of photos that saw it and ``photo``, one
photo of it with the detection drawn (``photos/tag_<id>.png``, the bottom edge red); in
``check.json`` a ``photos`` object (photos, placed, without tags, not placed, the tags that
anchor each set of photos, the reprojection RMS) and ``guidance``: what to photograph next
(also printed); ``photo_cache/``: the detections per photo (re-used by the next run).
"""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path

import numpy as np

from markerplace.report.deliverables import write_known_tag_maps
from markerplace.report.figures import floor_map, per_location_mean
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import atomic_path, fixed, write_json
from markerplace.scene.worldframe import discretization_to_user, poses_to_user

log = logging.getLogger(__name__)

__all__ = ["write_check_outputs"]

WORST_LOCATIONS = 5
LOSS_TOLERANCE = 1e-6
"""Score drops below this (nats) are rounding: installed poses read back from placement.json
differ from the planned ones in the last digits."""


def _user(T, offset):
    return None if T is None else poses_to_user(T, offset)


def write_check_outputs(out: Path, result, offset: np.ndarray, folder, installed_user, photos: dict | None = None) -> str:
    run_folder.make_dirs(out)
    disc = discretization_to_user(result.disc, offset)
    sp, si = result.score_planned, result.score_installed
    drop = sp - si
    L = len(disc.locations)
    loc_drop = per_location_mean(drop, disc.location_index, L)
    loc_p, loc_i = per_location_mean(sp, disc.location_index, L), per_location_mean(si, disc.location_index, L)
    worst = [int(i) for i in np.argsort(-loc_drop, kind="stable")[:WORST_LOCATIONS] if loc_drop[i] > LOSS_TOLERANCE]
    rows = []
    for r in result.rows:
        P, Q = _user(r.planned, offset), _user(r.installed, offset)
        rows.append({"order": r.order or None, "planned_id": r.planned_id, "installed_id": r.installed_id,
                     "status": r.status, "shift_m": r.shift_m, "shift_deg": r.shift_deg,
                     "score_lost": r.score_lost, "score_lost_seen": r.score_lost_seen,
                     "planned_position": None if P is None else P[:3, 3].tolist(),
                     "installed_position": None if Q is None else Q[:3, 3].tolist(),
                     "installed_normal": None if Q is None else Q[:3, 2].tolist(),
                     "installed_world_from_marker": None if Q is None else Q.tolist(), "move": r.move, "note": r.note})
        if photos is not None:
            mz = r.measured or {}
            rows[-1].update({k: mz.get(k) for k in ("position_std_m", "rotation_std_deg", "photos", "photo")})
    storeys = np.asarray(disc.storeys, float)
    worst_rows = [{"storey": int(disc.location_storey[i]), "floor_z": float(storeys[disc.location_storey[i]]),
                   "x": float(disc.locations[i, 0]), "y": float(disc.locations[i, 1]),
                   "score_planned": float(loc_p[i]), "score_installed": float(loc_i[i]),
                   "score_lost": float(loc_drop[i])} for i in worst]
    summary = {"num_poses": int(len(sp)), "mean_score_planned": float(sp.mean()),
               "mean_score_installed": float(si.mean()), "mean_score_lost": float(drop.mean()),
               "p10_score_planned": float(np.percentile(sp, 10)), "p10_score_installed": float(np.percentile(si, 10)),
               "poses_losing_over_1_nat": int((drop > 1.0).sum()),
               "statuses": {s: sum(r["status"] == s for r in rows) for s in dict.fromkeys(r["status"] for r in rows)}}
    report = {"plan": str(folder.path), "summary": summary, "tags": rows, "worst_locations": worst_rows}
    if photos is not None:
        report.update({"photos": {k: v for k, v in photos.items() if k != "guidance"}, "guidance": photos["guidance"]})
    write_json(out / "check.json", report)
    buf = io.StringIO()
    w = csv.writer(buf)
    extra_cols = ["position_std_m", "rotation_std_deg", "photos", "photo"] if photos is not None else []
    w.writerow(["order", "planned_id", "installed_id", "status", "shift_m", "shift_deg", "move_right_m", "move_up_m",
                "move_out_m", "score_lost", "x", "y", "z", *extra_cols, "note"])
    for r in rows:
        pos = r["installed_position"] or r["planned_position"]
        mv = r["move"] or {}
        extra = [fixed(r["position_std_m"], 4), fixed(r["rotation_std_deg"], 2), _s(r["photos"]), _s(r["photo"])] \
            if photos is not None else []
        w.writerow([r["order"] or "", _s(r["planned_id"]), _s(r["installed_id"]), r["status"], fixed(r["shift_m"], 3),
                    fixed(r["shift_deg"], 1), *(fixed(mv.get(k), 3) for k in ("right_m", "up_m", "out_m")),
                    fixed(r["score_lost"], 4), *(fixed(v, 3) for v in pos), *extra, r["note"]])
    with atomic_path(out / "check.csv") as tmp:
        tmp.write_text(buf.getvalue())
    slots = {int(s): k for k, s in enumerate(disc.planned_storeys)}
    eye = storeys[disc.planned_storeys] + folder.config.discretize.height

    def panel(z):
        z = np.asarray(z, float).reshape(-1)
        return np.argmin(np.abs(z[:, None] - eye[None]), axis=1) if len(z) else np.zeros(0, int)

    inst = np.array([m.position for m in installed_user]).reshape(-1, 3)
    plan_xyz = np.array([m.position for m in folder.markers]).reshape(-1, 3)
    order_of = {r["installed_id"]: r["order"] for r in rows if r["installed_id"] is not None and r["order"]}
    missing = [r["order"] for r in rows if r["status"] == "missing"]
    miss_xyz = plan_xyz[[o - 1 for o in missing]].reshape(-1, 3)
    floor_map(out / "check_map.png", occupancy=disc.occupancy, origin=disc.grid_origin, resolution=disc.grid_resolution,
              locations=disc.locations, location_panel=np.array([slots[int(s)] for s in disc.location_storey]),
              panel_titles=[f"storey {s}: floor {storeys[s]:.2f} m" for s in disc.planned_storeys],
              values=loc_drop, cmap="gray_r", value_range=(0.0, max(float(loc_drop.max(initial=0.0)), 1e-6)),
              title="Score lost per camera location, installed vs planned (dark = more lost)\n"
                    "tags numbered by placement order as on placement.png; +id extra; magenta x missing",
              colorbar_label="mean score drop over yaws (nats)",
              markers_xy=inst[:, :2], markers_normal=np.array([m.normal[:2] for m in installed_user]).reshape(-1, 2),
              marker_labels=[str(order_of[int(m.tag_id)]) if int(m.tag_id) in order_of else f"+{m.tag_id}"
                             for m in installed_user], marker_panel=panel(inst[:, 2]),
              candidates_xy=plan_xyz[:, :2], candidate_panel=panel(plan_xyz[:, 2]),
              missing_xy=miss_xyz[:, :2], missing_labels=[f"{o} missing" for o in missing],
              missing_panel=panel(miss_xyz[:, 2]))
    write_known_tag_maps(out / "tagmaps", list(installed_user) + list(folder.existing), "installed", disc,
                         folder.scene, folder.scene_options.get("up"))
    return _text(out, summary, rows, worst_rows, photos)


def _s(v) -> str:
    return "" if v is None else str(v)


def _text(out: Path, summary: dict, rows: list, worst: list, photos: dict | None = None) -> str:
    lines = [f"{'spot':>4} {'planned':>7} {'found':>5}  {'status':<12} {'shift m':>7} {'deg':>5} {'lost':>7}  what to do"]
    for r in rows:
        lines.append(f"{_s(r['order']) or '-':>4} {_s(r['planned_id']) or '-':>7} {_s(r['installed_id']) or '-':>5}  "
                     f"{r['status']:<12} {fixed(r['shift_m'], 2, '-'):>7} {fixed(r['shift_deg'], 0, '-'):>5} "
                     f"{fixed(r['score_lost'], 3, '-'):>7}  {r['note']}")
    lines.append(f"score (mean -H over {summary['num_poses']} poses): planned {fixed(summary['mean_score_planned'], 3)}, "
                 f"installed {fixed(summary['mean_score_installed'], 3)}, lost {fixed(summary['mean_score_lost'], 3)} "
                 f"nats; 10th percentile {fixed(summary['p10_score_planned'], 3)} -> "
                 f"{fixed(summary['p10_score_installed'], 3)}")
    if worst:
        lines.append("camera locations that lost most:")
        lines += [f"  storey {w['storey']} (floor {fixed(w['floor_z'], 2)} m) at ({fixed(w['x'], 2)}, {fixed(w['y'], 2)}): "
                  f"{fixed(w['score_planned'], 2)} -> {fixed(w['score_installed'], 2)} (lost {fixed(w['score_lost'], 2)} "
                  "nats)" for w in worst]
    else:
        lines.append("no camera location lost anything")
    if photos is not None:
        lines.append(f"photos: {photos['photos']}, {photos['placed']} placed on the model by tags "
                     f"{'; '.join(', '.join(map(str, a)) for a in photos['anchors'])} (reprojection RMS "
                     f"{fixed(photos['reprojection_rms_px'], 2)} px)")
        lines += [f"next: {g}" for g in photos["guidance"]] or ["next: nothing: every planned tag was measured"]
    lines.append(f"wrote {out}/check.json, check.csv, check_map.png, check.html, tagmaps/ (the tags as installed)"
                 + (", photos/ (each tag's detection)" if photos is not None else ""))
    return "\n".join(lines)
