"""Files a plan run leaves for its user: placement.json/.csv, tags/*.svg, scores.npz, figures, config.json."""

from __future__ import annotations

import csv
import io
import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.plan.score.localizability import entropy
from markerplace.report.deliverables import write_deliverables
from markerplace.report.figures import floor_map, per_location_mean
from markerplace.report.instructions import CHECKLIST_COLUMNS, checklist_row, install_instructions, install_to_frame
from markerplace.report.output_files import PlanOutputs, write_output_files
from markerplace.report.printable import write_tag_sheets
from markerplace.report.sheets import sheet_plan
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import atomic_path, write_json, write_npz
from markerplace.runtime.cache import config_dict
from markerplace.scene.worldframe import discretization_to_user, markers_to_user

log = logging.getLogger(__name__)


def placement_records(placement, method: str, disc=None) -> list[dict]:
    """One JSON-ready dict per placed marker, in placement order.

    With the run's :class:`~markerplace.plan.discretize.artifact.Discretization` ``disc``, each
    record says what the tag is on: ``surface`` (``"wall"``, ``"column"``, or for a category
    ``--allow`` allowed e.g. ``"bookshelf front"``) and ``surface_part`` (the mesh part's name).
    """
    rows = []
    for i, (m, c, g) in enumerate(zip(placement.markers, placement.candidates, placement.gains)):
        n = m.normal
        on = {}
        if disc is not None:
            on = {"surface": str(disc.candidate_surface[int(c)]), "surface_part": str(disc.candidate_part[int(c)])}
        rows.append({
            "order": i + 1,
            "tag_id": int(m.tag_id),
            "family": m.family,
            "size": float(m.size),
            "position": [round(float(v), 4) for v in m.position],
            "normal": [round(float(v), 4) for v in n],
            "yaw_deg": round(float(np.degrees(np.arctan2(n[1], n[0]))), 2),
            "world_from_marker": np.round(m.world_from_marker, 6).tolist(),
            "gain": None if not np.isfinite(g) else float(g),
            "candidate_index": int(c),
            "method": method,
            **on,
        })
    return rows


def plan_instructions(scene, placement, disc, height: float, surfaces: Sequence | None = None) -> list[dict]:
    """The ``install`` object of every placed marker (:mod:`markerplace.report.instructions`), in the
    frame of ``scene`` (the internal frame: ``placement`` and ``disc`` too).

    The floor under a tag is the plan's: a candidate's centre stands ``height`` (``--height``)
    above the storey's floor map in front of its wall (furniture tops are not floor there), so
    the floor is the tag's z minus ``height``; its storey is its candidate's.
    A frames plan (``plan --frames``) hangs tags at any height: the floor is its storey's.
    """
    t0 = time.perf_counter()
    storeys = [int(disc.candidate_storey[int(c)]) for c in placement.candidates]
    floors = [float(m.position[2]) - float(height) for m in placement.markers]
    if disc.summary.get("frames"):  # plan --frames: tags at any height; the floor is the storey's (plan/frames/layout)
        floors = [float(disc.storeys[s]) for s in storeys]
    out = install_instructions(scene, placement.markers, storeys, [float(disc.storeys[s]) for s in storeys], floors,
                               surfaces)
    log.info("instructions: %d tags measured on the model (walls, corners, door edges) in %.1f s", len(out),
             time.perf_counter() - t0)
    return out


def write_placement(out_dir: Path, records: Sequence[dict], scene_source: str, method: str, extra: dict) -> None:
    """placement.json (markers + summary), placement.csv (the installer's checklist, one row per
    marker: :data:`~markerplace.report.instructions.CHECKLIST_COLUMNS`) and tags/ (one print-ready
    SVG per marker)."""
    write_json(out_dir / "placement.json", {"scene": scene_source, "method": method, **extra, "markers": list(records)})
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(CHECKLIST_COLUMNS)
    for r in records:
        writer.writerow(checklist_row(r))
    with atomic_path(out_dir / "placement.csv") as tmp:
        tmp.write_text(buf.getvalue())
    write_tag_sheets(out_dir / "tags", records)


