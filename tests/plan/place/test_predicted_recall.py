"""The predicted recall of any marker list (``marker_set_curve``): a plan's own curve for its
order, and any other order or pose weights through the same recall curve."""

from __future__ import annotations

import numpy as np
import pytest

from helpers.recall_problems import plan_data
from markerplace.plan.place.config import PlacementConfig
from markerplace.plan.place.predicted_recall import marker_set_curve, predicted_recall
from markerplace.plan.place.recall_curve import recall_curve
from markerplace.plan.place.stage import place

RECALL = PlacementConfig().recall_model  # the calibrated method whose model predicts recall


def test_marker_set_curve_is_the_plans_curve_for_its_order():
    data = plan_data(5, N=40, C=9, E=1)
    conf = PlacementConfig(method="omp", k=4)
    placement = place(data, conf, progress=False)
    pr = predicted_recall(data, placement, conf)
    curve = marker_set_curve(data, placement.candidates, data.pose_weight, RECALL)
    assert np.allclose(curve, pr["recall"], atol=1e-6)
    # the set's value does not depend on the order; the prefixes do
    rev = marker_set_curve(data, list(placement.candidates)[::-1], None, RECALL)
    assert rev[-1] == pytest.approx(curve[-1], abs=1e-12) and rev[0] == curve[0]


def test_marker_set_curve_weights_the_poses():
    data = plan_data(2, N=30, C=6, E=0)
    w = np.random.default_rng(0).uniform(0, 2, 30)
    w *= 30 / w.sum()
    fit = data.calibration[RECALL]
    got = marker_set_curve(data, [3, 1], w, RECALL)
    want = recall_curve(data.base_info, fit["coverages"][:6], [3, 1], fit["model"], (), w)
    assert np.array_equal(got, want)
    assert not np.allclose(got, marker_set_curve(data, [3, 1], None, RECALL))
