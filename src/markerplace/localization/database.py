"""Map database for localization: per-image features with 3D points, VLAD, tag index.

In memory, concatenated arrays with offsets: ``poses`` (M, 4, 4) ``world_from_cam`` of each
map image; image i owns features ``offsets[i]:offsets[i+1]`` of ``keypoints`` (N, 2) float32
pixels, ``descriptors`` (N, 128) float32 SIFT, ``points_world`` (N, 3) float64 world metres;
tags ``tag_offsets[i]:tag_offsets[i+1]`` of ``tag_ids``; ``vlad`` (M, D) unit VLAD vectors; the
codebook and the markers. On disk a map is a feature folder
(:mod:`markerplace.imaging.features`, written by :func:`markerplace.simulation.maps.save_map`):
the database is built from it in each worker.

Only features with finite 3D points are kept.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from markerplace.localization.sift import SIFT_DEFAULT, SiftConfig, extract_sift, lift_to_3d
from markerplace.localization.tags import detect_tags
from markerplace.localization.vlad import VladCodebook
from markerplace.markers import Marker

log = logging.getLogger(__name__)



@dataclass(frozen=True, eq=False)
class MapImage:
    """One map image's localization data.

    Attributes:
        world_from_cam: (4, 4) pose.
        keypoints: (K, 2) float32 pixel (x, y).
        descriptors: (K, 128) float32 SIFT.
        points_world: (K, 3) float64 world points of the keypoints (all finite).
        tag_ids: (T,) int64 tag ids detected in the image.
    """

    world_from_cam: np.ndarray
    keypoints: np.ndarray
    descriptors: np.ndarray
    points_world: np.ndarray
    tag_ids: np.ndarray


def map_image_from_rgbd(
    rgb: np.ndarray,
    depth: np.ndarray,
    world_from_cam: np.ndarray,
    K: np.ndarray,
    sift: SiftConfig = SIFT_DEFAULT,
    detect: bool = True,
    max_depth: float = 10.0,
) -> MapImage:
    """Extract SIFT, lift to 3D with ``depth`` (metres) and detect tags in one map image."""
    kp, desc = extract_sift(rgb, sift)
    pts, valid = lift_to_3d(kp, depth, K, world_from_cam, max_depth=max_depth,
                            image_size=(rgb.shape[1], rgb.shape[0]))
    tags = np.array([d.tag_id for d in detect_tags(rgb)], np.int64) if detect else np.zeros(0, np.int64)
    return MapImage(np.asarray(world_from_cam, float), kp[valid], desc[valid], pts[valid], tags)


@dataclass(eq=False)
class MapDatabase:
    """All map images, concatenated (see module docstring for the layout).

    Build with :meth:`build`; image ``i``'s features are ``keypoints[offsets[i]:offsets[i+1]]``.
    """

    poses: np.ndarray
    offsets: np.ndarray
    keypoints: np.ndarray
    descriptors: np.ndarray
    points_world: np.ndarray
    tag_offsets: np.ndarray
    tag_ids: np.ndarray
    vlad: np.ndarray
    codebook: VladCodebook
    markers: dict[int, Marker] = field(default_factory=dict)
    tag_index: dict[int, list[int]] = field(init=False)

    def __post_init__(self) -> None:
        self.tag_index = {}
        for i in range(len(self)):
            for t in self.tag_ids[self.tag_offsets[i] : self.tag_offsets[i + 1]]:
                lst = self.tag_index.setdefault(int(t), [])
                if not lst or lst[-1] != i:
                    lst.append(i)

    def __len__(self) -> int:
        return int(len(self.poses))

    @property
    def num_features(self) -> int:
        return int(len(self.keypoints))

    def image(self, i: int) -> MapImage:
        """The :class:`MapImage` view of map image ``i`` (arrays are views, not copies)."""
        a, b = int(self.offsets[i]), int(self.offsets[i + 1])
        ta, tb = int(self.tag_offsets[i]), int(self.tag_offsets[i + 1])
        return MapImage(self.poses[i], self.keypoints[a:b], self.descriptors[a:b], self.points_world[a:b], self.tag_ids[ta:tb])

    def features(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(keypoints (K, 2), descriptors (K, 128), points_world (K, 3)) of image ``i``."""
        a, b = int(self.offsets[i]), int(self.offsets[i + 1])
        return self.keypoints[a:b], self.descriptors[a:b], self.points_world[a:b]

    @classmethod
    def build(
        cls,
        images: Iterable[MapImage | Sequence],
        markers: Iterable[Marker],
        codebook: VladCodebook,
    ) -> "MapDatabase":
        """Assemble a database.

        Args:
            images: :class:`MapImage` records or tuples ``(world_from_cam (4, 4), keypoints
                (K, 2), descriptors (K, 128), points_world (K, 3), tag_ids)``; features whose
                3D point is not finite are dropped.
            markers: the placement's markers (known tag poses), keyed by tag id.
            codebook: VLAD codebook used for the global descriptors.
        """
        poses, kps, descs, ptss, tags, vlads = [], [], [], [], [], []
        for rec in images:
            if isinstance(rec, MapImage):
                rec = (rec.world_from_cam, rec.keypoints, rec.descriptors, rec.points_world, rec.tag_ids)
            T, kp, desc, pts, tid = rec
            kp = np.asarray(kp, np.float32).reshape(-1, 2)
            desc = np.asarray(desc, np.float32).reshape(-1, 128)
            pts = np.asarray(pts, np.float64).reshape(-1, 3)
            if not (len(kp) == len(desc) == len(pts)):
                raise ValueError("keypoints, descriptors and points_world must have the same length")
            keep = np.all(np.isfinite(pts), axis=1)
            poses.append(np.asarray(T, np.float64).reshape(4, 4))
            kps.append(kp[keep])
            descs.append(desc[keep])
            ptss.append(pts[keep])
            tags.append(np.asarray(tid if tid is not None else [], np.int64).reshape(-1))
            vlads.append(codebook.vlad(desc[keep]))
        counts = np.array([len(k) for k in kps], np.int64)
        tcounts = np.array([len(t) for t in tags], np.int64)
        db = cls(
            poses=np.stack(poses) if poses else np.zeros((0, 4, 4)),
            offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            keypoints=np.concatenate(kps) if kps else np.zeros((0, 2), np.float32),
            descriptors=np.concatenate(descs) if descs else np.zeros((0, 128), np.float32),
            points_world=np.concatenate(ptss) if ptss else np.zeros((0, 3)),
            tag_offsets=np.concatenate([[0], np.cumsum(tcounts)]).astype(np.int64),
            tag_ids=np.concatenate(tags) if tags else np.zeros(0, np.int64),
            vlad=np.stack(vlads).astype(np.float32) if vlads else np.zeros((0, codebook.dim), np.float32),
            codebook=codebook,
            markers={int(m.tag_id): m for m in markers},
        )
        log.info("map database: %d images, %d features, %d markers", len(db), db.num_features, len(db.markers))
        return db
