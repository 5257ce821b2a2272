"""Spots where no tag may go (``plan --exclude FILE``), and what a replan changed.

For what no rule can see (a wall that will be painted, a spot behind a door that opens, a spot
the review of ``report.html`` rejected), the user lists spots and boxes to avoid in a small JSON
file, in the model's (user) frame, metres, z up::

    {
      "format": "markerplace-exclude/1",
      "spots": [{"x": 1.20, "y": 0.05, "z": 1.50, "radius": 0.3, "note": "tag #3 (id 2)"}],
      "boxes": [{"min": [0.0, 3.9, 0.0], "max": [5.0, 4.3, 2.7], "note": "north wall, to be painted"}]
    }

A candidate is excluded when its tag centre lies within ``radius`` (metres, default
:data:`DEFAULT_RADIUS`) of a spot, or inside a box (bounds included). Every key but ``spots``
or ``boxes`` is optional; ``format``, ``scene``, ``note`` (also per spot and box), and per spot
``order`` and ``tag_id`` are kept for people and ignored; any other key is an error. The file
``report.html``'s review buttons download (``rejected.json``) has this format.

The exclusion is applied when placing, as a mask over the cached candidates
(:func:`exclude_candidates`): the discretization, observation and similarity stages keep their
cache keys, so a replan renders nothing. An excluded spot is not replaced by the next spot along
the wall (that would change the candidates, and re-render).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.input_paths import check_input_file
from markerplace.jsonfile import read_json
from markerplace.scene.worldframe import points_to_user

log = logging.getLogger(__name__)

__all__ = ["DEFAULT_RADIUS", "FORMAT", "Exclusion", "apply_exclusion", "exclude_candidates", "excluded",
           "load_exclusion", "placement_changes", "previous_markers", "describe_changes"]

FORMAT = "markerplace-exclude/1"
DEFAULT_RADIUS = 0.3
"""Radius of a spot without one, metres."""

_TOP_KEYS = {"format", "scene", "note", "spots", "boxes"}
_SPOT_KEYS = {"x", "y", "z", "radius", "note", "order", "tag_id"}
_BOX_KEYS = {"min", "max", "note"}


@dataclass(frozen=True, eq=False)
class Exclusion:
    """Spots and boxes to avoid, user frame (metres, z up).

    Attributes:
        spots: (S, 3) centres.
        radius: (S,) radii, metres.
        boxes: (B, 2, 3) min and max corners.
        source: the file they came from (for messages).
    """

    spots: np.ndarray
    radius: np.ndarray
    boxes: np.ndarray
    source: str = ""

    def to_json(self) -> dict:
        """The file format (for ``config.json``)."""
        return {"format": FORMAT,
                "spots": [{"x": float(p[0]), "y": float(p[1]), "z": float(p[2]), "radius": float(r)}
                          for p, r in zip(self.spots, self.radius)],
                "boxes": [{"min": [float(v) for v in b[0]], "max": [float(v) for v in b[1]]} for b in self.boxes]}


def _number(value, what: str, path) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UserError(f"--exclude {path}: {what} must be a finite number, not {value!r}")
    if abs(value) > 1e7:
        raise UserError(f"--exclude {path}: {what} = {value:g} is not a coordinate in metres")
    return float(value)


def _keys(entry, allowed: set, what: str, path) -> dict:
    if not isinstance(entry, dict):
        raise UserError(f"--exclude {path}: {what} must be a JSON object, not {type(entry).__name__}")
    unknown = sorted(set(entry) - allowed)
    if unknown:
        raise UserError(f"--exclude {path}: {what} has unknown key(s) {', '.join(map(repr, unknown))}; "
                        f"allowed: {', '.join(sorted(allowed))} (see docs/cli.md)")
    return entry


def load_exclusion(path: str | Path) -> Exclusion:
    """Read an exclusion file (see the module docstring).

    Raises:
        UserError: a missing or unreadable file, not JSON, an unknown key, a missing or
            non-numeric coordinate, a negative radius, a box whose min exceeds its max, or a
            file with neither spots nor boxes.
    """
    path = Path(path)
    check_input_file(path, f"--exclude {path}", "a JSON file of spots and boxes to avoid",
                     "; give a JSON file of spots and boxes to avoid (or the rejected.json that report.html downloads)")

    doc = read_json(path, f"--exclude {path}")  # size, UTF-8 and depth guards, one line
    _keys(doc, _TOP_KEYS, "the file", path)
    if doc.get("format", FORMAT) != FORMAT:
        raise UserError(f"--exclude {path}: format {doc['format']!r} is not {FORMAT!r}")
    spots_in, boxes_in = doc.get("spots", []), doc.get("boxes", [])
    if not isinstance(spots_in, list) or not isinstance(boxes_in, list):
        raise UserError(f"--exclude {path}: 'spots' and 'boxes' must be JSON lists")
    if not spots_in and not boxes_in:
        raise UserError(f"--exclude {path}: no spots and no boxes: nothing to exclude")
    spots, radius, boxes = [], [], []
    for i, s in enumerate(spots_in):
        s = _keys(s, _SPOT_KEYS, f"spot {i + 1}", path)
        missing = [k for k in ("x", "y", "z") if k not in s]
        if missing:
            raise UserError(f"--exclude {path}: spot {i + 1} has no {', '.join(missing)}")
        spots.append([_number(s[k], f"spot {i + 1} {k}", path) for k in ("x", "y", "z")])
        r = _number(s.get("radius", DEFAULT_RADIUS), f"spot {i + 1} radius", path)
        if r <= 0:
            raise UserError(f"--exclude {path}: spot {i + 1} radius must be positive (metres), not {r:g}")
        radius.append(r)
    for i, b in enumerate(boxes_in):
        b = _keys(b, _BOX_KEYS, f"box {i + 1}", path)
        corners = []
        for k in ("min", "max"):
            v = b.get(k)
            if not isinstance(v, list) or len(v) != 3:
                raise UserError(f"--exclude {path}: box {i + 1} needs '{k}': [x, y, z]")
            corners.append([_number(c, f"box {i + 1} {k}", path) for c in v])
        if any(a > c for a, c in zip(*corners)):
            raise UserError(f"--exclude {path}: box {i + 1} has min {corners[0]} above max {corners[1]}")
        boxes.append(corners)
    return Exclusion(np.asarray(spots, float).reshape(-1, 3), np.asarray(radius, float),
                     np.asarray(boxes, float).reshape(-1, 2, 3), str(path))


def excluded(exclusion: Exclusion, positions: np.ndarray) -> np.ndarray:
    """(C,) bool: the (C, 3) tag centres (user frame) within a spot's radius or inside a box."""
    p = np.asarray(positions, float).reshape(-1, 3)
    out = np.zeros(len(p), bool)
    if len(exclusion.spots):
        d = np.linalg.norm(p[:, None] - exclusion.spots[None], axis=2)
        out |= np.any(d <= exclusion.radius[None], axis=1)
    if len(exclusion.boxes):
        lo, hi = exclusion.boxes[:, 0], exclusion.boxes[:, 1]
        out |= np.any(np.all((p[:, None] >= lo[None] - 1e-9) & (p[:, None] <= hi[None] + 1e-9), axis=2), axis=1)
    return out


