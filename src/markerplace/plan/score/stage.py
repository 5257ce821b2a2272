"""The score stage: each camera pose's information from its SIFT points (look-alikes
down-weighted), its localizability score, and what every candidate tag would add where it is
seen (:class:`~markerplace.plan.types.MarkerCoverage`).

Frames: poses are world_from_cam (N, 4, 4), marker poses world_from_marker (M, 4, 4), metres.
The marker list is the candidates first, then the existing markers.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from typing import Sequence

import numpy as np

from markerplace.geometry import Intrinsics
from markerplace.imaging.features import FeatureSet
from markerplace.plan.discretize.artifact import Discretization
from markerplace.plan.score.localizability import NoiseConfig, entropy, marker_visibility, pose_information
from markerplace.plan.score.marker_models import get_marker_model
from markerplace.plan.types import MarkerCoverage, PlanData

log = logging.getLogger(__name__)

__all__ = ["geometric_visibility", "build_coverages", "coverages_with_model", "score_poses"]


def geometric_visibility(world_from_cam: np.ndarray, world_from_markers: np.ndarray, camera: Intrinsics,
                         max_range: float) -> np.ndarray:
    """(N, M) bool: range (``max_range`` metres), field of view and viewing angle, no occlusion,
    of each of M marker poses from each of N camera poses."""
    out = np.zeros((len(world_from_cam), len(world_from_markers)), dtype=bool)
    for c, T in enumerate(world_from_markers):
        out[:, c] = marker_visibility(world_from_cam, T, camera.K, (camera.width, camera.height), max_range=max_range)
    return out


def build_coverages(world_from_cam: np.ndarray, world_from_markers: np.ndarray, sizes: Sequence[float],
                    visible: np.ndarray, marker_model: str, noise: NoiseConfig, K: np.ndarray) -> list:
    """One :class:`MarkerCoverage` per marker pose from the (N, M) visibility mask, with the
    information of the registered ``marker_model`` (:mod:`markerplace.plan.score.marker_models`);
    ``sizes`` (M,) metres, ``K`` (3, 3) the camera matrix."""
    model = get_marker_model(marker_model, noise=noise)
    covs = []
    for c, T in enumerate(world_from_markers):
        idx = np.flatnonzero(visible[:, c])
        info = model.information(world_from_cam[idx], T, sizes[c], K) if len(idx) else np.zeros((0, 6, 6))
        covs.append(MarkerCoverage(pose_idx=idx.astype(np.int64), info=info))
    return covs


def coverages_with_model(data: PlanData, marker_model: str, noise: NoiseConfig, K: np.ndarray) -> list:
    """``data.coverages`` (candidates, then existing markers) under another registered marker
    model: the same poses see each marker, the information differs."""
    if marker_model == data.marker_model:
        return data.coverages
    return build_coverages(data.disc.world_from_cam, data.marker_poses, list(data.marker_sizes), data.visible,
                           marker_model, noise, K)


def score_poses(disc: Discretization, obs: FeatureSet, n_similar: np.ndarray, marker_poses: np.ndarray,
                sizes: list, in_view: np.ndarray, num_existing: int, marker_model: str, noise: NoiseConfig,
                K: np.ndarray, timings: dict) -> PlanData:
    """The score stage (in memory, seconds): base information and score of every pose, and the
    coverage of every marker that some pose sees.

    Args:
        disc: the discretization; ``marker_poses`` (C + E, 4, 4) are its C candidates then the E
            = ``num_existing`` existing markers, ``sizes`` their black-square edges (metres).
        obs: the observe stage's features (3D points, pose of each, ``candidate_unoccluded``).
        n_similar: (P,) look-alike count of each point (zeros: the analysis is off).
        in_view: (N, C + E) bool geometric visibility (:func:`geometric_visibility`).
        timings: ``score`` seconds added.

    Candidates no pose sees are removed (a tag nobody sees helps nobody) and counted in the
    discretization's summary under ``candidates_removed["not seen"]``.
    """
    t0 = time.perf_counter()
    C = len(disc.candidate_world_from_marker)
    points, pose_index = obs.points_world, obs.image_index
    base_info = pose_information(disc.world_from_cam, K, np.asarray(points, float), pose_index, n_similar, noise)
    visible = in_view & np.asarray(obs.extras["candidate_unoccluded"])
    seen = visible[:, :C].any(axis=0)
    if not seen.all():
        log.info("plan: %d of %d candidates are seen by no camera pose (hidden behind furniture, beyond every "
                 "view or on walls no camera faces); removed", int((~seen).sum()), C)
        keep = np.r_[seen, np.ones(num_existing, bool)]
        disc = disc.with_candidates(seen)
        marker_poses, sizes, visible = marker_poses[keep], [v for v, k in zip(sizes, keep) if k], visible[:, keep]
        C = int(seen.sum())
    removed = {**disc.summary.get("candidates_removed", {}), "not seen": int((~seen).sum())}
    disc = replace(disc, summary={**disc.summary, "candidates_removed": removed})
    coverages = build_coverages(disc.world_from_cam, marker_poses, sizes, visible, marker_model, noise, K)
    timings["score"] = time.perf_counter() - t0
    return PlanData(disc, base_info, -entropy(base_info), coverages, C, timings, np.asarray(points), pose_index,
                    visible, marker_poses, np.asarray(sizes, float), marker_model=marker_model)
