"""Localizing image sets against each placement's map, skipping what a placement cannot change.

A placement's map (:class:`PlacementMaps`) holds the marker-free map features except for the
images with one of its markers in view, which are re-rendered (features cached by image and
markers in view, so OMP's nested prefixes share them). Against that map,
:func:`localize_set` localizes one image set (test queries, or the map images themselves with
their own location left out) and reuses the marker-free result of every image no marker of the
placement can change: its view holds none of the markers (so its features and tags are the
marker-free ones), the map images its VLAD retrieval returns against this placement's map are
the ones it returns against the marker-free map, in the same order, and none of them was
re-rendered. The localizer then sees identical inputs (and seeds RANSAC per query), so the
result is identical: this skips work, it approximates nothing (``tests/pipelines/test_evaluate.py``
compares both paths).
"""

from __future__ import annotations

import logging
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from markerplace.imaging.features import ImageFeatures
from markerplace.localization.localizer import LOCALIZERS
from markerplace.localization.vlad import nearest
from markerplace.registry import configure
from markerplace.runtime import cache, run_folder
from markerplace.simulation.conditions import QueryCondition
from markerplace.simulation.maps import localize_task, save_map
from markerplace.simulation.marker_sets import NO_MARKERS
from markerplace.simulation.prediction_store import PartialPrediction, load_prediction, save_prediction
from markerplace.simulation.render_store import RenderStore
from markerplace.simulation.rendered_images import BaseImages, TestbedImaging
from markerplace.tagfamily import DRAWING_VERSION


@dataclass(frozen=True, eq=False)
class ImageSet:
    """Images localized against every placement's map.

    Attributes:
        name: the set's name (a test set, or ``map`` for the map images themselves).
        world_from_cam: (Q, 4, 4) true poses.
        base: their marker-free features and union-marker in-view mask.
        exclude: per image, map image indices left out of its retrieval (None: none); the map
            images leave out their own location.
        own: the images are the map's own (re-rendered ones come from the placement's map).
        condition: the query condition its images are rendered under (None: clean), as
            ``base``'s; the images re-rendered with a placement's markers get it too.
    """

    name: str
    world_from_cam: np.ndarray
    base: BaseImages
    exclude: list | None = None
    own: bool = False
    condition: QueryCondition | None = None

__all__ = ["ImageSet", "Retrieval", "RenderedFeatures", "PlacementMap", "PlacementMaps", "localize_set",
           "PredictionKey", "PredictContext", "predict_placements"]

log = logging.getLogger(__name__)


class Retrieval:
    """The VLAD retrieval of images that see no marker, replayed in this process to tell which
    of them a placement cannot change.

    ``vlad`` (M, D) float32 holds the marker-free map images' VLAD vectors exactly as a
    worker's :class:`~markerplace.localization.database.MapDatabase` computes them; a
    placement replaces the rows of its re-rendered images.
    """

    def __init__(self, codebook, map_base: BaseImages, num_candidates: int):
        self.codebook = codebook
        self.n = int(num_candidates)
        feats = map_base.features
        self.vlad = np.stack([codebook.vlad(np.asarray(feats.image(i).descriptors, np.float32))
                              for i in range(len(feats))]).astype(np.float32) if len(feats) else None
        self._sets: dict = {}

    def image_vlads(self, name: str, features) -> list:
        """VLAD vectors of the images of a FeatureSet (computed once per ``name``)."""
        if name not in self._sets:
            feats = features
            self._sets[name] = [self.codebook.vlad(np.asarray(feats.image(i).descriptors, np.float32))
                                for i in range(len(feats))]
        return self._sets[name]

    def candidates(self, vlad: np.ndarray, query: np.ndarray, exclude: Sequence[int] = ()) -> tuple:
        """The localizer's VLAD-only retrieval of ``query`` against the rows of ``vlad``,
        leaving out ``exclude`` (as :meth:`~markerplace.localization.localizer.SiftPnP.retrieve`)."""
        skip = set(int(i) for i in exclude)
        order = nearest(vlad, query, self.n + len(skip))[0]
        return tuple(int(i) for i in order if int(i) not in skip)[:self.n]

    def unchanged(self, vlad: np.ndarray, query: np.ndarray, changed: set, exclude: Sequence[int] = ()) -> bool:
        """The query's retrieval against a placement's map (rows ``vlad``) equals the
        marker-free one and none of the retrieved images changed."""
        cand = self.candidates(vlad, query, exclude)
        return not (set(cand) & changed) and cand == self.candidates(self.vlad, query, exclude)


