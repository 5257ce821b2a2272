"""Installed is not planned: compare the tags a person measured on the walls with the plan.

The plan folder's cached stages are reused (:func:`~markerplace.pipelines.plan.prepare` with the
run's configuration and ``--existing`` markers: nothing is rendered again when they match). The
installed tags' coverages are computed by the same code as ``--existing`` markers and
candidates: geometric visibility (:func:`~markerplace.plan.score.stage.geometric_visibility`),
occlusion from a marker-free depth render at each pose that could see one
(:meth:`~markerplace.imaging.engine.ImagingEngine.unoccluded`), information from the run's
marker model (:func:`~markerplace.plan.score.stage.build_coverages`). A tag installed exactly as
planned therefore loses nothing.

Pairing planned spots with installed tags (all in the internal frame, metres):

1. a planned tag whose id is installed within ``radius`` of its spot is that tag (``as planned``
   when within ``tolerance_m`` and ``tolerance_deg``, else ``shifted``);
2. the remaining spots and installed tags are paired by least total distance (Hungarian) within
   ``radius`` and with normals less than 90 degrees apart: a different id at the spot is a
   ``wrong id`` (``swapped`` when the two ids sit on each other's spots);
3. spots left are ``missing``; installed tags left are ``extra``; with ``unmeasured`` (a photo
   check, :mod:`markerplace.plan.photo_check`), a spot left whose tag could not be measured is
   ``not measured``: scored as planned (unknown is not lost) and without a shift or a move.

``shift_deg`` is the angle of the rotation from the planned to the installed tag (a tag turned
on its wall counts; tags measured by position and normal hang upright, so for them it is the
angle between the normals).

What to do is said in the installer's terms (:func:`directions`): as you face the planned spot's
wall, how far to move the tag left or right, up or down, into or out from the wall, and how to
turn it.

Scores are the localizability -H (nats) per pose: with the existing and planned markers vs the
existing and installed ones. Per planned spot, ``score_lost`` is the drop of the mean score over
all poses when only that spot's tag is replaced by what was installed there (removed when
missing); the per-spot losses need not add up to the total (markers interact).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.imaging.engine import EngineSpec, imaging_job
from markerplace.imaging.visibility import marker_points
from markerplace.localization.tag_anchor import rotation_deg
from markerplace.plan.place.greedy import apply_coverages
from markerplace.plan.score.localizability import entropy
from markerplace.plan.score.stage import build_coverages, geometric_visibility
from markerplace.plan.types import MarkerCoverage

log = logging.getLogger(__name__)

__all__ = ["CheckResult", "TagRow", "compare", "installed_coverages", "pair_markers", "directions", "correction"]

MATCH_RADIUS_M = 1.5
TOLERANCE_M = 0.05
TOLERANCE_DEG = 5.0
SAY_M = 0.005
"""Moves shorter than this (metres) are left out of the words (they print as 0.00 m)."""
SAY_DEG = 0.5
"""Turns smaller than this (degrees) are left out of the words."""


@dataclass
class TagRow:
    """One planned spot (``order`` >= 1) or one extra installed tag (``order`` = 0).

    Attributes:
        order, planned_id: placement order and tag id of the spot (None for extras).
        installed_id: id of the tag found at the spot (None when missing).
        status: ``as planned``, ``shifted``, ``wrong id``, ``swapped``, ``missing``, ``not measured``
            or ``extra``.
        shift_m, shift_deg: distance between the planned and installed centres (metres) and the
            angle of the rotation between them (degrees); None when missing.
        score_lost: mean score drop over all poses from this spot alone (nats; negative = gain;
            None when not measured).
        score_lost_seen: the same over the poses that see the planned tag.
        planned, installed: (4, 4) ``world_from_marker`` (internal frame) or None.
        note: what to do, in words.
        move: how to bring the installed tag onto its spot, as you face the spot's wall
            (:func:`correction`), or None when missing or extra.
        measured: how a photo check measured the installed tag (``position_std_m``,
            ``rotation_std_deg``, ``photos``, ``photo``), else None.
    """

    order: int
    planned_id: int | None
    installed_id: int | None
    status: str
    shift_m: float | None
    shift_deg: float | None
    score_lost: float = 0.0
    score_lost_seen: float = 0.0
    planned: np.ndarray | None = None
    installed: np.ndarray | None = None
    note: str = ""
    move: dict | None = None
    measured: dict | None = None


@dataclass
class CheckResult:
    """Everything ``check`` reports (internal frame; the writer moves positions to the user's).

    Attributes:
        rows: per planned spot in placement order, then extras.
        score_planned, score_installed: (N,) per-pose score with the planned / installed tags.
        base_score: (N,) from the scene's features alone (no marker at all).
        disc: the plan's discretization (poses, locations, storeys).
    """

    rows: list
    score_planned: np.ndarray
    score_installed: np.ndarray
    base_score: np.ndarray
    disc: object
    extra: dict = field(default_factory=dict)


def correction(planned: np.ndarray, installed: np.ndarray) -> dict:
    """How to bring a tag hung at ``installed`` onto ``planned`` (both (4, 4) ``world_from_marker``),
    in the planned tag's frame, i.e. as a person facing its wall sees it (the marker frame: x to
    the right, y up, z out of the wall towards the person).

    Returns:
        ``right_m``, ``up_m``, ``out_m``: the move of the tag centre, metres (negative = left, down,
        into the wall); ``turn_cw_deg``: how far to turn it clockwise on the wall as you face it
        (negative = counter-clockwise; 180 = upside down); ``faces_right_deg`` / ``faces_up_deg``:
        how far the installed tag faces to the person's right / up from the planned direction
        (a tag not flat on the planned wall).
    """
    R = np.asarray(planned, float)[:3, :3]
    d = R.T @ (np.asarray(planned, float)[:3, 3] - np.asarray(installed, float)[:3, 3])
    rel = R.T @ np.asarray(installed, float)[:3, :3]  # installed axes in the planned frame
    n = rel[:, 2]
    roll = float(np.degrees(np.arctan2(rel[1, 0], rel[0, 0])))  # its x axis, counter-clockwise as seen facing the wall
    return {"right_m": float(d[0]), "up_m": float(d[1]), "out_m": float(d[2]), "turn_cw_deg": roll,
            "faces_right_deg": float(np.degrees(np.arctan2(n[0], n[2]))),
            "faces_up_deg": float(np.degrees(np.arcsin(np.clip(n[1], -1.0, 1.0))))}


def directions(move: dict) -> str:
    """What to do, in words, from a :func:`correction`: e.g. ``"move it 0.12 m left and 0.05 m up
    (as you face the wall)"``; parts under :data:`SAY_M` / :data:`SAY_DEG` are left out; ``""``
    when nothing is left."""
    parts = []
    for key, pos, neg in (("right_m", "right", "left"), ("up_m", "up", "down"),
                          ("out_m", "out from the wall", "into the wall")):
        v = move[key]
        if abs(v) >= SAY_M:
            parts.append(f"{abs(v):.2f} m {pos if v > 0 else neg}")
    text = f"move it {' and '.join(parts)}" if parts else ""
    turn = (move["turn_cw_deg"] + 180.0) % 360.0 - 180.0
    if abs(abs(turn) - 180.0) < SAY_DEG:
        words = "turn it 180 deg: it hangs upside down (the caption edge goes at the bottom)"
    elif abs(turn) >= SAY_DEG:
        words = f"turn it {abs(turn):.0f} deg {'clockwise' if turn > 0 else 'counter-clockwise'}"
    else:
        words = ""
    faces = [f"{abs(v):.0f} deg to your {a if v > 0 else b}" for v, a, b in
             ((move["faces_right_deg"], "right", "left"), (move["faces_up_deg"], "up", "down")) if abs(v) >= SAY_DEG]
    text = ", ".join(t for t in (text, words) if t)
    if faces:
        text += ("; " if text else "") + f"it faces {' and '.join(faces)}: hang it flat on the wall"
    return f"{text} (as you face the wall)" if text else ""


def pair_markers(planned: Sequence, installed: Sequence, radius: float = MATCH_RADIUS_M) -> dict[int, int]:
    """{planned index: installed index} by the rules of the module docstring (steps 1-2)."""
    from scipy.optimize import linear_sum_assignment

    P = np.array([m.position for m in planned]).reshape(-1, 3)
    Q = np.array([m.position for m in installed]).reshape(-1, 3)
    pairs: dict[int, int] = {}
    by_id = {int(m.tag_id): j for j, m in enumerate(installed)}
    for i, m in enumerate(planned):
        j = by_id.get(int(m.tag_id))
        if j is not None and np.linalg.norm(P[i] - Q[j]) <= radius and j not in pairs.values():
            pairs[i] = j
    rest_p = [i for i in range(len(planned)) if i not in pairs]
    rest_q = [j for j in range(len(installed)) if j not in pairs.values()]
    if rest_p and rest_q:
        D = np.linalg.norm(P[rest_p][:, None] - Q[rest_q][None], axis=2)
        facing = np.array([[np.dot(planned[i].normal, installed[j].normal) > 0 for j in rest_q] for i in rest_p])
        cost = np.where((D <= radius) & facing, D, 1e6)
        for a, b in zip(*linear_sum_assignment(cost)):
            if cost[a, b] < 1e6:
                pairs[rest_p[a]] = rest_q[b]
    return pairs


def _occlusion_task(engine, item) -> np.ndarray:
    world_from_cam, mask = item
    return engine.unoccluded(engine.render(world_from_cam, rgb=False), "installed", mask)


def installed_coverages(scene_spec, world_from_cam: np.ndarray, markers: Sequence, config, executor) -> list:
    """One :class:`MarkerCoverage` per marker (internal frame) over the plan's poses, computed as
    ``prepare`` computes them for ``--existing`` markers (see module docstring); renders depth
    only at the poses that could see one of them."""
    if not markers:
        return []
    T = np.array([m.world_from_marker for m in markers], dtype=float)
    sizes = np.array([m.size for m in markers], dtype=float)
    in_view = geometric_visibility(world_from_cam, T, config.imaging.camera, config.noise.max_range)
    todo = np.flatnonzero(in_view.any(axis=1))
    unoccluded = np.zeros_like(in_view)
    job = imaging_job(EngineSpec(scene_spec, config.imaging, {"installed": marker_points(T, sizes)}))
    items = [(world_from_cam[i], in_view[i]) for i in todo]
    for j, visible in executor.map(_occlusion_task, items, job):
        unoccluded[todo[j]] = visible
    return build_coverages(world_from_cam, T, list(sizes), in_view & unoccluded, config.placement.marker_model, config.noise,
                           config.imaging.camera.K)


def _scores_with(info: np.ndarray, score: np.ndarray, remove: Sequence[MarkerCoverage],
                 add: Sequence[MarkerCoverage]) -> np.ndarray:
    """(N,) scores after removing and adding coverages to ``info`` (only touched poses recomputed)."""
    touched = [c.pose_idx for c in (*remove, *add)]
    idx = np.unique(np.concatenate(touched)) if touched else np.zeros(0, np.int64)
    out = score.copy()
    if len(idx):
        sub = info[idx].copy()
        for c in remove:
            np.subtract.at(sub, np.searchsorted(idx, c.pose_idx), c.info)
        for c in add:
            np.add.at(sub, np.searchsorted(idx, c.pose_idx), c.info)
        out[idx] = -entropy(sub)
    return out


def _status(planned, inst, tol_m: float, tol_deg: float) -> tuple[str, float, float]:
    shift = float(np.linalg.norm(inst.position - planned.position))
    angle = rotation_deg(planned.world_from_marker, inst.world_from_marker)
    if int(inst.tag_id) != int(planned.tag_id):
        return "wrong id", shift, angle
    return ("as planned" if shift <= tol_m and angle <= tol_deg else "shifted"), shift, angle


def compare(data, planned: Sequence, planned_candidates: Sequence[int], installed: Sequence,
            installed_covs: Sequence[MarkerCoverage], *, radius: float = MATCH_RADIUS_M,
            tol_m: float = TOLERANCE_M, tol_deg: float = TOLERANCE_DEG, unmeasured=()) -> CheckResult:
    """Pair, score and explain (see module docstring).

    Args:
        data: :class:`~markerplace.plan.types.PlanData` of the plan (its existing markers' coverages
            after the candidates).
        planned: placed markers (internal frame), placement order.
        planned_candidates: their candidate indices into ``data.coverages``.
        installed: measured markers (internal frame); ``installed_covs`` their coverages.
        unmeasured: planned tag ids a photo check could not measure (module docstring, step 3).
    """
    if len(planned_candidates) != len(planned):
        raise UserError("placement.json lists markers without a candidate index: re-run `markerplace plan`")
    existing_covs = list(data.coverages[data.num_candidates:])
    planned_covs = [data.coverages[int(c)] for c in planned_candidates]
    info_planned = apply_coverages(data.base_info, existing_covs + planned_covs)
    score_planned = -entropy(info_planned)
    pairs = pair_markers(planned, installed, radius)
    unknown = [i for i, m in enumerate(planned) if int(m.tag_id) in set(unmeasured) and i not in pairs]
    info_installed = apply_coverages(data.base_info, existing_covs + list(installed_covs) +
                                     [planned_covs[i] for i in unknown])
    score_installed = -entropy(info_installed)
    spot_of_id = {int(planned[i].tag_id): int(installed[j].tag_id) for i, j in pairs.items()}
    rows = []
    mean_planned = float(score_planned.mean())
    for i, m in enumerate(planned):
        j = pairs.get(i)
        add = [] if j is None else [installed_covs[j]]
        s = _scores_with(info_planned, score_planned, [planned_covs[i]], add)
        seen = planned_covs[i].pose_idx
        lost_seen = float((score_planned[seen] - s[seen]).mean()) if len(seen) else 0.0
        move = None
        if i in unknown:
            rows.append(TagRow(i + 1, int(m.tag_id), None, "not measured", None, None, None, None,
                               np.asarray(m.world_from_marker, float), None,
                               f"tag {m.tag_id} not measured: see the guidance below; it is scored as planned"))
            continue
        if j is None:
            status, shift, angle, iid = "missing", None, None, None
            note = f"tag {m.tag_id} not found within {radius:g} m of its spot #{i + 1}: hang it there"
        else:
            status, shift, angle = _status(m, installed[j], tol_m, tol_deg)
            iid = int(installed[j].tag_id)
            move = correction(m.world_from_marker, installed[j].world_from_marker)
            note = {"as planned": "ok", "shifted": directions(move) or "move it onto its spot"}.get(status, "")
            if status == "wrong id":
                if spot_of_id.get(iid) == int(m.tag_id):
                    status = "swapped"
                    note = f"tags {m.tag_id} and {iid} are swapped: exchange the prints or use the installed tag maps"
                else:
                    note = f"tag {iid} hangs here instead of {m.tag_id}: replace it or use the installed tag maps"
        rows.append(TagRow(i + 1, int(m.tag_id), iid, status, shift, angle, mean_planned - float(s.mean()), lost_seen,
                           np.asarray(m.world_from_marker, float), None if j is None else
                           np.asarray(installed[j].world_from_marker, float), note, move))
    paired = set(pairs.values())
    for j, inst in enumerate(installed):
        if j in paired:
            continue
        s = _scores_with(info_planned, score_planned, [], [installed_covs[j]])
        rows.append(TagRow(0, None, int(inst.tag_id), "extra", None, None, mean_planned - float(s.mean()), 0.0, None,
                           np.asarray(inst.world_from_marker, float),
                           f"tag {inst.tag_id} is not near any planned spot (it still helps; keep it in the tag map)"))
    return CheckResult(rows, score_planned, score_installed, data.base_score, data.disc)
