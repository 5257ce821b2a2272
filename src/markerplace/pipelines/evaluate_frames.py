"""``markerplace evaluate --frames DIR``: the testbed on real photographs, read top to bottom in
:func:`run_frames_evaluation`:

1. the frames (:func:`markerplace.scan.frames.open_frameset`) and the fixed block split into map
   and query frames (:mod:`markerplace.testbed.frames.split`);
2. the plan at the map frames' own poses from their own colour and depth
   (:func:`markerplace.pipelines.plan_frames.prepare_frames`; the query frames are never seen by
   any placement method);
3. the marker sets: none and the placement methods (random and uniform with their runs), as the
   simulation testbed makes them (:func:`markerplace.simulation.marker_sets.build_placements`);
4. every image's features once (:mod:`markerplace.testbed.frames.store`): the real frames with
   each placement's tags composited in, and renders of the fused surface at the same poses;
5. per map kind and placement, the map database and the query frames localized against it
   (:mod:`markerplace.testbed.frames.localize`);
6. recall, paired intervals and the gap table (:mod:`markerplace.testbed.frames.report`).

Every stage is cached in the run folder; an interrupted run resumes.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from markerplace.imaging.config import ImagingConfig
from markerplace.imaging.engine import marker_key
from markerplace.localization.sift import SIFT_DEFAULT
from markerplace.pipelines.plan_frames import prepare_frames
from markerplace.plan.frames.surface import FUSED_NAME
from markerplace.report.html import esc, img, jpeg_uri, markdown_to_html, write_page
from markerplace.runtime import run_folder
from markerplace.runtime.atomic_io import atomic_path, write_json, write_npz
from markerplace.runtime.cache import config_dict, hash_of
from markerplace.runtime.executor import make_executor
from markerplace.scene.spec import SceneSpec
from markerplace.scene.worldframe import world_offset
from markerplace.simulation import metrics
from markerplace.simulation.map_setup import localizer_spec
from markerplace.simulation.marker_sets import build_placements
from markerplace.testbed.config import validate_evaluate_config
from markerplace.testbed.frames.config import FramesEvalConfig
from markerplace.testbed.frames.frame_features import REAL, RENDER, FrameJobSpec, FrameWorker, frame_in_view, frame_job, real_image
from markerplace.testbed.frames.localize import build_map, localize_queries, markers_in_view_of, train_codebook
from markerplace.testbed.frames.report import frames_markdown, recall_rows, set_label
from markerplace.testbed.frames.split import block_split
from markerplace.testbed.frames.store import FeatureStore, image_key
from markerplace.testbed.reporting.tables import write_recall_csv

log = logging.getLogger(__name__)

__all__ = ["FRAMES_UNSUPPORTED", "FramesResult", "run_frames_evaluation"]

FRAMES_UNSUPPORTED = ("expected-recall",)
"""Placement methods not run on frames: ``expected-recall`` fits its success model on renders of
the scene at the plan's poses (the simulation testbed), which a frame sequence does not have."""

_IMAGE_KIND = {"frames": REAL, "render": RENDER}
_LOOSE = (0.10, 10.0)


@dataclass(frozen=True)
class FramesResult:
    """What :func:`run_frames_evaluation` made: the run folder, the recall rows, the markdown."""

    out: Path
    rows: list
    markdown: str


def _shifted(world_from_cam: np.ndarray, offset: np.ndarray) -> np.ndarray:
    out = np.array(world_from_cam, float)
    out[:3, 3] -= offset
    return out


def _surface_key(path: Path) -> tuple:
    st = path.stat()
    return str(path.resolve()), st.st_size, st.st_mtime_ns