@dataclass(frozen=True, eq=False)
class PlacementMap:
    """One placement's map database on disk.

    Attributes:
        folder: the database folder (:func:`~markerplace.simulation.maps.save_map`).
        changed: indices of the map images re-rendered with the placement's markers.
        features: the map's features (marker-free ones where unchanged).
        vlad: (M, D) the map images' VLAD vectors, or None when no retrieval replay is kept.
    """

    folder: Path
    changed: set
    features: object
    vlad: np.ndarray | None


class RenderedFeatures:
    """Features of the images of one set rendered with markers, keyed by (image, markers in
    view): an image is rendered again only when the markers in its view change, so nested
    placements (OMP's prefixes) share the renders of the images whose view they do not change.
    Only the current placement's entries are kept in memory; with a :class:`RenderStore`,
    every render also goes to disk and is read back instead of rendered in later placements
    and runs.

    Args:
        store: the folder's render store (None: keep nothing on disk).
        set_key: the image set's features key (:attr:`BaseImages.key`); names its images in
            the store (and holds the set's query condition).
        condition: the query condition the set's images are rendered under (None: clean).
    """

    def __init__(self, store: RenderStore | None = None, set_key: str = "", condition: QueryCondition | None = None):
        self._features: dict[tuple, ImageFeatures] = {}
        self.store, self.set_key, self.condition = store, set_key, condition

    def _store_key(self, tb: TestbedImaging, i: int, key: tuple) -> str:
        return cache.hash_of("render-v1", DRAWING_VERSION, self.set_key, i, tb.appearance(key))

    def update(self, tb: TestbedImaging, world_from_cam: np.ndarray, keys: list, markers: Sequence, map_only: bool,
               desc: str, indices: Sequence[int] | None = None) -> dict[int, ImageFeatures]:
        """Features of every image of ``indices`` (default all) with markers in view
        (``keys``, :meth:`TestbedImaging.view_keys`), rendering the ones not held yet."""
        idx = range(len(keys)) if indices is None else indices
        used = {(i, keys[i]) for i in idx if keys[i]}
        need = sorted(i for i, _ in used if (i, keys[i]) not in self._features)
        names = {i: self._store_key(tb, i, keys[i]) for i in need} if self.store is not None else {}
        if names:
            got = self.store.get(names.values())
            for i in need:
                if names[i] in got:
                    self._features[(i, keys[i])] = got[names[i]]
            if got:
                log.debug("%s: %d of %d renders from the store", desc, len(got), len(need))
            need = [i for i in need if names[i] not in got]
        if need:
            for i, f in tb.render_iter(world_from_cam, need, markers, map_only, desc, self.condition):
                self._features[(i, keys[i])] = f
                if self.store is not None:
                    self.store.put(names[i], f)
            if self.store is not None:
                self.store.flush()
        for stale in [c for c in self._features if c not in used]:
            del self._features[stale]
        return {i: self._features[(i, k)] for i, k in used}


class PlacementMaps:
    """Builds the map database of each placement (see the module docstring), keeping the
    re-rendered features of the images the current placement shares with the previous ones.

    Args:
        tb: the testbed's imaging.
        map_base: marker-free map features and the map's in-view masks.
        codebook: the VLAD codebook.
        retrieval: the marker-free retrieval replay (None: no reuse of unchanged results).
        store: where renders with markers are kept between runs (None: nowhere).
    """

    def __init__(self, tb: TestbedImaging, map_base: BaseImages, codebook, retrieval: Retrieval | None,
                 store: RenderStore | None = None):
        self.tb, self.map_base, self.codebook, self.retrieval = tb, map_base, codebook, retrieval
        self._features = RenderedFeatures(store, map_base.key)

    @contextmanager
    def built(self, markers: Sequence, folder: Path, desc: str):
        """Write the map database of ``markers`` into ``folder``, yield its
        :class:`PlacementMap`, and delete the folder afterwards."""
        tb, base = self.tb, self.map_base
        keys = tb.view_keys(base.in_view, markers)
        rendered = self._features.update(tb, base.world_from_cam, keys, markers, True, desc)
        feats = base.features.with_images(rendered) if rendered else base.features
        changed = set(rendered)
        vlad = None
        if self.retrieval is not None:
            vlad = self.retrieval.vlad.copy()
            for i in changed:
                vlad[i] = self.codebook.vlad(np.asarray(feats.image(i).descriptors, np.float32))
        save_map(folder, feats, base.world_from_cam, markers, self.codebook.centres)
        try:
            yield PlacementMap(Path(folder), changed, feats, vlad)
        finally:
            run_folder.remove_tree(folder)


