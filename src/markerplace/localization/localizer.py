"""Localize a query image against a :class:`MapDatabase` (the paper's Fig. 8).

Pipeline for one query RGB image:

1. Tags (``use_tags``): detect tag36h11 tags. For each detected tag whose pose is known, the
   tag implies a coarse camera pose (IPPE square). Candidates, each group ranked by VLAD
   similarity: (a) map images that saw one of the detected tags AND lie near an implied pose
   (camera centres within ``tag_pose_radius_m``, optical axes within ``tag_pose_angle_deg``);
   (b) map poses near an implied pose (whether or not they saw the tag); (c) the other map
   images that saw a detected tag. At most ``num_candidates`` in total.
2. Fill up to ``num_candidates`` with VLAD nearest neighbours.
3. SIFT matching (query: OpenCV default SIFT) against each candidate, exact brute-force L2 kNN
   (k=2, numpy; equivalent to cv2.BFMatcher) with Lowe's ratio test; 2D-3D correspondences pooled over candidates, keeping for each query
   keypoint the match with the smallest descriptor distance.
4. ``tag_corners``: add the detected tags' 4 corners with their known 3D corners.
5. P3P RANSAC + LM (:func:`estimate_pose`).

Localizers are chosen by name from :data:`LOCALIZERS` (:mod:`markerplace.registry`); this
pipeline is ``sift_pnp`` (:class:`SiftPnP`, settings :class:`LocalizerConfig`). Adding one: a
subclass of :class:`Localizer` (``name``, ``summary``, a frozen ``Config`` subclassing
:class:`LocalizerSettings`, whose fields the testbed sets, and ``default_conf``) with
:meth:`Localizer.localize_features` returning :class:`LocalizationResult`, decorated with
``@LOCALIZERS.register`` (which refuses any other class); :func:`get_localizer` finds it by name.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from typing import ClassVar

import cv2
import numpy as np

from markerplace.localization.database import MapDatabase
from markerplace.localization.pnp import PnPConfig, estimate_pose
from markerplace.localization.sift import SIFT_DEFAULT, SiftConfig, extract_sift
from markerplace.localization.tags import TagDetection, detect_tags, pose_from_tag
from markerplace.localization.vlad import nearest_by_similarity
from markerplace.registry import Registry, configure

log = logging.getLogger(__name__)

@dataclass(frozen=True)
class LocalizerSettings:
    """The settings every localizer has, which the testbed sets (its
    :class:`~markerplace.testbed.config.LocalizationConfig` and seed,
    :func:`markerplace.simulation.map_setup.localizer_spec`).

    Attributes:
        use_tags: use the query's tag detections (``evaluate --no-tags`` turns it off).
        tag_corners: also use detected tag corners as 2D-3D correspondences (``--tag-corners``).
        seed: seed of any randomness of the localizer (RANSAC).
    """

    use_tags: bool = True
    tag_corners: bool = False
    seed: int = 0


@dataclass(frozen=True)
class LocalizerConfig(LocalizerSettings):
    """Settings of ``sift_pnp`` (paper defaults, docs/design.md section 3), besides
    :class:`LocalizerSettings`' (``use_tags``: tags in retrieval, the paper's "marker
    detection"; ``tag_corners``: off in the paper; ``seed``: RANSAC's).

    Attributes:
        num_candidates: map images retrieved per query (paper: 10).
        ratio: Lowe's ratio test threshold (paper: 0.8).
        tag_pose_radius_m: map poses within this distance of a tag-implied pose are candidates.
        tag_pose_angle_deg: ... and whose optical axis is within this angle of it.
        sift: query-side SIFT parameters (OpenCV defaults).
        pnp: RANSAC/refinement parameters.
    """

    num_candidates: int = 10
    ratio: float = 0.8
    tag_pose_radius_m: float = 2.0
    tag_pose_angle_deg: float = 60.0
    sift: SiftConfig = SIFT_DEFAULT
    pnp: PnPConfig = field(default_factory=PnPConfig)


@dataclass(frozen=True, eq=False)
class LocalizationResult:
    """Outcome of :meth:`Localizer.localize`.

    Attributes:
        world_from_cam: (4, 4) estimated pose or None (failure).
        num_inliers: PnP inliers (0 on failure before RANSAC).
        candidates: retrieved map image indices, in matching order.
        detected_tag_ids: ids of tags detected in the query (empty if tags are off).
        num_matches: pooled 2D-3D correspondences given to PnP.
        timing: seconds per stage (``features``, ``tags``, ``retrieval``, ``matching``, ``pnp``, ``total``).
    """

    world_from_cam: np.ndarray | None
    num_inliers: int
    candidates: list[int]
    detected_tag_ids: list[int]
    num_matches: int
    timing: dict[str, float]

    @property
    def success(self) -> bool:
        return self.world_from_cam is not None


class Localizer:
    """Base class of localizers: localizes query images of intrinsics ``K`` (3, 3) against ``db``.

    Class attributes:
        name: registry name (``evaluate --localizer NAME``).
        summary: a few words for help texts.
        Config: a frozen dataclass subclassing :class:`LocalizerSettings`; ``default_conf``
            an instance.
        replays_retrieval: for a query that sees no tag, the map images it matches against
            are the ``config.num_candidates`` (a field of its ``Config``) of highest VLAD
            similarity, after ``exclude``: then the testbed may replay that retrieval to reuse
            the marker-free result of a query no placement changes
            (:class:`markerplace.simulation.placement_localization.Retrieval`). False: every query is localized.

    Args:
        db: the map (images with SIFT features, 3D points, VLAD vectors, tags seen).
        K: (3, 3) pinhole matrix of the queries, pixels.
        config: settings; None = :attr:`default_conf`.
        **overrides: fields of ``Config`` replaced in ``config``.
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    Config: ClassVar[type] = LocalizerSettings
    default_conf: ClassVar = LocalizerSettings()
    replays_retrieval: ClassVar[bool] = False

    def __init__(self, db: MapDatabase, K: np.ndarray, config: LocalizerSettings | None = None, **overrides):
        self.db = db
        self.K = np.asarray(K, dtype=np.float64)
        self.config = configure(self.default_conf if config is None else config, overrides)

    def localize(self, rgb: np.ndarray) -> LocalizationResult:
        """Estimate the ``world_from_cam`` of an (H, W, 3) uint8 RGB query image: OpenCV-default
        SIFT and (with ``use_tags`` or ``tag_corners``) tag detection, then
        :meth:`localize_features`."""
        c = self.config
        t0 = time.perf_counter()
        kp, desc = extract_sift(rgb, SIFT_DEFAULT)
        tags = detect_tags(rgb) if (c.use_tags or c.tag_corners) else []
        result = self.localize_features(kp, desc, tags)
        result.timing.update(total=time.perf_counter() - t0)
        return result

    def localize_features(self, keypoints: np.ndarray, descriptors: np.ndarray,
                          tags: list[TagDetection], exclude=None) -> LocalizationResult:
        """Localize precomputed query features (what the testbed calls).

        Args:
            keypoints: (K, 2) pixel xy of the query's SIFT keypoints.
            descriptors: (K, 128) float32 SIFT descriptors (OpenCV defaults).
            tags: tag detections in the query (to be ignored unless ``use_tags`` or
                ``tag_corners`` is on).
            exclude: map image indices never used (a map image localized against the rest of
                the map leaves its own location out).

        Returns:
            the estimate (``world_from_cam`` None on failure) with retrieval and match details.
        """
        raise NotImplementedError


