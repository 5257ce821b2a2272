"""How the simulation localizes images (:class:`LocalizationConfig`): the ``evaluate`` settings
of the localizer, which the plan's calibration of ``expected-recall`` uses with its defaults."""

from __future__ import annotations

from dataclasses import dataclass

from markerplace.localization.localizer import LOCALIZERS
from markerplace.settings import setting

__all__ = ["LocalizationConfig"]


def _localizers():
    return LOCALIZERS


@dataclass(frozen=True)
class LocalizationConfig:
    """How test images are localized.

    Attributes:
        localizer: registered localizer name (:data:`markerplace.localization.localizer.LOCALIZERS`).
        use_tags: tag detection in the localizer (paper's "marker detection"; off = --no-tags).
        tag_corners: also use the tag corners as 2D-3D correspondences.
        vlad_clusters: k-means clusters of the VLAD codebook (trained on the no-marker map).
    """

    localizer: str = setting("sift_pnp", flag="--localizer", commands=("evaluate",), choices=lambda: _localizers().names(),
                             help=lambda: f"localizer of the test images: {_localizers().help()}",
                             doc="a registered localizer (today one: tags + VLAD retrieval + SIFT matching + P3P "
                                 "RANSAC + LM refinement)")
    use_tags: bool = setting(True, flag="--no-tags", commands=("evaluate",), const=False,
                             help="localize without tag detection (paper's parameter study)")
    tag_corners: bool = setting(False, flag="--tag-corners", commands=("evaluate",), const=True,
                                help="also use detected tag corners as 2D-3D matches (beyond the paper)")
    vlad_clusters: int = 64