def localize_set(tb: TestbedImaging, pmap: PlacementMap, markers: Sequence, lcfg, world_from_cam: np.ndarray,
                 in_view: np.ndarray, base_features, base_estimates: np.ndarray | None, retrieval: Retrieval | None,
                 set_name: str, desc: str, exclude: Sequence[Sequence[int]] | None = None,
                 own_features: bool = False, rendered: RenderedFeatures | None = None,
                 partial: PartialPrediction | None = None) -> tuple[np.ndarray, int]:
    """Localize every image of one set against a placement's map.

    Args:
        tb: the testbed's imaging (its executor runs the localizations).
        pmap: the placement's map.
        markers: the placement's markers.
        lcfg: (localizer name, settings).
        world_from_cam: (Q, 4, 4) true poses of the images (rendered when they see a marker).
        in_view: (Q, U) union-marker in-view mask of the images.
        base_features: the images' marker-free features (a FeatureSet).
        base_estimates: (Q, 4, 4) marker-free estimates (reused where nothing can change), or
            None to localize every image.
        retrieval: the marker-free retrieval replay (None: no reuse).
        set_name: key of the set's VLAD vectors in ``retrieval``.
        desc: progress bar label.
        exclude: per image, map image indices left out of its retrieval (None: none).
        own_features: the images are the map's own: an image with a marker in view takes its
            features from the placement's map instead of being rendered again.
        rendered: the set's renders with markers, kept between placements (None: render every
            image with a marker in view in the worker that localizes it).
        partial: where estimates are committed as they arrive (None: nowhere); the images it
            already holds (an interrupted run's) are neither rendered nor localized again.

    Returns:
        (Q, 4, 4) estimates (all NaN where localization failed) and the number of images
        actually localized.
    """
    Q = len(world_from_cam)
    keys = tb.view_keys(in_view, markers)
    todo = list(range(Q))
    est = np.full((Q, 4, 4), np.nan)
    if retrieval is not None and pmap.vlad is not None and base_estimates is not None and markers:
        qv = retrieval.image_vlads(set_name, base_features)
        # (an image whose marker-free render shows a tag takes the localizer's tag path, which
        # depends on the placement: never reused)
        same = [i for i in todo if not keys[i] and not len(base_features.image(i).tag_ids)
                and retrieval.unchanged(pmap.vlad, qv[i], pmap.changed, () if exclude is None else exclude[i])]
        est[same] = base_estimates[same]
        todo = sorted(set(todo) - set(same))
    localized = len(todo)
    prior = partial.done() if partial is not None else {}
    if prior:
        log.info("%s: resuming, %d of %d images already localized", desc, len(prior), localized)
        for i, e in prior.items():
            est[i] = e
        todo = [i for i in todo if i not in prior]
    with_markers = {}
    if rendered is not None and not own_features:
        with_markers = rendered.update(tb, world_from_cam, keys, markers, False, f"render {desc[len('localize '):]}",
                                       todo)

    def features(i: int):
        if not keys[i]:
            return base_features.image(i)
        return pmap.features.image(i) if own_features else with_markers.get(i)

    items = []
    for i in todo:
        item = (str(pmap.folder), lcfg, features(i), world_from_cam[i], list(markers) if keys[i] else [])
        items.append(item if exclude is None else item + (tuple(int(j) for j in exclude[i]),))
    for j, e in tb.run(localize_task, items, desc, len(prior)):
        est[todo[j]] = e
        if partial is not None:
            partial.add(todo[j], e)
    return est, localized



class PredictionKey(NamedTuple):
    """Names one prediction: the placement (method, run, budget k) and the image set."""

    method: str
    run: int
    k: int
    test_set: str


@dataclass(frozen=True, eq=False)
class PredictContext:
    """What every prediction of one evaluation shares.

    Attributes:
        tb: the testbed's imaging (and executor).
        map_base: marker-free map features.
        codebook: the VLAD codebook; ``codebook_key`` its cache key (it fixes the map).
        localizer: (localizer name, settings) (:func:`~markerplace.simulation.map_setup.localizer_spec`).
        imaging: the testbed's imaging config (part of the cache keys).
        cache_dir: ``predictions/`` and the temporary map folders go here.
        timings: ``map_with_markers`` and ``localize`` seconds are added.
        reuse: reuse the marker-free result where a placement cannot change it (exact).
        keep_renders: keep every render with markers in ``cache_dir/renders``
            (:class:`RenderStore`) and read back the ones earlier placements or runs made.
    """

    tb: TestbedImaging
    map_base: BaseImages
    codebook: object
    codebook_key: str
    localizer: tuple
    imaging: object
    cache_dir: Path
    timings: dict
    reuse: bool = True
    keep_renders: bool = True


