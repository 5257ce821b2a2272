"""The marker-free side of the testbed that every evaluation of one plan shares: the map images'
features and the VLAD codebook trained on them, cached under keys that depend only on the
scene, the map poses, the imaging settings and the codebook's settings. ``evaluate`` and the
calibration of ``expected-recall`` (:mod:`markerplace.simulation.success_fit`) build them through
these functions, so when they share a cache folder the map is rendered and the codebook trained
once.
"""

from __future__ import annotations

import logging
import time
from dataclasses import fields, replace
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.errors import UserError
from markerplace.imaging.config import renders_alike
from markerplace.localization.localizer import LocalizerSettings
from markerplace.localization.sift import SIFT_DEFAULT
from markerplace.localization.vlad import VladCodebook
from markerplace.plan.observe import MapOutput
from markerplace.runtime import cache
from markerplace.runtime.stages import cached
from markerplace.simulation.conditions import CLEAN, QueryCondition, set_name
from markerplace.simulation.placement_localization import ImageSet, PredictContext
from markerplace.simulation.rendered_images import BaseImages, TestbedImaging, base_features_key

log = logging.getLogger(__name__)

__all__ = ["testbed_imaging_config", "localizer_spec", "map_base_key", "map_images", "observed_map_output",
           "vlad_codebook", "marker_free_images"]


def testbed_imaging_config(plan_config, imaging_config=None):
    """The testbed's imaging: ``imaging_config``, else the plan's camera with the localization
    SIFT preset (OpenCV defaults)."""
    return imaging_config or replace(plan_config.imaging, sift=SIFT_DEFAULT)


def localizer_spec(localization, seed: int) -> tuple:
    """(registered localizer name, its settings) from a
    :class:`~markerplace.testbed.config.LocalizationConfig` and the localizer's seed: the
    fields of :class:`~markerplace.localization.localizer.LocalizerSettings`, which every
    localizer's ``Config`` has, as (name, value) pairs (hashable: part of cache keys)."""
    settings = LocalizerSettings(use_tags=localization.use_tags, tag_corners=localization.tag_corners, seed=int(seed))
    return localization.localizer, tuple((f.name, getattr(settings, f.name)) for f in fields(settings))


def map_base_key(scene, map_poses: np.ndarray) -> str:
    """Key of the marker-free map of ``scene`` at (N, 4, 4) ``map_poses``."""
    return cache.hash_of("testbed-v1", cache.scene_hash(scene), np.asarray(map_poses, float))


def map_images(tb: TestbedImaging, map_poses: np.ndarray, cache_dir: Path, base_key: str) -> BaseImages:
    """Marker-free map features (3D points only) and in-view masks, in ``cache_dir/map_base``."""
    return BaseImages(tb, np.asarray(map_poses, float), Path(cache_dir) / "map_base", base_key, True, "map")


def observed_map_output(scene, map_poses: np.ndarray, cache_dir: str | Path, plan_config,
                        imaging_config=None) -> MapOutput | None:
    """Where ``observe`` writes the marker-free map features of :func:`map_images` in
    ``cache_dir`` from its own renders at the (N, 4, 4) ``map_poses`` (the discretization's
    poses), under the key :func:`map_images` checks; None (with a log line) when the testbed's
    imaging (:func:`testbed_imaging_config`) renders otherwise than the plan's observe (another
    camera or depth setting): then the map renders itself."""
    imaging, observe_imaging = testbed_imaging_config(plan_config, imaging_config), plan_config.imaging
    if not renders_alike(imaging, observe_imaging):
        log.info("observe: the testbed's imaging differs from the plan's beyond SIFT: the map renders on its own")
        return None
    key = base_features_key(map_base_key(scene, map_poses), True, imaging)
    return MapOutput(Path(cache_dir) / "map_base" / "features", key, imaging)


def vlad_codebook(cache_dir: Path, base_key: str, imaging, map_base: BaseImages, num_clusters: int, seed: int,
                  timings: dict | None = None) -> tuple:
    """(codebook, key): the VLAD codebook trained on the marker-free map's descriptors,
    ``cache_dir/vlad_codebook.npz``; the key (with the digest of the map's features) fixes the
    map of every prediction made with it."""
    key = cache.hash_of("vlad-v2", base_key, map_base.digest, imaging, num_clusters, seed)
    n = len(map_base.features.descriptors)
    if n < num_clusters:
        raise UserError(f"the marker-free map images hold {n} SIFT features, fewer than the {num_clusters} words of "
                        "the VLAD codebook: use more map images (a finer --grid-spacing, more --yaws) or a scene "
                        "with texture")
    codebook = cached("vlad_codebook", Path(cache_dir) / "vlad_codebook.npz", key,
                      lambda: VladCodebook.train(np.asarray(map_base.features.descriptors, np.float32),
                                                 num_clusters=num_clusters, seed=seed),
                      lambda cb, p: cb.save(p), VladCodebook.load, timings)
    return codebook, key


def marker_free_images(tb: TestbedImaging, map_poses: np.ndarray, test_poses: dict, cache_dir: Path, base_key: str,
                       imaging, localization, seed: int, timings: dict,
                       reuse: bool = True, conditions: Sequence[str] = (CLEAN,),
                       condition_seed: int = 0) -> tuple[PredictContext, dict]:
    """The marker-free side of one evaluation: map features, the VLAD codebook and the query
    features of every test set under every query condition (each cached in ``cache_dir``).

    ``reuse``: predictions reuse the marker-free result where a placement cannot change it.
    ``conditions``: query conditions (:mod:`markerplace.simulation.conditions`); each (test set,
    condition) is an image set named :func:`~markerplace.simulation.conditions.set_name` (the
    clean one: the test set's name, key and folder as before conditions existed), seeded by
    ``condition_seed`` (the test seed). The map is always clean.

    Returns:
        (the :class:`~markerplace.simulation.placement_localization.PredictContext` every prediction shares,
        image set name -> :class:`~markerplace.simulation.placement_localization.ImageSet`, test sets in order,
        conditions in order within each).
    """
    t0 = time.perf_counter()
    map_base = map_images(tb, map_poses, cache_dir, base_key)
    timings["map_no_markers"] = time.perf_counter() - t0
    codebook, cb_key = vlad_codebook(cache_dir, base_key, imaging, map_base, localization.vlad_clusters, seed, timings)
    t0 = time.perf_counter()
    sets = {}
    for ts, tp in test_poses.items():
        for c in conditions:
            cond = None if c == CLEAN else QueryCondition(c, ts, condition_seed)
            key = cache.hash_of(base_key, tp.world_from_cam) if cond is None else \
                cache.hash_of(base_key, tp.world_from_cam, cond.key())
            name = set_name(ts, c)
            folder = cache_dir / (f"query_base_{ts}" if cond is None else f"query_base_{ts}_{c}")
            sets[name] = ImageSet(name, tp.world_from_cam, BaseImages(tb, tp.world_from_cam, folder, key, False,
                                                                      f"queries {name}", condition=cond),
                                  condition=cond)
    timings["queries_no_markers"] = time.perf_counter() - t0
    ctx = PredictContext(tb, map_base, codebook, cb_key, localizer_spec(localization, seed), imaging, cache_dir, timings,
                         reuse)
    return ctx, sets
