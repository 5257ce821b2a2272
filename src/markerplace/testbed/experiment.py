"""Simulation testbed: render map and test images with a placement's markers, extract features,
build the map database and localize the test images, over a process pool.

Work is spread over a ``spawn`` process pool; each worker owns one GL context (a
:class:`~markerplace.render.renderer.Renderer` on the scene rebuilt from a
:class:`~markerplace.plan.observe.SceneSpec`).

Re-use across placements (renders are deterministic): an image whose view contains no marker of
a placement is identical to the no-marker image, so its features come from the *base* (no
marker) feature set, computed once. More generally an image only depends on the markers in its
view, so features are keyed by ``(image, markers in view)`` and shared between placements with
the same markers in that view (e.g. the nested OMP prefixes). "In view" is decided
conservatively on the no-marker depth: a marker counts when any of a grid of sample points on
its drawn quad (quiet zone included) projects into the image (with a pixel margin) and is not
behind the rendered surface (see :func:`markers_in_view`).

Queries are re-localized for every placement (the database differs); a query with no marker in
view re-uses its base features, others are re-rendered inside the localization task.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import shutil
from contextlib import ExitStack
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from ..geometry import Intrinsics, project_with_depth_lookup
from ..io_utils import atomic_path, write_npy
from ..localization.features import SIFT_DEFAULT, SiftConfig, extract_sift, lift_to_3d
from ..markers import Marker
from ..runtime.workers import default_workers, single_threaded_libraries, spawn_pool

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TestbedConfig:
    """Rendering and feature settings of the testbed.

    Attributes:
        intrinsics: camera of map and test images (paper: 600x450, 90 deg HFOV).
        sift: SIFT parameters (paper: OpenCV defaults for localization).
        max_depth: map features farther than this (metres) get no 3D point.
        visibility_margin_px: a marker sample up to this many pixels outside the image still
            counts as in view (conservative).
        occlusion_tolerance: metres of slack of the depth test of marker samples.
        visibility_grid: samples per side of the marker quad for the in-view test.
        workers: processes (0 = number of CPUs, at most 4; 1 = run in this process).
        chunksize: jobs handed to a worker at once.
    """

    __test__ = False

    intrinsics: Intrinsics = field(default_factory=Intrinsics)
    sift: SiftConfig = SIFT_DEFAULT
    max_depth: float = 10.0
    visibility_margin_px: float = 16.0
    occlusion_tolerance: float = 0.10
    visibility_grid: int = 7
    workers: int = 0
    chunksize: int = 4


# --- per-image features ------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ImageFeatures:
    """Features of one image.

    Attributes:
        keypoints: (K, 2) float32 pixel (x, y).
        descriptors: (K, 128) uint8 SIFT (OpenCV's values rounded).
        points_world: (K, 3) float32 world metres, NaN where depth gave no point.
        tag_ids: (T,) int32 detected tag ids.
        tag_corners: (T, 4, 2) float32 pixel corners, order TL, TR, BR, BL (as
            :func:`markerplace.localization.tags.detect_tags` reports them).
    """

    keypoints: np.ndarray
    descriptors: np.ndarray
    points_world: np.ndarray
    tag_ids: np.ndarray
    tag_corners: np.ndarray


@dataclass(frozen=True, eq=False)
class FeatureSet:
    """Features of N images in flat arrays: image i owns rows ``offsets[i]:offsets[i+1]`` (and
    tags ``tag_offsets[i]:tag_offsets[i+1]``). Saved as a folder of ``.npy`` files so workers can
    memory-map it."""

    keypoints: np.ndarray
    descriptors: np.ndarray
    points_world: np.ndarray
    offsets: np.ndarray
    tag_ids: np.ndarray
    tag_corners: np.ndarray
    tag_offsets: np.ndarray

    FIELDS = ("keypoints", "descriptors", "points_world", "offsets", "tag_ids", "tag_corners", "tag_offsets")

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def image(self, i: int) -> ImageFeatures:
        a, b = int(self.offsets[i]), int(self.offsets[i + 1])
        ta, tb = int(self.tag_offsets[i]), int(self.tag_offsets[i + 1])
        return ImageFeatures(np.asarray(self.keypoints[a:b]), np.asarray(self.descriptors[a:b]),
                             np.asarray(self.points_world[a:b]), np.asarray(self.tag_ids[ta:tb]),
                             np.asarray(self.tag_corners[ta:tb]))

    @classmethod
    def from_images(cls, images: Sequence[ImageFeatures]) -> "FeatureSet":
        counts = np.array([len(f.keypoints) for f in images], dtype=np.int64)
        tcounts = np.array([len(f.tag_ids) for f in images], dtype=np.int64)

        def cat(name, shape, dtype):
            arrs = [getattr(f, name) for f in images]
            return np.concatenate(arrs).astype(dtype) if arrs else np.zeros((0,) + shape, dtype)

        return cls(cat("keypoints", (2,), np.float32), cat("descriptors", (128,), np.uint8),
                   cat("points_world", (3,), np.float32), np.concatenate([[0], np.cumsum(counts)]),
                   cat("tag_ids", (), np.int32), cat("tag_corners", (4, 2), np.float32),
                   np.concatenate([[0], np.cumsum(tcounts)]))

    def with_images(self, updates: dict[int, ImageFeatures]) -> "FeatureSet":
        """A copy where image i is replaced by ``updates[i]``."""
        return FeatureSet.from_images([updates.get(i) or self.image(i) for i in range(len(self))])

    def save(self, folder: str | Path) -> None:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        for name in self.FIELDS:
            write_npy(folder / f"{name}.npy", np.ascontiguousarray(getattr(self, name)))

    @classmethod
    def load(cls, folder: str | Path, mmap: bool = False) -> "FeatureSet":
        folder = Path(folder)
        mode = "r" if mmap else None
        return cls(**{n: np.load(folder / f"{n}.npy", mmap_mode=mode, allow_pickle=False) for n in cls.FIELDS})

    @staticmethod
    def exists(folder: str | Path) -> bool:
        return all((Path(folder) / f"{n}.npy").exists() for n in FeatureSet.FIELDS)


# --- marker visibility -------------------------------------------------------------------------

def marker_samples(markers: Sequence[Marker], grid: int = 7) -> np.ndarray:
    """(M, grid*grid, 3) world points on each marker's drawn quad (quiet zone included)."""
    from ..render.tags import outer_size

    if not markers:
        return np.zeros((0, grid * grid, 3))
    u = np.linspace(-0.5, 0.5, grid)
    gu, gv = np.meshgrid(u, u)
    out = []
    for m in markers:
        s = outer_size(m.size)
        local = np.stack([gu.ravel() * s, gv.ravel() * s, np.zeros(grid * grid)], axis=1)
        out.append(local @ m.world_from_marker[:3, :3].T + m.world_from_marker[:3, 3])
    return np.asarray(out)


def markers_in_view(depth: np.ndarray, world_from_cam: np.ndarray, K: np.ndarray, samples: np.ndarray,
                    margin_px: float, tolerance: float) -> np.ndarray:
    """Which markers may change this image (conservative).

    Args:
        depth: (H, W) planar depth rendered WITHOUT markers, metres (0 = nothing hit).
        world_from_cam: (4, 4) camera pose.
        K: (3, 3) intrinsics.
        samples: (M, S, 3) world sample points per marker (:func:`marker_samples`).
        margin_px: samples up to this far outside the image count as inside.
        tolerance: a sample is hidden only when the surface there is closer than its depth
            minus ``tolerance`` metres.

    Returns:
        (M,) bool: some sample is in front of the camera, inside the (enlarged) image, and not
        hidden (samples outside the image proper are never considered hidden).
    """
    M, S, _ = samples.shape
    if M == 0:
        return np.zeros(0, bool)
    H, W = depth.shape
    uv, z, surface = project_with_depth_lookup(depth, world_from_cam, K, samples.reshape(-1, 3))
    u, v = uv[:, 0], uv[:, 1]
    near_image = (z > 1e-3) & (u > -0.5 - margin_px) & (u < W - 0.5 + margin_px) & (v > -0.5 - margin_px) & (v < H - 0.5 + margin_px)
    hidden = near_image & (surface > 0) & (surface < z - tolerance)
    return (near_image & ~hidden).reshape(M, S).any(axis=1)


def marker_key(marker: Marker) -> tuple:
    """Hashable identity of a marker's appearance: id, size and pose (rounded to 0.1 mm)."""
    return (int(marker.tag_id), round(float(marker.size), 6),
            tuple(np.round(np.asarray(marker.world_from_marker, float)[:3].ravel(), 4)))


# --- worker side -------------------------------------------------------------------------------

_W: dict = {}


def _worker_init(scene_spec, config: TestbedConfig, samples: np.ndarray, localize_args: dict | None) -> None:
    from ..render.renderer import Renderer

    if mp.current_process().name != "MainProcess":
        single_threaded_libraries()  # parallelism is across worker processes
    _W["renderer"] = Renderer(scene_spec.load(), config.intrinsics)
    _W["config"] = config
    _W["samples"] = samples
    _W["markers_key"] = ()
    _W["localize_args"] = localize_args or {}
    _W["db_folder"] = None


def _worker_close() -> None:
    r = _W.pop("renderer", None)
    if r is not None:
        r.close()
    _W.clear()


def _render_extract(world_from_cam: np.ndarray, markers: Sequence[Marker], want_visibility: bool):
    from ..localization.tags import detect_tags

    config: TestbedConfig = _W["config"]
    renderer = _W["renderer"]
    key = tuple(marker_key(m) for m in markers)
    if key != _W["markers_key"]:
        renderer.set_markers(list(markers))
        _W["markers_key"] = key
    res = renderer.render(world_from_cam, rgb=True, depth=True, normal=False)
    K = config.intrinsics.K
    kp, desc = extract_sift(res.rgb, config.sift)
    pts, valid = lift_to_3d(kp, res.depth, K, world_from_cam, max_depth=config.max_depth)
    pts = np.where(valid[:, None], pts, np.nan)
    dets = detect_tags(res.rgb)
    ids = np.array([d.tag_id for d in dets], dtype=np.int32)
    corners = np.array([np.asarray(d.corners, dtype=np.float32).reshape(4, 2) for d in dets], dtype=np.float32).reshape(-1, 4, 2)
    feats = ImageFeatures(kp.astype(np.float32), np.clip(np.rint(desc), 0, 255).astype(np.uint8),
                          pts.astype(np.float32), ids, corners)
    vis = None
    if want_visibility:
        vis = markers_in_view(res.depth, world_from_cam, K, _W["samples"], config.visibility_margin_px,
                              config.occlusion_tolerance)
    return feats, vis


def _render_job(job):
    """(key, world_from_cam, markers, want_visibility, map_only) -> (key, ImageFeatures, (U,) bool | None).

    ``map_only`` drops features without a 3D point (the map database keeps only those).
    """
    key, world_from_cam, markers, want_vis, map_only = job
    feats, vis = _render_extract(world_from_cam, markers, want_vis)
    if map_only:
        keep = np.isfinite(feats.points_world).all(axis=1)
        feats = ImageFeatures(feats.keypoints[keep], feats.descriptors[keep], feats.points_world[keep],
                              feats.tag_ids, feats.tag_corners)
    return key, feats, vis


def save_map(folder: str | Path, features: FeatureSet, world_from_cam: np.ndarray, markers: Sequence[Marker],
             codebook_centres: np.ndarray) -> None:
    """Write everything a worker needs to build one placement's map database into ``folder``:
    the features, (N, 4, 4) map poses, the markers (JSON) and the (C, 128) VLAD centres."""
    from ..io_utils import write_json

    folder = Path(folder)
    features.save(folder)
    write_npy(folder / "poses.npy", np.asarray(world_from_cam, np.float64))
    write_npy(folder / "codebook.npy", np.asarray(codebook_centres, np.float32))
    write_json(folder / "markers.json", [m.to_json() for m in markers])


def load_map_database(folder: str | Path):
    """Build the :class:`~markerplace.localization.database.MapDatabase` saved by :func:`save_map`."""
    import json

    from ..localization.database import MapDatabase
    from ..localization.vlad import VladCodebook
    from ..markers import marker_from_json

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
    from ..localization.tags import TagDetection

    return [TagDetection(int(t), np.asarray(c, np.float64), np.asarray(c, np.float64).mean(axis=0))
            for t, c in zip(feats.tag_ids, feats.tag_corners)]


def localize_features(localizer, feats: ImageFeatures):
    """Localize precomputed query features (extracted once, reused across placements)."""
    return localizer.localize_features(feats.keypoints, feats.descriptors.astype(np.float32), _tag_detections(feats))


def _localize_job(job):
    """(key, db_folder, features | None, world_from_cam, markers) -> (key, (4, 4) estimate, NaN on failure).

    With ``features`` None the query is first rendered here with ``markers``.
    """
    from ..localization.localizer import Localizer

    key, folder, feats, world_from_cam, markers = job
    if _W.get("db_folder") != folder:
        _W["localizer"] = None
        db = load_map_database(folder)
        _W["localizer"] = Localizer(db, _W["config"].intrinsics.K, _W["localize_args"]["localizer"])
        _W["db_folder"] = folder
    if feats is None:
        feats, _ = _render_extract(world_from_cam, markers, False)
    res = localize_features(_W["localizer"], feats)
    est = np.full((4, 4), np.nan) if res.world_from_cam is None else np.asarray(res.world_from_cam, float)
    return key, est


# --- main side ---------------------------------------------------------------------------------


class Testbed:
    """Owns the worker pool. Use as a context manager.

    Args:
        scene_spec: how workers rebuild the scene.
        config: rendering / feature settings.
        union_markers: every marker any evaluated placement uses (for the in-view test).
        progress: tqdm bars.
        localize_args: picklable settings the workers need to build databases and localize
            (passed to :mod:`markerplace.testbed.experiment` worker functions).
    """

    def __init__(self, scene_spec, config: TestbedConfig, union_markers: Sequence[Marker],
                 progress: bool = True, localize_args: dict | None = None):
        self.scene_spec = scene_spec
        self.config = config
        self.union = list(union_markers)
        self.union_index = {marker_key(m): i for i, m in enumerate(self.union)}
        self.samples = marker_samples(self.union, config.visibility_grid)
        self.progress = progress
        self.localize_args = localize_args or {}
        self.workers = default_workers(config.workers)
        self._pool = None
        self._stack = ExitStack()

    def __enter__(self) -> "Testbed":
        initargs = (self.scene_spec, self.config, self.samples, self.localize_args)
        if self.workers <= 1:
            _worker_init(*initargs)
        else:
            self._pool = self._stack.enter_context(spawn_pool(self.workers, _worker_init, initargs))
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._stack.__exit__(*exc)
            self._pool = None
        else:
            _worker_close()

    def _run(self, func: Callable, jobs: list, desc: str) -> Iterable:
        from tqdm import tqdm

        bar = tqdm(total=len(jobs), desc=desc, unit="img", disable=not self.progress, leave=False)
        try:
            if self._pool is None:
                for job in jobs:
                    yield func(job)
                    bar.update()
            else:
                for r in self._pool.imap_unordered(func, jobs, chunksize=self.config.chunksize):
                    yield r
                    bar.update()
        finally:
            bar.close()

    def render_features(self, world_from_cam: np.ndarray, indices: Sequence[int], markers: Sequence[Marker],
                        want_visibility: bool, map_only: bool, desc: str) -> dict[int, tuple[ImageFeatures, np.ndarray | None]]:
        """Render images ``indices`` of ``world_from_cam`` (N, 4, 4) with ``markers`` and extract
        features; with ``want_visibility`` also the (U,) in-view mask of the union markers
        (meaningful only for marker-free renders); ``map_only`` keeps only features with a 3D
        point."""
        jobs = [(int(i), world_from_cam[i], list(markers), want_visibility, map_only) for i in indices]
        return {k: (f, v) for k, f, v in self._run(_render_job, jobs, desc)}

    def localize(self, jobs: list, desc: str) -> dict[int, np.ndarray]:
        """Run localization jobs ``(key, db_folder, features|None, world_from_cam, markers)``;
        returns key -> (4, 4) estimate (all NaN on failure)."""
        return {k: T for k, T in self._run(_localize_job, jobs, desc)}

    def view_keys(self, visibility: np.ndarray, markers: Sequence[Marker]) -> list[tuple[int, ...]]:
        """Per image: sorted union indices of ``markers`` in view, from the (N, U) base mask."""
        idx = np.array([self.union_index[marker_key(m)] for m in markers], dtype=np.int64)
        if len(idx) == 0:
            return [()] * len(visibility)
        sub = visibility[:, idx]
        return [tuple(sorted(idx[row].tolist())) for row in sub]


def clear_folder(folder: str | Path) -> None:
    """Remove a temporary database folder (ignore if missing)."""
    shutil.rmtree(folder, ignore_errors=True)


# --- the experiment loop -----------------------------------------------------------------------

def _visibility_job(job):
    """(key, world_from_cam) -> (key, (U,) bool) from a marker-free depth render."""
    key, world_from_cam = job
    config: TestbedConfig = _W["config"]
    renderer = _W["renderer"]
    if _W["markers_key"] != ():
        renderer.set_markers([])
        _W["markers_key"] = ()
    depth = renderer.render(world_from_cam, rgb=False, depth=True, normal=False).depth
    return key, markers_in_view(depth, world_from_cam, config.intrinsics.K, _W["samples"],
                                config.visibility_margin_px, config.occlusion_tolerance)


class BaseImages:
    """Marker-free features and the (N, U) union-marker in-view mask of one image set, cached
    on disk in ``folder`` (features keyed without markers, the mask keyed with the union)."""

    def __init__(self, testbed: Testbed, world_from_cam: np.ndarray, folder: Path, key: str, map_only: bool,
                 name: str):
        from ..runtime import cache

        self.folder = Path(folder)
        from dataclasses import replace

        feat_key = cache.hash_of(key, map_only, replace(testbed.config, workers=0, chunksize=0))
        vis_key = cache.hash_of(feat_key, testbed.samples, testbed.config.visibility_margin_px,
                                testbed.config.occlusion_tolerance)
        feat_dir, vis_path = self.folder / "features", self.folder / "visibility.npy"
        vis = None
        cached = cache.load_fresh(feat_dir, feat_key, FeatureSet.load) if FeatureSet.exists(feat_dir) else None
        if cached is not None:
            self.features = cached
            log.info("%s: reusing marker-free features in %s", name, feat_dir)
        else:
            res = testbed.render_features(world_from_cam, range(len(world_from_cam)), [], True, map_only, f"{name} (no markers)")
            self.features = FeatureSet.from_images([res[i][0] for i in range(len(world_from_cam))])
            self.features.save(feat_dir)
            cache.mark_done(feat_dir, feat_key)
            vis = np.stack([res[i][1] for i in range(len(world_from_cam))]) if len(world_from_cam) else None
        if vis is None:
            vis = cache.load_fresh(vis_path, vis_key, lambda p: np.load(p, allow_pickle=False))
            cached_vis = vis is not None
        else:
            cached_vis = False
        if not cached_vis:
            if vis is None:  # features cached, markers changed: depth-only renders
                jobs = [(i, world_from_cam[i]) for i in range(len(world_from_cam))]
                got = dict(testbed._run(_visibility_job, jobs, f"{name} (marker visibility)"))
                vis = np.stack([got[i] for i in range(len(world_from_cam))]).reshape(len(world_from_cam), -1)
            write_npy(vis_path, vis)
            cache.mark_done(vis_path, vis_key)
        self.visibility = vis.reshape(len(world_from_cam), len(testbed.union))


def _load_errors(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(t_err, r_err) of a cached ``results_<key>.npz``."""
    with np.load(path, allow_pickle=False) as f:
        return f["t_err"], f["r_err"]


def _localizer_config(config):
    from ..localization.localizer import LocalizerConfig

    return LocalizerConfig(use_tags=config.use_tags, tag_corners=config.tag_corners, seed=config.seed)


def run_evaluation(scene_spec, plan_config, config, out_dir: str | Path, placements_dir: str | Path | None = None,
                   testbed_config: TestbedConfig | None = None, progress: bool = True) -> list[dict]:
    """Run the paper's experiments and write every output into ``out_dir``.

    Args:
        scene_spec: :class:`~markerplace.plan.observe.SceneSpec` of the scene.
        plan_config: :class:`~markerplace.plan.planner.PlanConfig` (discretization, scoring, v, ...).
        config: :class:`~markerplace.testbed.evaluation.EvaluateConfig`.
        out_dir: run directory: planner artifacts (``plan/``), caches (``cache/``) and the
            outputs ``recall.csv``, ``query_errors.npz``, ``tables.md``, ``recall_vs_k.png``,
            ``timings.json``, ``config.json``, ``test_poses_<set>.npz``.
        placements_dir: folder of ``placement.json`` files evaluated as extra methods.
        testbed_config: rendering settings (default: the plan's intrinsics and workers).
        progress: tqdm bars.

    Returns:
        The recall rows (see :mod:`markerplace.report.tables`).

    Resume: per-placement query results are cached (``cache/results_<hash>.npz``); an
    interrupted run continues where it stopped.
    """
    import time
    from dataclasses import replace

    from ..runtime import cache
    from . import evaluation as ev
    from ..io_utils import write_json, write_npz
    from ..markers import load_markers
    from ..plan.planner import prepare, validate

    t_all = time.perf_counter()
    ev.validate_evaluate_config(config)
    validate(plan_config)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cache_dir = out / "cache"
    timings: dict[str, float] = {}
    if testbed_config is None:
        testbed_config = TestbedConfig(intrinsics=plan_config.observe.intrinsics, workers=plan_config.observe.workers)

    t0 = time.perf_counter()
    data = prepare(scene_spec, plan_config, out / "plan", progress=progress)
    timings["plan_prepare"] = time.perf_counter() - t0
    disc = data.disc
    map_poses = np.asarray(disc.world_from_cam, float)
    scene = scene_spec.load()
    scene_name = scene.name
    tb_key_cfg = replace(testbed_config, workers=0, chunksize=0)  # results do not depend on these

    t0 = time.perf_counter()
    extra = {}
    if placements_dir is not None:
        from ..scene.worldframe import markers_to_internal, world_offset

        # placement files are in the user's (file) frame; the scene may be recentred
        extra = {name: markers_to_internal(load_markers(p), world_offset(scene))
                 for name, p in ev.find_placement_files(placements_dir).items()}
    placements = ev.build_placements(data, plan_config.placement, config, extra)
    timings["placements"] = time.perf_counter() - t0
    log.info("evaluating %d marker sets: %s", len(placements),
             ", ".join(sorted({p.method for p in placements})))

    t0 = time.perf_counter()
    layer = {int(st): k for k, st in enumerate(disc.planned_storeys)}
    is_free = ev.free_space_checker(disc.occupancy, disc.grid_origin, disc.grid_resolution, config.min_clearance,
                                    np.array([layer[int(st)] for st in disc.pose_storey], dtype=np.int64))
    test_poses = {}
    base_key = cache.hash_of("testbed-v1", cache.scene_hash(scene), map_poses)
    for ts in config.test_sets:  # a test set's seed does not depend on which other sets run
        tcfg = ev.TestPoseConfig(num=config.tests, mode=ts, seed=config.pose_seed + 1000 * ev.TEST_SETS.index(ts),
                                 min_clearance=config.min_clearance)
        path = out / f"test_poses_{ts}.npz"
        key = cache.hash_of("test-poses-v1", base_key, data.base_score, tcfg, plan_config.discretize.grid_spacing)
        loaded = cache.load_fresh(path, key, ev.TestPoses.load)
        if loaded is not None:
            test_poses[ts] = loaded
        else:
            test_poses[ts] = ev.sample_test_poses(map_poses, data.base_score, plan_config.discretize.grid_spacing, tcfg, is_free)
            test_poses[ts].save(path)
            cache.mark_done(path, key)
    timings["test_poses"] = time.perf_counter() - t0

    union: dict = {}
    for p in placements:
        for m in p.markers:
            union.setdefault(marker_key(m), m)
    lcfg = _localizer_config(config)
    results: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    with Testbed(scene_spec, testbed_config, list(union.values()), progress, {"localizer": lcfg}) as tb:
        t0 = time.perf_counter()
        map_base = BaseImages(tb, map_poses, cache_dir / "map_base", base_key, True, "map")
        timings["map_no_markers"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        codebook_path = cache_dir / "vlad_codebook.npz"
        cb_key = cache.hash_of("vlad-v1", base_key, tb_key_cfg, config.vlad_clusters, config.seed)
        from ..localization.vlad import VladCodebook

        codebook = cache.load_fresh(codebook_path, cb_key, VladCodebook.load)
        if codebook is None:
            codebook = VladCodebook.train(map_base.features.descriptors.astype(np.float32),
                                          num_clusters=config.vlad_clusters, seed=config.seed)
            codebook.save(codebook_path)
            cache.mark_done(codebook_path, cb_key)
        timings["vlad_codebook"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        query_base = {ts: BaseImages(tb, test_poses[ts].world_from_cam, cache_dir / f"query_base_{ts}",
                                     cache.hash_of(base_key, test_poses[ts].world_from_cam), False, f"queries {ts}")
                      for ts in config.test_sets}
        timings["queries_no_markers"] = time.perf_counter() - t0

        timings["map_with_markers"] = 0.0
        timings["localize"] = 0.0
        feature_cache: dict[tuple, ImageFeatures] = {}
        for p in placements:
            marker_arr = [(m.tag_id, m.size, np.asarray(m.world_from_marker)) for m in p.markers]
            pending = []
            for ts in config.test_sets:
                rkey = cache.hash_of("results-v1", cb_key, test_poses[ts].world_from_cam, marker_arr, lcfg, tb_key_cfg)
                rpath = cache_dir / f"results_{rkey}.npz"
                got = cache.load_fresh(rpath, rkey, _load_errors)
                if got is not None:
                    results[(p.method, p.run, p.k, ts)] = got
                else:
                    pending.append((ts, rkey, rpath))
            if not pending:
                continue
            t0 = time.perf_counter()
            keys = tb.view_keys(map_base.visibility, p.markers)
            need = [i for i, k in enumerate(keys) if k and (i, k) not in feature_cache]
            if need:
                got = tb.render_features(map_poses, need, p.markers, False, True, f"map {p.method} k={p.k} run {p.run}")
                for i in need:
                    feature_cache[(i, keys[i])] = got[i][0]
            used = {(i, k) for i, k in enumerate(keys) if k}
            for stale in [c for c in feature_cache if c not in used]:
                del feature_cache[stale]
            feats = map_base.features.with_images({i: feature_cache[(i, k)] for i, k in enumerate(keys) if k}) \
                if used else map_base.features
            db_dir = cache_dir / f"db_{cache.hash_of(cb_key, marker_arr)}"
            save_map(db_dir, feats, map_poses, p.markers, codebook.centres)
            timings["map_with_markers"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            try:
                for ts, rkey, rpath in pending:
                    tp = test_poses[ts]
                    qkeys = tb.view_keys(query_base[ts].visibility, p.markers)
                    jobs = [(i, str(db_dir), None if qkeys[i] else query_base[ts].features.image(i),
                             tp.world_from_cam[i], list(p.markers) if qkeys[i] else []) for i in range(len(tp))]
                    est_d = tb.localize(jobs, f"localize {ts} {p.method} k={p.k} run {p.run}")
                    est = np.stack([est_d[i] for i in range(len(tp))])
                    t_err, r_err = ev.pose_errors_batch(est, tp.world_from_cam)
                    write_npz(rpath, est=est, t_err=t_err, r_err=r_err)
                    cache.mark_done(rpath, rkey, method=p.method, run=p.run, k=p.k, test_set=ts)
                    results[(p.method, p.run, p.k, ts)] = (t_err, r_err)
            finally:
                clear_folder(db_dir)
            timings["localize"] += time.perf_counter() - t0

    t0 = time.perf_counter()
    rows = write_outputs(out, scene_name, placements, results, test_poses, data.base_score, config, plan_config)
    timings["report"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    write_json(out / "timings.json", {k: round(v, 3) for k, v in timings.items()})
    log.info("stage seconds: %s", ", ".join(f"{k} {v:.1f}" for k, v in timings.items()))
    return rows


def write_outputs(out: Path, scene_name: str, placements, results: dict, test_poses: dict, base_score: np.ndarray,
                  config, plan_config) -> list[dict]:
    """recall.csv, query_errors.npz, tables.md, recall_vs_k.png and config.json."""
    from . import evaluation as ev
    from ..runtime.cache import config_dict
    from ..io_utils import write_json, write_npz
    from ..report.figures import recall_vs_k
    from ..report.paired import paired_markdown
    from ..report.tables import recall_curves, tables_markdown, write_recall_csv

    labels = [ev.threshold_label(t) for t in config.thresholds]
    rows = []
    arrays: dict[str, np.ndarray] = {}
    for ts in config.test_sets:
        keys = [(p.method, p.run, p.k) for p in placements if (p.method, p.run, p.k, ts) in results]
        for method, run, k in keys:
            t_err, r_err = results[(method, run, k, ts)]
            for label, (tm, rm) in zip(labels, config.thresholds):
                rows.append(dict(scene=scene_name, method=method, run=run, k=k, test_set=ts, threshold=label,
                                 recall=ev.recall(t_err, r_err, tm, rm), n_tests=len(t_err)))
        arrays[f"{ts}_method"] = np.array([k[0] for k in keys], dtype=str)
        arrays[f"{ts}_run"] = np.array([k[1] for k in keys], dtype=np.int64)
        arrays[f"{ts}_k"] = np.array([k[2] for k in keys], dtype=np.int64)
        arrays[f"{ts}_t_err"] = np.array([results[k + (ts,)][0] for k in keys]).reshape(len(keys), -1)
        arrays[f"{ts}_r_err"] = np.array([results[k + (ts,)][1] for k in keys]).reshape(len(keys), -1)
        arrays[f"{ts}_world_from_cam"] = test_poses[ts].world_from_cam
        arrays[f"{ts}_score"] = np.asarray(base_score)[test_poses[ts].source_index]
    write_recall_csv(out / "recall.csv", rows)
    write_npz(out / "query_errors.npz", **arrays)
    main = ev.threshold_label(ev.MAIN_THRESHOLD) if ev.MAIN_THRESHOLD in config.thresholds else labels[0]
    ks = sorted(set(config.ks))
    md = tables_markdown(rows, ks, main, labels)
    t_main, r_main = next(t for t in config.thresholds if ev.threshold_label(t) == main)
    hits = {ts: {(m, run, k): ev.hit_mask(*res, t_main, r_main)
                 for (m, run, k, t), res in results.items() if t == ts} for ts in config.test_sets}
    md += paired_markdown(hits, ks, main, seed=config.seed)
    with atomic_path(out / "tables.md") as tmp:
        tmp.write_text(md)
    ts0 = config.test_sets[0]
    curves = recall_curves(rows, scene_name, ts0, main, ks)
    if curves:
        recall_vs_k(out / "recall_vs_k.png", [0] + ks, curves, f"{scene_name}: recall at {main} ({ts0} test set)")
    write_json(out / "config.json", {"evaluate": config_dict(config), "plan": config_dict(plan_config)})
    return rows