def predict_placements(ctx: PredictContext, placements, sets: dict) -> dict:
    """Estimates of every image set against every placement's map, cached per (placement, set).

    Args:
        ctx: what the predictions share (:class:`PredictContext`).
        placements: :class:`~markerplace.simulation.marker_sets.PlacementRun` list; the marker-free
            one (``none``) first, so that the others can reuse its results. A placement with
            ``test_sets`` is localized on those sets only (``map`` is always localized).
        sets: name -> :class:`ImageSet`.

    Returns:
        :class:`PredictionKey` -> (Q, 4, 4) estimates, NaN where localization failed.
    """
    tb, map_base, codebook, cb_key, lcfg = ctx.tb, ctx.map_base, ctx.codebook, ctx.codebook_key, ctx.localizer
    imaging, cache_dir, timings = ctx.imaging, ctx.cache_dir, ctx.timings

    pred_dir = cache_dir / "predictions"
    timings.setdefault("map_with_markers", 0.0)
    timings.setdefault("localize", 0.0)
    predictions: dict[PredictionKey, np.ndarray] = {}

    name, settings = lcfg
    localizer = LOCALIZERS.lookup(name)
    conf = configure(localizer.default_conf, dict(settings))
    retrieval = None
    if ctx.reuse and localizer.replays_retrieval and map_base.world_from_cam.size:
        retrieval = Retrieval(codebook, map_base, conf.num_candidates)
    store = RenderStore(cache_dir / "renders") if ctx.keep_renders else None
    maps = PlacementMaps(tb, map_base, codebook, retrieval, store)
    rendered = {s.name: RenderedFeatures(store, s.base.key, s.condition) for s in sets.values()}
    reused = 0
    for p in placements:
        marker_arr = [(m.tag_id, m.size, np.asarray(m.world_from_marker)) for m in p.markers]
        pending = []
        for s in sets.values():
            if p.test_sets is not None and s.name not in p.test_sets and not s.own:
                continue
            # what it reads: the set's features, the in-view columns of its own markers (in the
            # set and the map), the map (cb_key) and settings; not the other placements' markers
            views = (tb.view_digest(s.base.in_view, p.markers), tb.view_digest(map_base.in_view, p.markers))
            key = cache.hash_of("prediction-v3", DRAWING_VERSION, cb_key, s.base.digest, views, s.world_from_cam,
                                marker_arr, lcfg, imaging) \
                if s.exclude is None else cache.hash_of("map-prediction-v3", DRAWING_VERSION, cb_key, s.base.digest, views,
                                                        s.world_from_cam, s.exclude, marker_arr, lcfg, imaging)
            est = load_prediction(pred_dir, key)
            if est is not None:
                predictions[PredictionKey(p.method, p.run, p.k, s.name)] = est
            else:
                pending.append((s, key))
        if not pending:
            continue
        t0 = time.perf_counter()
        with maps.built(p.markers, cache_dir / f"db_{cache.hash_of(cb_key, marker_arr)}",
                        f"map {p.method} k={p.k} run {p.run}") as pmap:
            timings["map_with_markers"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            for s, key in pending:
                partial = PartialPrediction(pred_dir, key)
                est, localized = localize_set(tb, pmap, p.markers, lcfg, s.world_from_cam, s.base.in_view,
                                              s.base.features, predictions.get(PredictionKey(NO_MARKERS, 0, 0, s.name)), retrieval,
                                              s.name, f"localize {s.name} {p.method} k={p.k} run {p.run}",
                                              s.exclude, s.own, rendered[s.name], partial)
                reused += len(est) - localized
                save_prediction(pred_dir, key, est, method=p.method, run=p.run, k=p.k, test_set=s.name,
                                localized=localized)
                partial.discard()
                predictions[PredictionKey(p.method, p.run, p.k, s.name)] = est
            timings["localize"] += time.perf_counter() - t0
    if reused:
        log.info("localize: %d images no placement's markers could change took the no-marker result", reused)
    return predictions
