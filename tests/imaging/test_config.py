"""``renders_alike``: when one render can feed both the plan's and the testbed's extraction."""

from dataclasses import replace

import pytest

from markerplace.geometry import Intrinsics
from markerplace.imaging.config import ImagingConfig, renders_alike
from markerplace.localization.sift import SIFT_DEFAULT, SIFT_SCORING


def test_a_different_feature_preset_still_renders_alike():
    plan = ImagingConfig(sift=SIFT_SCORING)
    testbed = replace(plan, sift=SIFT_DEFAULT)
    assert plan != testbed
    assert renders_alike(plan, testbed) and renders_alike(testbed, plan)


@pytest.mark.parametrize("change", [dict(camera=Intrinsics(width=640, height=480, fx=320.0, fy=320.0, cx=320.0, cy=240.0)),
                                    dict(max_depth=8.0), dict(occlusion_tolerance=0.05),
                                    dict(visibility_margin_px=0.0), dict(visibility_grid=5)])
def test_any_other_setting_does_not(change):
    plan = ImagingConfig()
    assert not renders_alike(plan, replace(plan, sift=SIFT_DEFAULT, **change))
