"""The place stage: k tags chosen among the scored candidates by the configured method, with
tag ids, and the first pick's gain per pose (the paper's Fig. 5(c))."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from markerplace.markers import FAMILY, Marker
from markerplace.plan.place.config import PlacementConfig
from markerplace.plan.place.greedy import apply_coverages, check_k
from markerplace.plan.place.methods import method_from_config
from markerplace.plan.score.localizability import information_gain
from markerplace.plan.types import Placement, PlanData

__all__ = ["place", "first_pick_gain"]


def place(data: PlanData, config: PlacementConfig, existing: Sequence[Marker] = (), progress: bool = True) -> Placement:
    """Choose ``config.k`` markers among the candidates with the method ``config.method``
    (:func:`~markerplace.plan.place.methods.method_from_config`), seeded with ``config.seed``; a
    nested method may stop early at ``config.target_recall``.

    With ``progress``, each OMP pick is logged (candidate, gain) as it is made.
    """
    check_k(config.k, data.num_candidates)
    choice = method_from_config(config).place(data, config.k, seed=config.seed, progress=progress,
                                              target=config.target_recall)
    order = np.asarray(choice.order, dtype=np.int64)
    used = {m.tag_id for m in existing}
    markers, tag_id = [], config.first_tag_id
    for c in order:
        while tag_id in used:
            tag_id += 1
        markers.append(Marker(tag_id, config.tag_size, data.disc.candidate_world_from_marker[c].copy(), FAMILY))
        used.add(tag_id)
    return Placement(order, np.asarray(choice.gains, dtype=float), markers, choice.info_after, float(choice.q))


def first_pick_gain(data: PlanData, placement: Placement) -> np.ndarray:
    """(N,) information gain of the first placed marker at every pose (0 where not seen),
    given the existing markers (the paper's Fig. 5(c))."""
    existing_info = apply_coverages(data.base_info, data.coverages[data.num_candidates:])
    gain = np.zeros(len(data.base_info))
    if len(placement.candidates):
        cov = data.coverages[int(placement.candidates[0])]
        if len(cov.pose_idx):
            gain[cov.pose_idx] = information_gain(existing_info[cov.pose_idx], cov.info)
    return gain