def exclude_candidates(data, drop: np.ndarray):
    """The :class:`~markerplace.plan.types.PlanData` without the candidates where (C,) bool
    ``drop`` is true (existing markers stay; the calibration's coverages follow)."""
    drop = np.asarray(drop, bool)
    C = data.num_candidates
    if not drop.any():
        return data
    keep = np.r_[~drop, np.ones(len(data.coverages) - C, bool)]
    idx = np.flatnonzero(keep)
    calibration = {name: {**fit, "coverages": [fit["coverages"][i] for i in idx]} if "coverages" in fit else fit
                   for name, fit in data.calibration.items()}
    return replace(data, disc=data.disc.with_candidates(~drop), coverages=[data.coverages[i] for i in idx],
                   num_candidates=int((~drop).sum()),
                   visible=None if data.visible is None else data.visible[:, keep],
                   marker_poses=None if data.marker_poses is None else data.marker_poses[keep],
                   marker_sizes=None if data.marker_sizes is None else data.marker_sizes[keep],
                   calibration=calibration)


def apply_exclusion(data, exclusion: Exclusion, offset, k: int):
    """``data`` (:class:`~markerplace.plan.types.PlanData`, internal frame) without the
    candidates ``exclusion`` (user frame) covers; ``offset`` (3,) is the scene's
    :func:`~markerplace.scene.worldframe.world_offset`. Logs how many went.

    Raises:
        UserError: fewer than ``k`` candidates would be left.
    """
    drop = excluded(exclusion, points_to_user(data.disc.candidate_position, offset))
    left = data.num_candidates - int(drop.sum())
    log.info("plan: --exclude %s (%d spots, %d boxes) removes %d of %d candidates", exclusion.source,
             len(exclusion.spots), len(exclusion.boxes), int(drop.sum()), data.num_candidates)
    if not drop.any():
        log.warning("--exclude %s matches no candidate spot (check its coordinates are the model's, as in "
                    "placement.json)", exclusion.source)
    if left < k:
        raise UserError(f"--exclude {exclusion.source} leaves {left} candidate spots, fewer than -k {k}; exclude "
                        "less or lower -k")
    return exclude_candidates(data, drop)


