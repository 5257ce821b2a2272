"""Map databases per placement, and localizing test images against them on the executor.

A placement's map database is a folder (:func:`save_map`): the map images' features (a
:class:`~markerplace.imaging.features.FeatureSet`, memory-mapped by the workers), their poses,
the placement's markers and the VLAD codebook. A worker builds the
:class:`~markerplace.localization.database.MapDatabase` and the localizer once per folder and
keeps them in its imaging engine's cache while it localizes that placement's queries.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.imaging.engine import ImagingEngine
from markerplace.imaging.features import FeatureSet, ImageFeatures
from markerplace.localization.database import MapDatabase
from markerplace.localization.localizer import get_localizer
from markerplace.localization.tags import TagDetection
from markerplace.localization.vlad import VladCodebook
from markerplace.markers import Marker, marker_from_json
from markerplace.runtime.atomic_io import write_json, write_npy

__all__ = ["save_map", "load_map_database", "localize_features", "localize_task"]


def save_map(folder: str | Path, features: FeatureSet, world_from_cam: np.ndarray, markers: Sequence[Marker],
             codebook_centres: np.ndarray) -> None:
    """Write everything a worker needs to build one placement's map database into ``folder``:
    the features, (N, 4, 4) map poses, the markers (JSON) and the (C, 128) VLAD centres."""
    folder = Path(folder)
    features.save(folder)
    write_npy(folder / "poses.npy", np.asarray(world_from_cam, np.float64))
    write_npy(folder / "codebook.npy", np.asarray(codebook_centres, np.float32))
    write_json(folder / "markers.json", [m.to_json() for m in markers])


def load_map_database(folder: str | Path):
    """Build the :class:`~markerplace.localization.database.MapDatabase` saved by :func:`save_map`."""
    folder = Path(folder)
    feats = FeatureSet.load(folder, mmap=True)
    poses = np.load(folder / "poses.npy", allow_pickle=False)
    codebook = VladCodebook(np.load(folder / "codebook.npy", allow_pickle=False))
    markers = [marker_from_json(d) for d in json.loads((folder / "markers.json").read_text())]
    images = []
    for i in range(len(feats)):
        f = feats.image(i)
        images.append((poses[i], f.keypoints, f.descriptors.astype(np.float32), f.points_world, f.tag_ids))
    return MapDatabase.build(images, markers, codebook)


def _tag_detections(feats: ImageFeatures) -> list:
    return [TagDetection(int(t), np.asarray(c, np.float64), np.asarray(c, np.float64).mean(axis=0))
            for t, c in zip(feats.tag_ids, feats.tag_corners)]


def localize_features(localizer, feats: ImageFeatures, exclude=None):
    """Localize precomputed query features (extracted once, reused across placements);
    ``exclude``: map images left out of retrieval."""
    return localizer.localize_features(feats.keypoints, feats.descriptors.astype(np.float32), _tag_detections(feats),
                                       exclude)


def localize_task(engine: ImagingEngine, item) -> np.ndarray:
    """(db folder, (localizer name, settings), features | None, world_from_cam, markers[,
    exclude]) -> (4, 4) estimate, all NaN on failure. With features None the query is first
    rendered here with ``markers`` (its view holds some of them); ``exclude`` (map image
    indices left out of retrieval) localizes a map image against the rest of the map."""
    folder, (name, settings), feats, world_from_cam, markers = item[:5]
    exclude = item[5] if len(item) > 5 else None
    if engine.cache.get("db_folder") != (folder, name, settings):
        engine.cache.pop("localizer", None)
        engine.cache["localizer"] = get_localizer(name, load_map_database(folder), engine.K, **dict(settings))
        engine.cache["db_folder"] = (folder, name, settings)
    if feats is None:
        feats = engine.features(engine.render(world_from_cam, markers), tags=True)
    res = localize_features(engine.cache["localizer"], feats, exclude)
    return np.full((4, 4), np.nan) if res.world_from_cam is None else np.asarray(res.world_from_cam, float)
