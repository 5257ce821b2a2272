"""Per-image cost profile of an evaluation: render, SIFT, tags, localization, tags in view.

Reproduces the "one-off profile" of docs/results/office.md with the testbed's own functions. Prints
``name: value`` lines (nothing else on stdout). For ``--images`` N test poses of ``--scene``,
drawn from the plan's map poses as ``evaluate`` draws them (``sample_test_poses``, test set
``--test-set``, seed ``--seed``) and rendered with the first ``--k`` markers of ``--placement``,
the mean milliseconds per image of:

* ``render``: :meth:`ImagingEngine.render` (RGB + depth, the markers drawn);
* ``sift``: ``extract_sift`` with the testbed's preset (OpenCV defaults);
* ``tags``: ``detect_tags`` (tag36h11);
* ``features``: :meth:`ImagingEngine.features` with tags, i.e. what the testbed runs per image
  (SIFT + lifting to 3D + tags, so about sift + tags);
* ``localize``: ``localize_features`` of one query against the placement's map (query VLAD and
  retrieval, SIFT matching against the candidates, P3P RANSAC + LM), split into its stages.

The map is built as ``evaluate`` builds it (``map_images``, ``vlad_codebook``, then
``PlacementMaps`` re-renders the map images with a marker in view): its cost is only reported
in total (``map_build_s``), not per image. Fractions: of all map images and of the N test
images, those with at least one of the k markers in view (the conservative in-view test on the
marker-free depth that the testbed's caches use) and those with at least one tag detected.
Timing runs in this process with single-threaded BLAS / OpenCV, as the evaluation's workers.

The plan's artifacts (``discretization.npz``, ``observations/``, ``similarity.npz``) are copied
to a scratch folder and reused there by ``prepare`` with the default plan settings: nothing
under ``--plan`` is written (artifacts made with other settings are recomputed in the copy,
with a warning on stderr).

    nice -n 10 .venv/bin/python benchmarks/evaluation_profile.py --plan out/eval_office/plan \\
        --placement out/placements_office/omp-corners/placement.json [--scene office] \\
        [--images 200] [--k 20] [--seed 0] [--test-set weighted] [--workers 1]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads BLAS
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import shutil  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

PLAN_ARTIFACTS = ("discretization.npz", "observations", "similarity.npz")


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = f"{value:.4g}"
    print(f"{name}: {value}", flush=True)


def copy_plan(plan: Path, dest: Path) -> dict:
    """Copy the plan's reusable artifacts (and their ``.meta.json``) into ``dest``; returns
    artifact -> recorded cache key."""
    dest.mkdir(parents=True)
    keys = {}
    for name in PLAN_ARTIFACTS:
        src, meta = plan / name, plan / (name + ".meta.json")
        if not src.exists() or not meta.exists():
            continue
        (shutil.copytree if src.is_dir() else shutil.copy2)(src, dest / src.name)
        shutil.copy2(meta, dest / meta.name)
        keys[name] = json.loads(meta.read_text()).get("key")
    if "discretization.npz" not in keys:
        sys.exit(f"error: {plan} holds no discretization.npz: give a plan folder (e.g. out/eval_office/plan)")
    return keys


def test_poses(data, plan_config, mode: str, num: int, seed: int, min_clearance: float):
    """``num`` test poses drawn as ``evaluate`` draws a test set (its seed here ``seed``)."""
    from markerplace.simulation import pose_sampling as tp

    disc = data.disc
    layer = {int(st): k for k, st in enumerate(disc.planned_storeys)}
    is_free = tp.free_space_checker(disc.occupancy, disc.grid_origin, disc.grid_resolution, min_clearance,
                                    np.array([layer[int(st)] for st in disc.pose_storey], dtype=np.int64))
    cfg = tp.TestPoseConfig(num=num, mode=mode, seed=seed, min_clearance=min_clearance)
    return tp.sample_test_poses(np.asarray(disc.world_from_cam, float), data.base_score,
                                plan_config.discretize.grid_spacing, cfg, is_free).world_from_cam


def ms(seconds: list) -> float:
    return 1000.0 * float(np.mean(seconds)) if seconds else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="office", help="built-in scene name (default office)")
    ap.add_argument("--plan", required=True, type=Path, help="plan folder (discretization.npz, observations/)")
    ap.add_argument("--placement", type=Path, help="placement.json (default: PLAN/placement.json)")
    ap.add_argument("--k", type=int, default=20, help="first k markers of the placement (default 20)")
    ap.add_argument("--images", type=int, default=200, help="test images timed (default 200)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the test poses (default 0)")
    ap.add_argument("--test-set", default="weighted", choices=("weighted", "uniform"))
    ap.add_argument("--workers", type=int, default=1, help="processes building the map (default 1: this one)")
    ap.add_argument("--cache", type=Path,
                    help="scratch folder kept between runs (its profile_plan/ and profile_cache/; the marker-free "
                         "map is reused, so map_build_s drops) (default: a temporary one)")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)

    from markerplace.imaging.engine import ImagingEngine
    from markerplace.localization.localizer import get_localizer
    from markerplace.localization.sift import extract_sift
    from markerplace.localization.tags import detect_tags
    from markerplace.markers import load_markers
    from markerplace.pipelines.plan import prepare
    from markerplace.plan.config import PlanConfig
    from markerplace.runtime.cache import hash_of
    from markerplace.runtime.executor import RuntimeConfig, make_executor
    from markerplace.runtime.workers import single_threaded_libraries
    from markerplace.scene.spec import SceneSpec
    from markerplace.scene.worldframe import markers_to_internal, world_offset
    from markerplace.simulation.config import LocalizationConfig
    from markerplace.simulation.map_setup import localizer_spec, map_base_key, map_images, testbed_imaging_config, vlad_codebook
    from markerplace.simulation.maps import load_map_database, localize_features
    from markerplace.simulation.placement_localization import PlacementMaps
    from markerplace.simulation.rendered_images import TestbedImaging
    from markerplace.testbed.config import TestSetConfig

    placement = args.placement or args.plan / "placement.json"
    single_threaded_libraries()
    spec, plan_config, lconf = SceneSpec(args.scene), PlanConfig(), LocalizationConfig()
    scene = spec.load()
    markers = markers_to_internal(load_markers(placement), world_offset(scene))[: args.k]
    with tempfile.TemporaryDirectory(prefix="evaluation_profile_") as tmp:
        work = args.cache or Path(tmp)
        plan_dir, cache_dir = work / "profile_plan", work / "profile_cache"  # never evaluate's plan/, cache/
        if plan_dir.exists():
            shutil.rmtree(plan_dir)
        keys = copy_plan(args.plan, plan_dir)
        with make_executor(RuntimeConfig(workers=args.workers)) as ex:
            data = prepare(spec, plan_config, plan_dir, progress=False, executor=ex)
            for name, key in keys.items():
                if json.loads((plan_dir / (name + ".meta.json")).read_text()).get("key") != key:
                    print(f"warning: {args.plan / name} was made with other settings: recomputed", file=sys.stderr)
            map_poses = np.asarray(data.disc.world_from_cam, float)
            poses = test_poses(data, plan_config, args.test_set, args.images, args.seed, TestSetConfig().min_clearance)
            imaging = testbed_imaging_config(plan_config)
            tb = TestbedImaging(spec, imaging, markers, ex, progress=False)

            # (a)-(c) per test image, in this process; features kept for (d)
            engine = ImagingEngine(tb.spec)
            t_render, t_sift, t_tags, t_feat, feats, in_view, detected = [], [], [], [], [], [], []
            try:
                engine.render(poses[0], markers)  # warm-up: shaders, marker textures
                for T in poses:
                    t0 = time.perf_counter()
                    res = engine.render(T, markers)
                    t1 = time.perf_counter()
                    extract_sift(res.rgb, imaging.sift)
                    t2 = time.perf_counter()
                    tags = detect_tags(res.rgb)
                    t3 = time.perf_counter()
                    feats.append(engine.features(res, tags=True))
                    t4 = time.perf_counter()
                    for acc, dt in ((t_render, t1 - t0), (t_sift, t2 - t1), (t_tags, t3 - t2), (t_feat, t4 - t3)):
                        acc.append(dt)
                    detected.append(len(tags) > 0)
                    in_view.append(engine.in_view(engine.render(T, (), rgb=False), "union"))
            finally:
                engine.close()
            test_seen = np.mean([bool(v) for v in tb.view_keys(np.stack(in_view), markers)])

            # the placement's map, as evaluate builds it
            t0 = time.perf_counter()
            base_key = map_base_key(scene, map_poses)
            map_base = map_images(tb, map_poses, cache_dir, base_key)
            codebook, _ = vlad_codebook(cache_dir, base_key, imaging, map_base, lconf.vlad_clusters, 0)
            maps = PlacementMaps(tb, map_base, codebook, None)
            with maps.built(markers, cache_dir / f"db_{hash_of(base_key, len(markers))}", "map") as pmap:
                map_build_s = time.perf_counter() - t0
                map_seen = np.mean([bool(v) for v in tb.view_keys(map_base.in_view, markers)])
                map_detected = np.mean(np.diff(np.asarray(pmap.features.tag_offsets)) > 0)
                name, settings = localizer_spec(lconf, 0)
                localizer = get_localizer(name, load_map_database(pmap.folder), imaging.camera.K, **dict(settings))

                # (d) one query at a time against the map
                localize_features(localizer, feats[0])  # warm-up
                t_loc, stages, ok = [], {"retrieval": [], "matching": [], "pnp": []}, []
                for f in feats:
                    t0 = time.perf_counter()
                    r = localize_features(localizer, f)
                    t_loc.append(time.perf_counter() - t0)
                    for s in stages:
                        stages[s].append(r.timing[s])
                    ok.append(r.success)

    emit("scene", args.scene)
    emit("placement", str(placement))
    emit("k", len(markers))
    emit("test_set", args.test_set)
    emit("seed", args.seed)
    emit("images", len(poses))
    emit("map_images", len(map_poses))
    emit("map_build_s", round(map_build_s, 1))
    emit("render_ms", ms(t_render))
    emit("sift_ms", ms(t_sift))
    emit("tags_ms", ms(t_tags))
    emit("features_ms", ms(t_feat))
    emit("localize_ms", ms(t_loc))
    for s, v in stages.items():
        emit(f"localize_{s}_ms", ms(v))
    emit("localized_fraction", float(np.mean(ok)))
    emit("map_tag_in_view_fraction", float(map_seen))
    emit("map_tag_detected_fraction", float(map_detected))
    emit("test_tag_in_view_fraction", float(test_seen))
    emit("test_tag_detected_fraction", float(np.mean(detected)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
