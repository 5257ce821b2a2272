"""Settings of the place stage: how many tags, chosen by which method, printed how large."""

from __future__ import annotations

from dataclasses import dataclass

from markerplace.markers import DEFAULT_TAG_SIZE

CALIBRATION_POSES = ("map", "offgrid")
"""Images ``expected-recall`` may fit its success model on (``--calibration-poses``)."""


@dataclass(frozen=True)
class PlacementConfig:
    """How markers are chosen.

    Attributes:
        k: number of markers to place.
        method: a name in :data:`~markerplace.plan.place.methods.PLACEMENT_METHODS`: ``omp`` (the
            paper's greedy), ``random`` (seeded uniform sample of candidates) or ``uniform``
            (evenly spaced along the free-space perimeter).
        v: OMP hyper-parameter in [0, 100]: the most visible v percent of candidates compete.
        marker_model: a name in :data:`~markerplace.plan.score.marker_models.MARKER_MODELS`:
            ``paper`` (relative-pose factor, as published) or ``corners`` (projected tag
            corners; depends on distance, viewing angle and tag size).
        tag_size: black-square edge of the printed tags, metres: the one home of the tag size
            (:class:`PlanConfig` derives ``discretize.tag_size``, the tag that must fit flat on
            a wall, from it; the scoring and the placed markers use it too).
        similarity: down-weight look-alike points (the paper's similarity analysis).
        lazy: lazy greedy (exactly the same picks as plain greedy, far fewer evaluations).
        seed: seed of the randomized methods (random and uniform).
        first_tag_id: tag id of the first placed marker; ids count up in placement order,
            skipping ids of existing markers.
        calibration_poses: images ``expected-recall`` fits its success model on (map images
            only, never test images): ``map`` (the map images, each localized against the map
            without its own location) or ``offgrid`` (renders at test-like poses, map poses
            perturbed within a grid cell and +-22.5 deg of yaw, localized against the whole
            map; :mod:`markerplace.testbed.calibration`).
    """

    k: int = 20
    method: str = "omp"
    v: float = 90.0
    marker_model: str = "paper"
    tag_size: float = DEFAULT_TAG_SIZE
    similarity: bool = True
    lazy: bool = True
    seed: int = 0
    first_tag_id: int = 0
    calibration_poses: str = "map"