LOCALIZERS = Registry("localizer", "--localizer", base=Localizer)
"""Every localizer by name, in registration order (each a :class:`Localizer`)."""


@LOCALIZERS.register
class SiftPnP(Localizer):
    """The paper's localizer (the pipeline of the module docstring)."""

    name = "sift_pnp"
    summary = "tags and VLAD retrieval, SIFT matching, P3P RANSAC + LM, as in the paper"
    Config = LocalizerConfig
    default_conf = LocalizerConfig()
    replays_retrieval = True

    def __init__(self, db: MapDatabase, K: np.ndarray, config: LocalizerConfig | None = None, **overrides):
        super().__init__(db, K, config, **overrides)
        self._centres = db.poses[:, :3, 3] if len(db) else np.zeros((0, 3))
        self._axes = db.poses[:, :3, 2] if len(db) else np.zeros((0, 3))

    # ---- retrieval -------------------------------------------------------------------------
    def _near(self, world_from_cam: np.ndarray) -> np.ndarray:
        """(M,) bool: map poses near ``world_from_cam`` (radius and optical-axis angle)."""
        c = self.config
        close = np.linalg.norm(self._centres - world_from_cam[:3, 3], axis=1) <= c.tag_pose_radius_m
        cosang = self._axes @ world_from_cam[:3, 2]
        return close & (cosang >= np.cos(np.radians(c.tag_pose_angle_deg)))

    def retrieve(self, query_vlad: np.ndarray, tags: list[TagDetection], exclude=None) -> list[int]:
        """Candidate map image indices (tag-based first, then VLAD), at most ``num_candidates``.

        ``exclude``: map image indices never returned (e.g. the images taken at a map image's
        own location when that image is localized against the rest of the map); the ranking
        of the others is unchanged."""
        n = self.config.num_candidates
        if len(self.db) == 0 or n <= 0:
            return []
        sims = self.db.vlad @ np.asarray(query_vlad, dtype=self.db.vlad.dtype)  # as vlad.nearest computes it
        out: list[int] = []
        excluded = np.zeros(len(self.db), bool)
        if exclude is not None:
            excluded[np.asarray(exclude, dtype=np.int64)] = True
        if tags:
            saw = np.zeros(len(self.db), bool)
            near = np.zeros(len(self.db), bool)
            for det in tags:
                saw[self.db.tag_index.get(det.tag_id, [])] = True
                marker = self.db.markers.get(det.tag_id)
                if marker is not None:
                    try:
                        near |= self._near(pose_from_tag(det, marker, self.K))
                    except (RuntimeError, cv2.error) as exc:  # degenerate corners
                        log.debug("pose_from_tag failed for tag %d: %s", det.tag_id, exc)
            for group in (saw & near, near & ~saw, saw & ~near):
                idx = np.flatnonzero(group & ~excluded)
                out.extend(int(i) for i in idx[np.argsort(-sims[idx], kind="stable")])
            out = out[:n]
        if len(out) < n:
            taken = set(out)
            order, _ = nearest_by_similarity(sims, n + len(out) + int(excluded.sum()))
            out.extend(int(i) for i in order if int(i) not in taken and not excluded[i])
            out = out[:n]
        return out

    # ---- matching --------------------------------------------------------------------------
    def match(self, descriptors: np.ndarray, candidates: list[int]) -> tuple[np.ndarray, np.ndarray]:
        """Pooled matches: (L,) query keypoint indices and (L, 3) world points (best per keypoint).

        Per candidate: exact brute-force L2 2-nearest neighbours (the same as
        ``cv2.BFMatcher(NORM_L2).knnMatch(k=2)``, computed with one matrix product) and Lowe's
        ratio test ``d1 < ratio * d2``. Over candidates, each query keypoint keeps the match
        with the smallest distance.
        """
        q = np.asarray(descriptors, dtype=np.float32)
        nq = len(q)
        if nq == 0:
            return np.zeros(0, np.int64), np.zeros((0, 3))
        qq = np.einsum("ij,ij->i", q, q)
        best_d2 = np.full(nq, np.inf, np.float32)
        best_pt = np.full((nq, 3), np.nan)
        r2 = float(self.config.ratio) ** 2
        rows = np.arange(nq)
        for i in candidates:
            _, desc, pts = self.db.features(i)
            if len(desc) < 2:
                continue
            d2 = q @ (-2.0 * desc.T)
            d2 += qq[:, None]
            d2 += np.einsum("ij,ij->i", desc, desc)[None, :]
            # the two smallest per row (argmin, then the minimum of the rest: faster than
            # argpartition on these small rows; equal distances fail the ratio test either way)
            first = np.argmin(d2, axis=1)
            a = d2[rows, first]
            d2[rows, first] = np.inf
            b = d2.min(axis=1)
            d1, d2nd = np.maximum(a, 0.0), np.maximum(b, 0.0)
            ok = (d1 < r2 * d2nd) & (d1 < best_d2)
            best_d2[ok] = d1[ok]
            best_pt[ok] = pts[first[ok]]
        sel = np.flatnonzero(np.isfinite(best_d2))
        return sel.astype(np.int64), best_pt[sel]

    # ---- full pipeline ---------------------------------------------------------------------
    def localize(self, rgb: np.ndarray) -> LocalizationResult:
        """Estimate the ``world_from_cam`` of an (H, W, 3) uint8 RGB query image."""
        c = self.config
        t0 = time.perf_counter()
        kp, desc = extract_sift(rgb, c.sift)
        t1 = time.perf_counter()
        tags = detect_tags(rgb) if (c.use_tags or c.tag_corners) else []
        t2 = time.perf_counter()
        result = self.localize_features(kp, desc, tags)
        result.timing.update(features=t1 - t0, tags=t2 - t1, total=time.perf_counter() - t0)
        return result

    def localize_features(self, keypoints: np.ndarray, descriptors: np.ndarray,
                          tags: list[TagDetection], exclude=None) -> LocalizationResult:
        """:meth:`Localizer.localize_features` (descriptors of ``config.sift``'s parameters;
        ``exclude``: see :meth:`retrieve`)."""
        c = self.config
        timing: dict[str, float] = {}
        t2 = time.perf_counter()
        desc = np.asarray(descriptors, dtype=np.float32)
        qv = self.db.codebook.vlad(desc)
        candidates = self.retrieve(qv, tags if c.use_tags else [], exclude)
        t3 = time.perf_counter()
        timing["retrieval"] = t3 - t2
        qidx, pts = self.match(desc, candidates)
        px = np.asarray(keypoints)[qidx].astype(np.float64)
        if c.tag_corners:
            for det in tags:
                marker = self.db.markers.get(det.tag_id)
                if marker is not None:
                    pts = np.concatenate([pts, marker.corners_world()])
                    px = np.concatenate([px, det.corners])
        t4 = time.perf_counter()
        timing["matching"] = t4 - t3
        est = estimate_pose(pts, px, self.K, c.pnp, seed=c.seed)
        timing["pnp"] = time.perf_counter() - t4
        return LocalizationResult(
            world_from_cam=est.world_from_cam,
            num_inliers=est.num_inliers,
            candidates=candidates,
            detected_tag_ids=[d.tag_id for d in tags],
            num_matches=int(len(pts)),
            timing=timing,
        )


def get_localizer(name: str, db: MapDatabase, K: np.ndarray, **conf):
    """The localizer registered as ``name`` for ``db`` and queries of matrix ``K`` (3, 3), with
    ``conf`` overrides of its ``default_conf``.

    Raises:
        UserError: unknown name (one line listing the known ones).
    """
    return LOCALIZERS.lookup(name)(db, K, **conf)
