"""Settings of the imaging engine: the camera, the feature preset and the visibility tests."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from markerplace.geometry import Intrinsics
from markerplace.localization.sift import SIFT_SCORING, SiftConfig
from markerplace.settings import setting

OBSERVE_VIEWS = ("pose", "location-renders", "location-features")
"""Values of :attr:`ImagingConfig.observe_views`."""

__all__ = ["OBSERVE_VIEWS", "ImagingConfig", "renders_alike"]


@dataclass(frozen=True)
class ImagingConfig:
    """How an image is made and read.

    Attributes:
        camera: pinhole intrinsics of every render (paper: 600x450, 90 deg horizontal FOV).
            The one home of the camera: planning, scoring and the testbed read it from here.
        sift: feature preset: the paper's scoring preset (1000 features, contrast 0.1, edge 5)
            for planning, OpenCV defaults for localization (``SIFT_DEFAULT``).
        max_depth: features farther than this get no 3D point, metres.
        occlusion_tolerance: a marker sample counts as hidden only when the rendered surface is
            closer than the sample by more than this, metres.
        visibility_margin_px: for "may this marker change the image": samples up to this many
            pixels outside the image still count as inside (conservative).
        visibility_grid: samples per side of a marker's drawn quad for that test.
        observe_views: how plan's observe stage looks at a camera location: ``pose`` renders
            and extracts every pose; ``location-renders`` renders every other yaw as a larger
            face, the yaws between get their image resampled from the two faces (SIFT per
            pose); ``location-features`` also gives the yaws between the faces' features (SIFT
            per face) (:mod:`markerplace.imaging.location_views`). Planning only: the testbed
            renders every image, and a run that also makes the testbed's map images
            (``evaluate``, ``plan --with-map``, a success model) observes per pose. Default
            ``location-renders``: its fidelity to ``pose`` is measured in
            benchmarks/observe_views.py (docs/results/benchmarks.md).
    """

    camera: Intrinsics = field(default_factory=Intrinsics)
    sift: SiftConfig = SIFT_SCORING
    max_depth: float = 10.0
    occlusion_tolerance: float = 0.10
    visibility_margin_px: float = 16.0
    visibility_grid: int = 7
    observe_views: str = setting("location-renders", flag="--observe-views", choices=lambda: OBSERVE_VIEWS, commands=("plan",),
                                 help="how observe looks at a camera location: pose (render and extract every "
                                      "pose), location-renders (every other yaw rendered as a larger view, the "
                                      "yaws between resampled from it: half the renders) or location-features "
                                      "(also their features taken from it: half the renders and SIFT)")


def renders_alike(a: ImagingConfig, b: ImagingConfig) -> bool:
    """True when ``a`` and ``b`` make the same images (camera, depth and visibility settings)
    and differ at most in the feature preset: one render can then feed both extractions (the
    plan's observe and the testbed's marker-free map)."""
    return replace(a, sift=b.sift, observe_views=b.observe_views) == b
