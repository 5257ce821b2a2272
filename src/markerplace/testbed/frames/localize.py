"""Each placement's map database from the map frames, and the query frames localized against it.

The map of a placement is its map images (``real`` frames or ``render`` images, :mod:`.images`)
with its tags in them, each image's features from the :class:`~.store.FeatureStore`, the map
poses, the placement's markers and the VLAD codebook of the marker-free map
(:func:`markerplace.simulation.maps.save_map`, one folder per placement and map kind, named by the
hash of its contents). Queries are localized by the registered localizer on the executor
(:func:`markerplace.simulation.maps.localize_task`), their estimates stored per (map, query kind)
as ``.npz`` so that a rerun reuses them.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.imaging.engine import marker_key
from markerplace.imaging.features import FeatureSet, ImageFeatures
from markerplace.localization.vlad import VladCodebook
from markerplace.markers import Marker
from markerplace.progress import progress_bar
from markerplace.runtime.atomic_io import atomic_path, write_npz
from markerplace.runtime.cache import hash_of
from markerplace.simulation.maps import localize_task, save_map
from markerplace.testbed.frames.store import FeatureStore, image_key

log = logging.getLogger(__name__)

__all__ = ["markers_in_view_of", "train_codebook", "build_map", "localize_queries"]


def _without_extras(feats: ImageFeatures) -> ImageFeatures:
    """The features a map keeps (per-image compositing counts differ in length between images)."""
    return ImageFeatures(feats.keypoints, feats.descriptors, feats.points_world, feats.tag_ids, feats.tag_corners)


def markers_in_view_of(in_view: dict, frame: int, markers: Sequence[Marker]) -> list[Marker]:
    """The markers of a placement that may show in ``frame``: ``in_view`` maps
    (frame, :func:`~markerplace.imaging.engine.marker_key`) to bool for the union of markers."""
    return [m for m in markers if in_view[(int(frame), marker_key(m))]]


def train_codebook(store: FeatureStore, kind: str, map_frames: Sequence[int], num_clusters: int, seed: int,
                   path: Path) -> VladCodebook:
    """The VLAD codebook on the marker-free map images' descriptors (3D points only), cached at ``path``."""
    key = hash_of("frames-vlad-v1", store.settings_key, kind, np.asarray(map_frames), num_clusters, seed)
    meta = path.with_suffix(".key")
    if path.is_file() and meta.is_file() and meta.read_text() == key:
        return VladCodebook.load(path)
    desc = [store.get(image_key(kind, f, ())).with_3d_only().descriptors for f in map_frames]
    codebook = VladCodebook.train(np.concatenate(desc).astype(np.float32), num_clusters=num_clusters, seed=seed)
    codebook.save(path)
    with atomic_path(meta) as tmp:  # a run folder's own file (runtime.run_folder)
        tmp.write_text(key)
    return codebook


def build_map(store: FeatureStore, kind: str, map_frames: Sequence[int], poses: np.ndarray, markers: Sequence[Marker],
              in_view: dict, codebook: VladCodebook, root: Path) -> Path:
    """The map folder of one placement (module docstring); made once per content."""
    keys = [image_key(kind, f, markers_in_view_of(in_view, f, markers)) for f in map_frames]
    name = hash_of("frames-map-v1", store.settings_key, [(k[0], k[1], [marker_key(m) for m in k[2]]) for k in keys],
                   [marker_key(m) for m in markers], np.asarray(codebook.centres))
    folder = Path(root) / f"{kind}-{name}"
    if not (folder / "markers.json").is_file():
        feats = FeatureSet.from_images([_without_extras(store.get(k).with_3d_only()) for k in keys])
        save_map(folder, feats, np.asarray(poses, float), list(markers), np.asarray(codebook.centres))
    return folder


def localize_queries(store: FeatureStore, map_folder: Path, query_kind: str, query_frames: Sequence[int],
                     query_poses: np.ndarray, markers: Sequence[Marker], in_view: dict, localizer: tuple,
                     executor, job, out: Path, progress: bool = True, desc: str = "localize") -> np.ndarray:
    """(Q, 4, 4) estimated ``world_from_cam`` of the query images (all NaN where localization
    failed), cached in ``out`` (``.npz``) under the map, the queries and the localizer."""
    keys = [image_key(query_kind, f, markers_in_view_of(in_view, f, markers)) for f in query_frames]
    key = hash_of("frames-localize-v1", str(map_folder.name), store.settings_key,
                  [(k[0], k[1], [marker_key(m) for m in k[2]]) for k in keys], localizer)
    path = Path(out) / f"{map_folder.name}-{query_kind}-{key}.npz"
    if path.is_file():
        with np.load(path, allow_pickle=False) as z:
            return z["world_from_cam"]
    items = [(str(map_folder), localizer, store.get(k), query_poses[i], list(markers)) for i, k in enumerate(keys)]
    est = np.full((len(items), 4, 4), np.nan)
    with progress_bar(len(items), desc, "query", progress) as bar:
        for i, T in executor.map(localize_task, items, job):
            est[i] = T
            bar.update(1)
    write_npz(path, world_from_cam=est)
    return est
