"""What the success model predicts for each evaluated placement (``evaluate --predicted``).

The model is the one plans use (their ``placement.recall_model``'s, fitted on
map images by :func:`markerplace.simulation.success_fit.calibrate_plan`; test images never touch
it), and so is the prediction: :func:`markerplace.plan.place.predicted_recall.marker_set_curve`, the
weighted mean over the N feasible poses of P(success | score with the placement's tags). What
changes between test sets is only the pose weights, those the test set's poses are drawn with
(:func:`markerplace.simulation.pose_sampling.sampling_probabilities`):

* ``uniform``: every pose 1 (a plan's own ``predicted_recall`` curve without ``--where``);
* ``weighted``: N times the paper's probabilities, towards low scores;
* ``where``: the ``--where`` pose weights (a plan's own curve with ``--where``).

So the predicted recall of a test set is the expected share of its test images that localize
if a test image localized as its source pose is predicted to. A second number, *on the drawn
poses*, weighs each feasible pose by how many of the test set's images were actually drawn from
it (their ``source_index``): the same prediction without the luck of the draw (and exact where
the free-space check redrew a pose).

A placement is predicted when its markers are candidates at the planned size
(:func:`markerplace.simulation.success_fit.placement_candidates`; not with ``--tag-scale``,
``--shift`` or a ``--placements`` file off the candidates); ``none`` is the empty set (k = 0).
The ceiling's placements (picked on the test images) and its single-tag runs are left out.
"""

from __future__ import annotations

import logging

import numpy as np

from markerplace.plan.place.predicted_recall import marker_set_curve
from markerplace.simulation.marker_sets import NO_MARKERS, RESERVED_NAMES
from markerplace.simulation.pose_sampling import sampling_probabilities
from markerplace.simulation.success_fit import placement_candidates

log = logging.getLogger(__name__)

__all__ = ["drawn_weights", "predict_recalls", "test_set_weights"]


def test_set_weights(base_score: np.ndarray, test_set: str, pose_weight: np.ndarray | None = None
                     ) -> np.ndarray | None:
    """(N,) pose weights summing to N with which ``test_set`` draws its source poses (None for
    ``uniform``: every pose 1, as a plan's curve without ``--where``)."""
    if test_set == "uniform":
        return None
    n = len(base_score)
    return n * sampling_probabilities(np.asarray(base_score, float), test_set, pose_weight)


test_set_weights.__test__ = False  # type: ignore[attr-defined]


def drawn_weights(num_poses: int, source_index: np.ndarray) -> np.ndarray:
    """(N,) weights summing to N: each feasible pose's share of the test images drawn from it."""
    counts = np.bincount(np.asarray(source_index, np.int64), minlength=num_poses).astype(float)
    return counts * (num_poses / counts.sum())


def predict_recalls(data, placements, test_poses: dict, tag_size: float, model: str) -> dict:
    """Predicted recall of every placement on every test set.

    Args:
        data: the prepared plan with the success model fitted (``data.calibration[model]``).
        placements: the evaluated :class:`~markerplace.simulation.marker_sets.PlacementRun` list.
        test_poses: test set -> :class:`~markerplace.simulation.pose_sampling.TestPoses`.
        tag_size: the planned tag size (metres): a marker of another size is no candidate.
        model: the calibrated method whose success model predicts (the plan's ``recall_model``).

    Returns:
        (test set, method, run, k) -> (predicted, predicted on the drawn poses), shares in [0, 1].
    """
    n = len(data.base_score)
    weights = {ts: (test_set_weights(data.base_score, ts, data.pose_weight), drawn_weights(n, tp.source_index))
               for ts, tp in test_poses.items()}
    out = {}
    for p in placements:
        if p.method in RESERVED_NAMES:
            continue
        cands = np.zeros(0, np.int64) if p.method == NO_MARKERS else \
            placement_candidates(p.markers, data.disc.candidate_world_from_marker, tag_size)
        if cands is None:
            log.info("predicted recall: %s k=%d run %d is not made of candidates; left out", p.method, p.k, p.run)
            continue
        for ts, (w_set, w_drawn) in weights.items():
            if p.test_sets is not None and ts not in p.test_sets:
                continue
            out[(ts, p.method, p.run, p.k)] = (float(marker_set_curve(data, cands, w_set, model)[-1]),
                                               float(marker_set_curve(data, cands, w_drawn, model)[-1]))
    return out
