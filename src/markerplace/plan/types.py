"""What the plan stages hand each other: :class:`MarkerCoverage` (what one tag adds where it is
seen), :class:`PlanData` (scored poses and candidates, the input of every placement method) and
:class:`Placement` (the chosen tags).

Kept apart from the stages so that placement methods, the testbed and the reports can name
these types without importing the stages that make them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from markerplace.plan.discretize.artifact import Discretization

__all__ = ["MarkerCoverage", "PlanData", "Placement"]


@dataclass(frozen=True, eq=False)
class MarkerCoverage:
    """Poses that see one candidate marker and the information the marker adds there.

    Attributes:
        pose_idx: (n_m,) int, distinct indices into the feasible poses.
        info: (n_m, 6, 6) symmetric PSD information ``M`` per seeing pose, camera tangent
            space (omega, nu), 1/rad^2 and 1/m^2.

    Memory is ``n_m * 296`` bytes: 500 candidates seen by 500 poses each take 74 MB.
    """

    pose_idx: np.ndarray
    info: np.ndarray

    def __post_init__(self) -> None:
        idx = np.asarray(self.pose_idx, dtype=np.int64).reshape(-1)
        info = np.asarray(self.info, dtype=float).reshape(-1, 6, 6)
        if idx.shape[0] != info.shape[0]:
            raise ValueError("MarkerCoverage: pose_idx and info lengths differ")
        if np.unique(idx).shape[0] != idx.shape[0]:
            raise ValueError("MarkerCoverage: pose_idx must be distinct")
        object.__setattr__(self, "pose_idx", idx)
        object.__setattr__(self, "info", info)

    def __len__(self) -> int:
        return int(self.pose_idx.shape[0])

    @classmethod
    def from_dense(cls, info: np.ndarray, visible: np.ndarray | None = None) -> "MarkerCoverage":
        """From per-pose information (N, 6, 6) and an optional (N,) visibility mask.

        Poses that are not visible or whose information is exactly zero are dropped.
        """
        info = np.asarray(info, dtype=float)
        keep = np.any(info != 0.0, axis=(1, 2))
        if visible is not None:
            keep &= np.asarray(visible, dtype=bool)
        idx = np.flatnonzero(keep)
        return cls(idx, info[idx])


@dataclass(frozen=True, eq=False)
class PlanData:
    """Everything placement needs, computed once per scene and discretization.

    Attributes:
        disc: the discretization (poses, candidates, occupancy).
        base_info: (N, 6, 6) information per pose from scene features only.
        base_score: (N,) localizability score -entropy without markers.
        coverages: one :class:`MarkerCoverage` per candidate (poses that see it and the
            information it adds there), then one per existing marker.
        num_candidates: C (coverages[C:] belong to existing markers).
        timings: seconds per stage.
        points_world: (K, 3) float32 world metres of the map images' SIFT keypoints (NaN: no 3D
            point), or None; for methods that look at the scene's texture (``human``).
        pose_index: (K,) int32 camera pose of each keypoint, or None.
        visible: (N, C + E) bool: the pose sees the marker (geometry and occlusion), candidates
            then existing markers, or None; with ``marker_poses`` (C + E, 4, 4) and
            ``marker_sizes`` (C + E,) metres it rebuilds the coverages under another marker
            model (:func:`~markerplace.plan.score.stage.coverages_with_model`).
        calibration: what a calibrated method needs, filled by
            :func:`markerplace.simulation.success_fit.calibrate_plan` (e.g. the fitted
            :class:`~markerplace.plan.score.success_model.SuccessModel` of ``expected-recall``).
        marker_model: the registered marker model the coverages were computed with.
        pose_weight: (N,) weight >= 0 of each pose, summing to N (``plan --where``:
            :mod:`markerplace.plan.where`), or None: every pose weighs 1. The objectives
            (OMP's percentile, ``expected-recall``'s sum, the predicted recall and the bounds)
            weigh each pose by it.
    """

    disc: Discretization
    base_info: np.ndarray
    base_score: np.ndarray
    coverages: list
    num_candidates: int
    timings: dict
    points_world: np.ndarray | None = None
    pose_index: np.ndarray | None = None
    visible: np.ndarray | None = None
    marker_poses: np.ndarray | None = None
    marker_sizes: np.ndarray | None = None
    calibration: dict = field(default_factory=dict)
    marker_model: str = "paper"
    pose_weight: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class Placement:
    """A chosen set of markers.

    Attributes:
        candidates: (k,) candidate indices in placement order.
        gains: (k,) localizability gain of each pick when it was chosen (OMP; NaN otherwise).
        markers: the markers, with tag ids.
        info_after: (N, 6, 6) information per pose with existing + placed markers.
        q: OMP percentile used (NaN for baselines).
    """

    candidates: np.ndarray
    gains: np.ndarray
    markers: list
    info_after: np.ndarray
    q: float
