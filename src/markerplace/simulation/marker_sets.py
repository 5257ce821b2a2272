"""The marker sets an evaluation compares: no markers, every placement method (OMP once with
the largest k and its prefixes, randomized methods once per run and k), and placement files
given with ``--placements``; printed at a scaled size or shifted along their walls for the
sensitivity studies.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.markers import Marker
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.plan.place.stage import place
from markerplace.tagfamily import NUM_TAGS

#: ``--methods`` name of the marker set without markers; every other name is a placement method
#: of :data:`~markerplace.plan.place.methods.PLACEMENT_METHODS`.
NO_MARKERS = "none"
#: Names of the diagnostics' marker sets (:mod:`markerplace.testbed.ceiling`); a placement file of
#: that name is renamed like one named after a method.
RESERVED_NAMES = ("single", "ceiling")


def method_names() -> tuple[str, ...]:
    """Every name ``--methods`` accepts: ``none``, then the registered placement methods."""
    return (NO_MARKERS, *PLACEMENT_METHODS)


def baseline_methods() -> tuple[str, ...]:
    """The randomized placement methods (``random``, ``uniform``): placed ``--runs`` times each
    and the baselines of the paired comparisons."""
    return tuple(name for name, cls in PLACEMENT_METHODS.items() if cls.randomized)


def marker_set_count(config) -> int:
    """Marker sets with markers that :func:`build_placements` evaluates without ``--placements``
    files: per method, one per k, times ``runs`` for randomized methods (every entry of
    ``config.study.ks`` counts: an upper bound when ks repeat)."""
    ks = len(config.study.ks)
    return sum(ks * (config.study.runs if PLACEMENT_METHODS[m].randomized else 1)
               for m in config.study.methods if m in PLACEMENT_METHODS)


@dataclass(frozen=True, eq=False)
class PlacementRun:
    """One evaluated marker set.

    Attributes:
        method: ``none``, a placement method's name or an extra (``--placements``) name.
        run: run index (0 for deterministic methods).
        k: number of markers (0 for ``none``).
        markers: the markers as drawn in the scene (after tag scale and shift).
        test_sets: the test sets it is evaluated on (None: every one); the ceiling's oracle
            placements are chosen on one test set's images and evaluated on that set only.
    """

    method: str
    run: int
    k: int
    markers: tuple
    test_sets: tuple | None = None


def shift_markers(markers: Sequence, shift: float, seed: int) -> list:
    """Move marker i along its wall (marker x axis) by ``s_i * shift`` metres, ``s_i = s0 (-1)^i``
    with a seeded random first sign ``s0``; orientation unchanged."""
    if shift == 0.0 or not markers:
        return list(markers)
    s0 = 1.0 if np.random.default_rng(seed).random() < 0.5 else -1.0
    out = []
    for i, m in enumerate(markers):
        T = np.array(m.world_from_marker, dtype=float)
        T[:3, 3] += s0 * (-1.0) ** i * shift * T[:3, 0]
        out.append(Marker(m.tag_id, m.size, T, m.family))
    return out


def scale_markers(markers: Sequence, scale: float) -> list:
    """Markers printed ``scale`` times their planned size (same centre and orientation)."""
    if scale == 1.0:
        return list(markers)
    return [Marker(m.tag_id, m.size * scale, np.array(m.world_from_marker, float), m.family) for m in markers]


def candidate_of(world_from_marker: np.ndarray, candidate_world_from_marker: np.ndarray, atol: float = 1e-5) -> int:
    """Index of the candidate whose (4, 4) pose equals ``world_from_marker`` within ``atol``
    (above the 1e-6 rounding of placement.json), or -1 when none does."""
    cands = np.asarray(candidate_world_from_marker, float).reshape(-1, 16)
    if not len(cands):
        return -1
    d = np.abs(cands - np.asarray(world_from_marker, float).reshape(1, 16)).max(axis=1)
    j = int(np.argmin(d))
    return j if d[j] <= atol else -1


def with_candidate_ids(runs: Sequence[PlacementRun], candidate_world_from_marker: np.ndarray) -> list[PlacementRun]:
    """The same marker sets with tag ids fixed by spot (``--tag-ids candidate``).

    A marker on candidate spot c (pose within 1e-5 of the candidate's, any printed size)
    shows id c in every run; any other marker (shifted, or from a placement file with its own
    spots) an id from C up, one per pose, in order of first appearance. When the ids would
    exceed the tag family, the runs are returned unchanged (ids in placement order) with a
    warning.

    Args:
        runs: the marker sets (ids as placed).
        candidate_world_from_marker: (C, 4, 4) candidate poses.
    """
    C = len(candidate_world_from_marker)
    others: dict[tuple, int] = {}

    def spot(m) -> int:
        j = candidate_of(m.world_from_marker, candidate_world_from_marker)
        if j >= 0:
            return j
        return C + others.setdefault(tuple(np.round(np.asarray(m.world_from_marker, float).ravel(), 4)), len(others))

    ids = [[spot(m) for m in r.markers] for r in runs]
    if C + len(others) > NUM_TAGS:
        logging.getLogger(__name__).warning("--tag-ids candidate: %d spots need more ids than tag36h11 has (%d); "
                                            "ids stay in placement order", C + len(others), NUM_TAGS)
        return list(runs)
    return [PlacementRun(r.method, r.run, r.k, tuple(Marker(i, m.size, np.array(m.world_from_marker, float), m.family)
                                                     for i, m in zip(rid, r.markers)), r.test_sets)
            for r, rid in zip(runs, ids)]


def build_placements(data, placement_config, config, extra: dict[str, Sequence] | None = None,
                     given: dict[str, Sequence] | None = None) -> list[PlacementRun]:
    """Every marker set to evaluate, in processing order.

    Args:
        data: the planner's :class:`~markerplace.plan.types.PlanData` (one ``prepare``).
        placement_config: the planner's :class:`~markerplace.plan.place.config.PlacementConfig` (v,
            marker model, tag size, similarity, placement seed).
        config: the :class:`~markerplace.testbed.config.EvaluateConfig` (its study: methods,
            runs, ks, tag scale, shift; its pose seed for the shift signs).
        extra: method name -> ordered markers (e.g. from ``--placements``); evaluated at each k
            up to their length (prefixes), or at their full length when shorter than every k.
        given: method name -> its placement made already (``evaluate --plan``), used instead
            of placing it: its first k markers at each k (the caller keeps k within it, and
            to its length for a method that is not nested).

    Methods come in registry order. A ``nested`` method (OMP) is placed once with max k and
    evaluated on prefixes; a ``randomized`` one (random, uniform) draws its own placement for
    every (run, k) with seed ``placement_seed + run``; any other is placed once per k.
    """
    study = config.study
    ks = sorted(set(study.ks))
    runs: list[PlacementRun] = []

    def add(method, run, k, markers):
        markers = shift_markers(scale_markers(markers, study.tag_scale), study.shift, config.pose_seed)
        runs.append(PlacementRun(method, run, k, tuple(markers)))

    if NO_MARKERS in study.methods:
        runs.append(PlacementRun(NO_MARKERS, 0, 0, ()))
    for method, cls in PLACEMENT_METHODS.items():
        if method not in study.methods:
            continue
        if method in (given or {}):
            for k in ks:
                add(method, 0, k, list(given[method])[:k])
        elif cls.randomized:
            for run in range(study.runs):
                for k in ks:
                    pl = place(data, replace(placement_config, k=k, method=method, seed=placement_config.seed + run),
                               progress=False)
                    add(method, run, k, pl.markers)
        elif cls.nested:
            pl = place(data, replace(placement_config, k=max(ks), method=method), progress=False)
            for k in ks:
                add(method, 0, k, pl.markers[:k])
        else:
            for k in ks:
                add(method, 0, k, place(data, replace(placement_config, k=k, method=method), progress=False).markers)
    for name, markers in (extra or {}).items():
        fits = [k for k in ks if k <= len(markers)] or [len(markers)]
        for k in fits:
            add(name, 0, k, list(markers)[:k])
    return runs


def find_placement_files(folder: str | Path) -> dict[str, Path]:
    """``placement.json`` (or any ``*.json``) files under ``folder`` -> method name.

    The name is the parent folder for files called ``placement.json`` and the file stem
    otherwise. Raises :class:`UserError` when nothing is found or names clash.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise UserError(f"--placements {folder} is not a directory")
    found: dict[str, Path] = {}
    for path in sorted(folder.rglob("*.json")):
        # plan's and evaluate's own outputs and caches are not placements
        parts = path.relative_to(folder).parts
        if (path.name.endswith(".meta.json") or path.name in ("config.json", "timings.json", "check.json")
                or path.name.startswith("success_model_") or {"cache", "calibration", "tagmaps"} & set(parts)):
            continue
        name = path.parent.name if path.name == "placement.json" else path.stem
        if name in method_names() or name in RESERVED_NAMES:
            name = f"{name}-file"
        if name in found:
            raise UserError(f"--placements: two files give the method name {name!r} ({found[name]}, {path}): rename one")
        found[name] = path
    if not found:
        raise UserError(f"--placements {folder} holds no placement.json files: run `markerplace plan` first")
    return found