def write_plan_outputs(out_dir: str | Path, *, data, placement, first_gain: np.ndarray, config, method: str,
                       scene_source: str, scene, existing: Sequence = (), world_offset=None, paper: str = "a4",
                       scene_options: dict | None = None, exclusion=None, predicted: dict | None = None,
                       where=None) -> dict:
    """Write every output of a plan run and return a summary dict (also in placement.json).

    ``scene`` (internal frame) is measured for the installer's instructions (each marker's
    ``install`` object, :func:`plan_instructions`), whose ``pages`` say where it is in tags.pdf.

    ``paper`` sets tags.pdf's paper (:mod:`markerplace.report.pdf`); ``scene_options`` (``up``,
    ``unit_scale``, ``seed`` of the scene argument) go into config.json with the existing markers,
    so ``export`` and ``check`` can rebuild the run, and set the tag maps' file axes
    (:mod:`markerplace.report.deliverables`); ``exclusion`` (``--exclude``,
    :class:`~markerplace.plan.discretize.exclusion.Exclusion`, user frame) goes there too.
    ``predicted`` (``predicted_recall`` and ``score_bound``,
    :mod:`markerplace.plan.place.predicted_recall`) goes into placement.json as it is. ``where``
    (``--where``, :class:`~markerplace.plan.where.Where`) goes into config.json as read; with
    ``data.pose_weight`` the summary gets a ``where`` object (weighted mean scores, the poses
    that weigh) and ``where.png`` maps the mean weight per location.

    ``data``, ``placement`` and ``existing`` are in the scene's internal frame; every position
    written is moved into the user's frame by ``world_offset`` ((3,) metres, see
    :mod:`markerplace.scene.worldframe`; None = not shifted).
    """
    out_dir = Path(out_dir)
    install = plan_instructions(scene, placement, data.disc, config.discretize.height,
                                [r.get("surface") for r in placement_records(placement, method, data.disc)])
    if world_offset is not None and np.any(world_offset):
        data = replace(data, disc=discretization_to_user(data.disc, world_offset))
        placement = replace(placement, markers=markers_to_user(placement.markers, world_offset))
        existing = markers_to_user(existing, world_offset)
    disc = data.disc
    score_after = -entropy(placement.info_after)
    L = len(disc.locations)
    loc_before = per_location_mean(data.base_score, disc.location_index, L)
    loc_after = per_location_mean(score_after, disc.location_index, L)
    loc_gain = per_location_mean(first_gain, disc.location_index, L)
    summary = {
        "num_poses": int(len(disc.world_from_cam)),
        "num_locations": int(L),
        "num_candidates": int(data.num_candidates),
        "q": None if not np.isfinite(placement.q) else float(placement.q),
        "mean_score_before": float(data.base_score.mean()),
        "mean_score_after": float(score_after.mean()),
        "p10_score_before": float(np.percentile(data.base_score, 10)),
        "p10_score_after": float(np.percentile(score_after, 10)),
        "storeys": [float(z) for z in disc.storeys],
        "planned_storeys": [int(s) for s in disc.planned_storeys],
        "discretization": disc.summary,
    }
    w = data.pose_weight
    if w is not None:
        summary["where"] = {"weighted_poses": int(np.count_nonzero(w > 0)),
                            "mean_score_before": float(np.sum(w * data.base_score) / np.sum(w)),
                            "mean_score_after": float(np.sum(w * score_after) / np.sum(w))}
    records = placement_records(placement, method, disc)
    for r, inst in zip(records, install):
        r["install"] = install_to_frame(inst, world_offset)
    for r, sh in zip(records, sheet_plan(records, paper)):  # where each tag is in tags.pdf
        r["install"].update(pages=sh.pages, tiles=list(sh.tiles))
    write_placement(out_dir, records, scene_source, method, {"summary": summary, **(predicted or {})})

    write_deliverables(out_dir, records, placement.markers, existing, disc, scene_source, scene_options, paper)
    write_output_files(out_dir, PlanOutputs(scene_source, method, records, placement.markers, existing, summary))
    write_npz(out_dir / "scores.npz", world_from_cam=disc.world_from_cam, location_index=disc.location_index,
              locations=disc.locations, score_before=data.base_score, score_after=score_after,
              first_pick_gain=first_gain, candidates=placement.candidates, gains=placement.gains,
              **({} if w is None else {"pose_weight": w}))
    write_json(out_dir / "config.json", {"scene": scene_source, **config_dict(config), "scene_options": scene_options or {},
                                         "existing_markers": [m.to_json() for m in existing],
                                         "exclude": None if exclusion is None else exclusion.to_json(),
                                         **({} if where is None else {"where": where.doc})})

    slots = {int(s): k for k, s in enumerate(disc.planned_storeys)}
    eye = disc.storeys[disc.planned_storeys] + config.discretize.height

    def panel(z: np.ndarray) -> np.ndarray:
        """Panel (planned storey) of points at heights z: the nearest eye-level plane."""
        z = np.asarray(z, float).reshape(-1)
        return np.argmin(np.abs(z[:, None] - eye[None]), axis=1) if len(z) else np.zeros(0, int)

    grid = dict(occupancy=disc.occupancy, origin=disc.grid_origin, resolution=disc.grid_resolution,
                locations=disc.locations, location_panel=np.array([slots[int(s)] for s in disc.location_storey]),
                panel_titles=[f"storey {s}: floor {disc.storeys[s]:.2f} m" for s in disc.planned_storeys])
    floor_map(out_dir / "scores.png", **grid, values=loc_before, cmap="gray",
              title="Localizability score, no markers (dark = low)", colorbar_label="mean score -H over yaws",
              candidates_xy=disc.candidate_position[:, :2],
              candidate_panel=np.array([slots[int(s)] for s in disc.candidate_storey]))
    if len(placement.markers):
        first = placement.markers[0]
        floor_map(out_dir / "gain_first.png", **grid, values=loc_gain, cmap="gray_r",
                  title="Information gain of the first marker (dark = high)", colorbar_label="mean gain (nats)",
                  markers_xy=first.position[None, :2], markers_normal=first.normal[None, :2], marker_labels=["1"],
                  marker_panel=panel(first.position[2]))
    if w is None:
        run_folder.remove(out_dir / "where.png")  # a previous run's, with --where
    else:
        floor_map(out_dir / "where.png", **grid, values=per_location_mean(w, disc.location_index, L), cmap="gray_r",
                  title="Where the cameras will be (--where): pose weight (dark = high)",
                  colorbar_label="mean weight over yaws (1 = average pose)")
    markers = list(placement.markers) + list(existing)
    pos = np.array([m.position for m in markers]).reshape(-1, 3)
    nrm = np.array([m.normal[:2] for m in markers]).reshape(-1, 2)
    labels = [str(i + 1) for i in range(len(placement.markers))] + ["e"] * len(existing)
    floor_map(out_dir / "placement.png", **grid, values=loc_after, cmap="gray",
              title=f"{method}: {len(placement.markers)} markers (numbers = order), score after placement",
              colorbar_label="mean score -H over yaws",
              markers_xy=pos[:, :2], markers_normal=nrm, marker_labels=labels, marker_panel=panel(pos[:, 2]))
    return summary