def run_frames_evaluation(fs, plan_config, config, frames_config: FramesEvalConfig, out: str | Path,
                          mesh: str | Path | None = None, progress: bool = True) -> FramesResult:
    """Evaluate placements on a real RGB-D sequence and write every output into ``out``.

    Args:
        fs: the :class:`~markerplace.scan.frameset.FrameSet` (world z up).
        plan_config: :class:`~markerplace.plan.config.PlanConfig` (its camera is replaced by the
            frames' intrinsics).
        config: :class:`~markerplace.testbed.config.EvaluateConfig` (methods, runs, ks, seed,
            thresholds, localizer).
        frames_config: the split, map kinds and compositing.
        out: run folder: ``recall.csv``, ``tables.md``, ``query_errors.npz``, ``report.html``,
            ``config.json``, ``split.json`` and the caches (``plan/``, ``cache/``).
        mesh: a mesh for the candidate spots and the renders instead of the surface fused from
            the map frames.
    """
    t_all = time.perf_counter()
    validate_evaluate_config(config)
    frames_config.validate()
    out = Path(out)
    run_folder.make_dirs(out)
    ks = sorted(set(config.study.ks))
    skipped = [m for m in config.study.methods if m in FRAMES_UNSUPPORTED]
    if skipped:
        log.info("evaluate --frames: %s not run (%s)", ", ".join(skipped), FRAMES_UNSUPPORTED_REASON)
    study = replace(config.study, methods=tuple(m for m in config.study.methods if m not in FRAMES_UNSUPPORTED))
    config = replace(config, study=study)
    map_idx, query_idx = block_split(len(fs.frames), frames_config.split)
    write_json(out / "split.json", {"map_frames": [fs.frames[i].name for i in map_idx],
                                    "query_frames": [fs.frames[i].name for i in query_idx],
                                    "split": config_dict(frames_config.split)})
    log.info("frames: %d map frames, %d query frames (blocks of %d, gap %d)", len(map_idx), len(query_idx),
             frames_config.split.block, frames_config.split.gap)
    plan_config = replace(plan_config, imaging=replace(plan_config.imaging, camera=fs.intrinsics))
    data = prepare_frames(fs, map_idx, plan_config, out / "plan", mesh=mesh, progress=progress, k=max(ks))
    placements = build_placements(data, plan_config.placement, config)
    log.info("evaluating %d marker sets: %s", len(placements), ", ".join(sorted({p.method for p in placements})))
    surface_path = Path(mesh) if mesh is not None else out / "plan" / FUSED_NAME
    surface = SceneSpec(str(surface_path), up="z" if mesh is None else None, unit_scale=1.0 if mesh is None else None)
    # the plan (markers) and the renders are in the surface's internal frame: so are the poses here
    offset = world_offset(surface.load())
    fs = replace(fs, frames=tuple(replace(r, world_from_cam=_shifted(r.world_from_cam, offset)) for r in fs.frames))
    imaging = ImagingConfig(camera=fs.intrinsics, sift=SIFT_DEFAULT, max_depth=plan_config.imaging.max_depth)
    spec = FrameJobSpec(fs, surface, imaging, frames_config.composite, config.seed)
    poses = np.array([r.world_from_cam for r in fs.frames])
    settings_key = hash_of("frames-store-v1", str(Path(fs.root).resolve()), [r.name for r in fs.frames], poses,
                           imaging, frames_config.composite, config.seed, _surface_key(surface_path))
    store = FeatureStore(out / "cache" / "features", settings_key)
    union = list({marker_key(m): m for p in placements for m in p.markers}.values())
    size = (fs.intrinsics.width, fs.intrinsics.height)
    in_view = {}
    for f in np.r_[map_idx, query_idx]:
        mask = frame_in_view(poses[f], imaging.camera.K, size, union)
        in_view.update({(int(f), marker_key(m)): bool(v) for m, v in zip(union, mask)})
    query_kinds = {"frames": (REAL,), "render": (REAL, RENDER) if frames_config.gap else (REAL,)}
    keys = []
    for map_kind in frames_config.maps:
        kind = _IMAGE_KIND[map_kind]
        for p in placements:
            keys += [image_key(kind, f, markers_in_view_of(in_view, f, p.markers)) for f in map_idx]
            keys += [image_key(q, f, markers_in_view_of(in_view, f, p.markers))
                     for q in query_kinds[map_kind] for f in query_idx]
        keys += [image_key(kind, f, ()) for f in map_idx]
    localizer = localizer_spec(config.localization, config.seed)
    errors: dict = {}
    with make_executor(plan_config.runtime) as executor:
        job = frame_job(spec)
        store.compute(keys, executor, job, "images", progress)
        for map_kind in frames_config.maps:
            kind = _IMAGE_KIND[map_kind]
            codebook = train_codebook(store, kind, map_idx, config.localization.vlad_clusters, config.seed,
                                      out / "cache" / f"vlad_{map_kind}.npz")
            for p in placements:
                folder = build_map(store, kind, map_idx, poses[map_idx], p.markers, in_view, codebook,
                                   out / "cache" / "maps")
                for q in query_kinds[map_kind]:
                    label = set_label(q, map_kind)
                    est = localize_queries(store, folder, q, query_idx, poses[query_idx], p.markers, in_view, localizer,
                                           executor, job, out / "cache" / "localized", progress,
                                           f"{label} {p.method} k={p.k} run {p.run}")
                    errors[(p.method, p.run, p.k, label)] = metrics.pose_errors_batch(est, poses[query_idx])
    rows = recall_rows(fs.root.name, errors, config.thresholds)
    write_recall_csv(out / "recall.csv", rows)
    write_npz(out / "query_errors.npz", query_frames=np.array([fs.frames[i].name for i in query_idx]),
              keys=np.array(["|".join(map(str, k)) for k in errors]),
              t_err=np.array([v[0] for v in errors.values()]), r_err=np.array([v[1] for v in errors.values()]))
    main = metrics.main_threshold(config.thresholds)
    labels = [metrics.threshold_label(t) for t in config.thresholds]

    def hits_at(th):
        out_: dict = {}
        for (m, r, k, s), (t_err, r_err) in errors.items():
            out_.setdefault(s, {})[(m, r, k)] = metrics.hit_mask(t_err, r_err, *th)
        return out_

    header = [f"- frames: `{fs.root.name}` ({fs.format} layout, {len(fs.frames)} frames, "
              f"{fs.intrinsics.width}x{fs.intrinsics.height})",
              f"- split: {len(map_idx)} map frames, {len(query_idx)} query frames (blocks of {frames_config.split.block}, "
              f"gap {frames_config.split.gap}, map every {frames_config.split.map_step}, query every "
              f"{frames_config.split.query_step}); the plan saw the map frames only",
              f"- candidates: {data.num_candidates}; methods: {', '.join(study.methods)}; runs: {study.runs}; "
              f"k: {', '.join(map(str, ks))}; seed {config.seed}"
              + (f"; not run: {', '.join(skipped)} ({FRAMES_UNSUPPORTED_REASON})" if skipped else "")]
    md = frames_markdown(fs.root.name, rows, hits_at(main), hits_at(_LOOSE), ks, metrics.threshold_label(main),
                         metrics.threshold_label(_LOOSE), labels, header, config.seed)
    with atomic_path(out / "tables.md") as tmp:
        tmp.write_text(md)
    write_json(out / "config.json", {"evaluate": config_dict(config), "plan": config_dict(plan_config),
                                     "frames": config_dict(frames_config), "frames_root": str(fs.root),
                                     "format": fs.format})
    _write_report(out, fs, spec, placements, query_idx, in_view, md, frames_config.sheet)
    log.info("evaluate --frames: %.0f s", time.perf_counter() - t_all)
    return FramesResult(out, rows, md)