def previous_markers(out: str | Path, scene: str) -> list | None:
    """The marker records of ``out/placement.json`` when it is a plan of ``scene`` (None: no
    file, another scene's, or unreadable)."""
    path = Path(out) / "placement.json"
    if not path.is_file():
        return None

    try:
        doc = read_json(path)
        markers = doc.get("markers") if doc.get("scene") == scene else None
    except (UserError, AttributeError):
        return None
    ok = isinstance(markers, list) and all(isinstance(m, dict) and {"position", "order", "tag_id"} <= set(m)
                                           for m in markers)
    return markers if ok else None


def placement_changes(old: list[dict], new: list[dict], same: float = 0.01, moved: float = 2.0) -> dict:
    """What changed between two ``placement.json`` marker lists (user frame).

    A spot in both (centres within ``same`` metres) is ``kept`` (its order or tag id may differ);
    an old spot without a match whose nearest unmatched new spot faces the same way (normals
    within 30 degrees) within ``moved`` metres has ``moved`` there; the other old spots are
    ``removed``, the other new ones ``added``.

    Returns:
        ``{"kept": [(old, new)], "moved": [(old, new, metres)], "removed": [old], "added": [new]}``
        with the records themselves.
    """
    def arrays(records):
        p = np.array([r["position"] for r in records], float).reshape(-1, 3)
        n = np.array([r.get("normal", [0.0, 0.0, 0.0]) for r in records], float).reshape(-1, 3)
        return p, n

    po, no = arrays(old)
    pn, nn = arrays(new)
    free_new = set(range(len(new)))
    kept, left = [], []
    for i in range(len(old)):
        d = np.linalg.norm(pn - po[i], axis=1) if len(pn) else np.zeros(0)
        j = next((int(j) for j in np.argsort(d) if j in free_new and d[j] <= same), None)
        if j is None:
            left.append(i)
        else:
            free_new.discard(j)
            kept.append((old[i], new[j]))
    moves, removed = [], []
    for i in left:
        cands = [j for j in free_new if float(no[i] @ nn[j]) >= np.cos(np.radians(30.0))]
        if cands:
            d = {j: float(np.linalg.norm(pn[j] - po[i])) for j in cands}
            j = min(d, key=d.get)
            if d[j] <= moved:
                free_new.discard(j)
                moves.append((old[i], new[j], d[j]))
                continue
        removed.append(old[i])
    return {"kept": kept, "moved": moves, "removed": removed, "added": [new[j] for j in sorted(free_new)]}


def _at(r: dict) -> str:
    x, y, z = r["position"]
    return f"#{r['order']} (tag id {r['tag_id']}) at ({x:.2f}, {y:.2f}, {z:.2f})"


def describe_changes(changes: dict) -> list[str]:
    """Lines for the log and the terminal: a count line, then one line per changed tag."""
    kept, moved, removed, added = (changes[k] for k in ("kept", "moved", "removed", "added"))
    renumbered = [(a, b) for a, b in kept if (a["order"], a["tag_id"]) != (b["order"], b["tag_id"])]
    lines = [f"changes against the previous placement.json: {len(kept)} kept ({len(renumbered)} of them "
             f"renumbered), {len(moved)} moved, {len(removed)} removed, {len(added)} added"]
    lines += [f"  moved: {_at(a)} -> #{b['order']} (tag id {b['tag_id']}) at "
              f"({b['position'][0]:.2f}, {b['position'][1]:.2f}, {b['position'][2]:.2f}), {d:.2f} m away"
              for a, b, d in moved]
    lines += [f"  removed: {_at(a)}" for a in removed]
    lines += [f"  added: {_at(b)}" for b in added]
    lines += [f"  renumbered: {_at(a)} is now #{b['order']} (tag id {b['tag_id']})" for a, b in renumbered]
    return lines
