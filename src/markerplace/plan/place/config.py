"""Settings of the place stage: how many tags, chosen by which method, printed how large."""

from __future__ import annotations

from dataclasses import dataclass, field

from markerplace.markers import DEFAULT_TAG_SIZE
from markerplace.plan.place.method_registry import PLACEMENT_METHODS, method_settings
from markerplace.plan.score.marker_models import MARKER_MODELS
from markerplace.settings import SEED_MAX, setting

K_ALL = 10_000
"""``k`` of a ``--target-recall`` plan given no ``-k``: the largest -k, so that only the
candidates and the free tag ids bound the plan."""


@dataclass(frozen=True)
class PlacementConfig:
    """How markers are chosen.

    Attributes:
        k: number of markers to place.
        method: a name in :data:`~markerplace.plan.place.methods.PLACEMENT_METHODS`: ``omp`` (the
            paper's greedy), ``random`` (seeded uniform sample of candidates) or ``uniform``
            (evenly spaced along the free-space perimeter).
        marker_model: a name in :data:`~markerplace.plan.score.marker_models.MARKER_MODELS`:
            ``paper`` (relative-pose factor, as published) or ``corners`` (projected tag
            corners; depends on distance, viewing angle and tag size).
        tag_size: black-square edge of the printed tags, metres: the one home of the tag size
            (the discretization's fit check, the scoring and the placed markers use it).
        similarity: down-weight look-alike points (the paper's similarity analysis).
        seed: seed of the randomized methods (random and uniform).
        first_tag_id: tag id of the first placed marker; ids count up in placement order,
            skipping ids of existing markers.
        target_recall: place tags until the predicted recall (share of feasible camera poses
            predicted to localize under the success model fitted on the map images,
            :mod:`markerplace.plan.place.recall_curve`) reaches this share, in (0, 1]; ``k`` is
            then the most tags (without ``-k`` on the command line: every candidate). Needs a
            nested method (``omp``, ``expected-recall``). None: place ``k`` tags.
        recall_curve: fit the success model for any method, so that ``report.html`` and
            ``placement.json`` show the predicted recall against k (calibration renders and
            localizes the map images: :func:`markerplace.simulation.success_fit.calibrate_plan`).
            Always on with ``expected-recall`` or ``target_recall``.
        recall_model: the calibrated method (a
            :class:`~markerplace.plan.place.methods.CalibratedMethod`) whose fitted success model
            predicts the recall of every plan (the recall curve, ``target_recall``,
            ``evaluate --predicted``).
        methods: each registered method's own settings (its ``Config``), by method name with
            ``-`` as ``_`` (:func:`~markerplace.plan.place.method_registry.method_settings`): the one
            home of OMP's ``v``, ``expected-recall``'s ``calibration_poses``, ... In a
            ``--config`` file the table ``[placement.methods.omp]``; on the command line
            ``--method-conf KEY=VALUE`` (and the flags a method's fields carry, ``-v``,
            ``--calibration-poses``).
    """

    k: int = setting(20, flag="-k", bounds=(1, 10_000), commands=("plan",), help="number of markers to place",
                     doc="number of markers", hint="the number of markers to place, e.g. 20")
    method: str = setting("omp", flag="--method", choices=lambda: PLACEMENT_METHODS.names(), commands=("plan",),
                          help=lambda: f"placement method: {PLACEMENT_METHODS.help()}",
                          doc=lambda: "a registered placement method: " + ", ".join(
                              f"`{n}`" + (f" ({c.summary})" if getattr(c, "summary", "") else "")
                              for n, c in PLACEMENT_METHODS.items()))
    marker_model: str = setting("paper", flag="--marker-model", choices=lambda: MARKER_MODELS.names(),
                                help=lambda: f"marker information model: {MARKER_MODELS.help()}")
    tag_size: float = setting(DEFAULT_TAG_SIZE, flag="--tag-size", bounds=(0.02, 3.0), units="m",
                              hint="the black-square edge in metres, e.g. 0.4",
                              help="black-square edge of the printed tags, metres; the one tag size (the "
                                   "discretization's fit check uses it too)")
    similarity: bool = setting(True, flag="--no-similarity", const=False,
                               help="turn the look-alike (similarity) analysis off (no down-weighting of repeated "
                                    "features)")
    seed: int = setting(0, flag="--placement-seed", bounds=(0, SEED_MAX), hint=f"a seed in 0..{SEED_MAX}, e.g. 0",
                        help=lambda: "seed of the " + "/".join(n for n, c in PLACEMENT_METHODS.items() if c.randomized)
                        + " placements")
    first_tag_id: int = 0
    target_recall: float | None = setting(
        None, flag="--target-recall", bounds=(0.0, 1.0), commands=("plan",), metavar="R",
        hint="a share of camera poses in (0, 1], e.g. 0.9",
        help="place tags until the predicted share of camera poses that localize reaches R (0 < R <= 1), under "
             "the success model fitted on the map images; -k, if given, is the most tags (else every candidate); "
             "omp or expected-recall")
    recall_curve: bool = setting(
        False, flag="--recall-curve", const=True, commands=("plan",),
        help="fit the success model (renders and localizes the map images) for any method, so that report.html "
             "and placement.json show the predicted recall against the number of tags; always on with "
             "expected-recall or --target-recall")
    recall_model: str = setting("expected-recall", choices=lambda: tuple(
        n for n, c in PLACEMENT_METHODS.items() if c.calibrated))
    methods: object = field(default_factory=method_settings)