FRAMES_UNSUPPORTED_REASON = "its success model is fitted on renders at the plan's poses"


def _write_report(out: Path, fs, spec: FrameJobSpec, placements, query_idx, in_view: dict, md: str, count: int) -> None:
    """report.html: the tables and a sheet of query frames with the largest placement's tags
    composited in, so a person can judge the compositing."""
    ranked = sorted((p for p in placements if p.markers), key=lambda p: (p.method != "omp", -p.k, p.method, p.run))
    shown = next((p for p in ranked if any(markers_in_view_of(in_view, f, p.markers) for f in query_idx)), None)
    figures = []
    if shown is not None and count > 0:
        worker = FrameWorker(spec)
        seen = [f for f in query_idx if markers_in_view_of(in_view, f, shown.markers)]
        for f in seen[:: max(1, len(seen) // count)][:count]:
            rgb, _, stats = real_image(worker, int(f), markers_in_view_of(in_view, f, shown.markers))
            vis = sum(int(s.covered_px - s.hidden_px) for s in stats)
            figures.append(img(jpeg_uri(rgb), f"frame {fs.frames[f].name}",
                               f"{fs.frames[f].name}: {len(stats)} tag(s) of {shown.method} k={shown.k}, "
                               f"{vis} tag pixels visible"))
    body = (f"<h1>Real frames: {esc(fs.root.name)}</h1>"
            + (f"<h2>Composited query frames</h2><div class='gallery'>{''.join(figures)}</div>" if figures else "")
            + markdown_to_html(md, heading_offset=1))
    write_page(out / "report.html", f"markerplace evaluate --frames: {fs.root.name}", body)
