"""Would re-extracting SIFT only around the tags in view speed up an evaluation? Measures it.

SIFT is five sixths of an evaluation's per-image cost (``benchmarks/evaluation_profile.py``),
and a tag changes only the pixels it covers. The idea measured here: keep the marker-free
image's keypoints farther than ``--radius`` pixels from every changed pixel, and take the rest
from SIFT run on crops around the changed pixels (each crop the changed pixels' bounding box
grown by ``--margin`` pixels, its origin on a multiple of ``--align`` pixels so that the
pyramid's octaves sample the same pixels as on the whole image). It is an approximation: a
keypoint's detection and descriptor use pixels up to about 5 times its size away, so large
keypoints near a tag, and crop keypoints near a crop's edge, can differ from the whole image's.

For ``--images`` poses of a test-pose file written by ``evaluate`` (``test_poses_<set>.npz``)
rendered with the first ``--k`` markers of ``--placement``, prints ``name: value`` lines:

* ``full_sift_ms``: SIFT of the whole image (what the testbed runs now), mean per image;
* ``base_render_ms``: the extra marker-free render the local variant needs for the changed
  pixels (the testbed caches the marker-free features, not the pixels);
* ``local_sift_ms``: the changed pixels, the crops' SIFT and the merge (the marker-free
  features are cached in the testbed, so they are not timed; the gray image is shared with the
  full SIFT, whose time includes it);
* ``changed_images_fraction``: images in which the markers change any pixel;
* ``crop_area_fraction``: crop pixels over image pixels, mean over changed images;
* ``keypoints_reproduced``: share of the whole image's keypoints that the local variant gives
  at the same position (within 0.05 px) with the same descriptor (L2 below 2), pooled; and its
  worst image (``keypoints_reproduced_min``);
* ``speedup_per_image``: (render + full SIFT + rest) / (render + base render + local SIFT +
  rest), with ``--rest-ms`` the per-image cost besides render and SIFT (tags and localization;
  default 21.6 ms, the office profile's 6.9 + 14.7).

One process, single-threaded OpenCV, as the evaluation's workers::

    .venv/bin/python benchmarks/local_sift.py --poses out/eval_office/test_poses_weighted.npz \\
        --placement out/placements_office/omp-corners/placement.json [--scene office] [--k 20] \\
        [--images 100] [--radius 40] [--margin 96] [--align 32]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy loads BLAS
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402


def emit(name: str, value) -> None:
    if isinstance(value, float):
        value = f"{value:.4g}"
    print(f"{name}: {value}", flush=True)


def sift_arrays(sift, gray: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, 2) float64 keypoint positions and (K, 128) float32 descriptors of ``gray``."""
    kps, desc = sift.detectAndCompute(gray, None)
    if desc is None or not kps:
        return np.zeros((0, 2)), np.zeros((0, 128), np.float32)
    return np.array([k.pt for k in kps], float).reshape(-1, 2), np.asarray(desc, np.float32)


def crops(changed: np.ndarray, margin: int, align: int) -> list[tuple[int, int, int, int]]:
    """(x0, y0, x1, y1) per connected group of changed pixels, grown by ``margin`` and merged
    where they overlap; origins rounded down to multiples of ``align``."""
    import cv2

    h, w = changed.shape
    n, _, stats, _ = cv2.connectedComponentsWithStats(changed.astype(np.uint8), connectivity=8)
    boxes = [(max(0, (x - margin) // align * align), max(0, (y - margin) // align * align),
              min(w, x + bw + margin), min(h, y + bh + margin)) for x, y, bw, bh, _ in stats[1:n]]
    merged = True
    while merged:  # merge overlapping boxes until none overlap
        merged = False
        for i in range(len(boxes)):
            for j in range(i + 1, len(boxes)):
                a, b = boxes[i], boxes[j]
                if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]:
                    boxes[i] = (min(a[0], b[0]), min(a[1], b[1]), max(a[2], b[2]), max(a[3], b[3]))
                    del boxes[j]
                    merged = True
                    break
            if merged:
                break
    return boxes


def local_sift(sift, gray: np.ndarray, changed: np.ndarray, base_xy: np.ndarray, base_desc: np.ndarray,
               radius: float, margin: int, align: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The local variant's keypoints and descriptors of ``gray`` and its crop area fraction."""
    import cv2

    dist = cv2.distanceTransform((~changed).astype(np.uint8), cv2.DIST_L2, 5)
    h, w = changed.shape

    def near(xy):
        xi = np.clip(np.rint(xy[:, 0]).astype(int), 0, w - 1)
        yi = np.clip(np.rint(xy[:, 1]).astype(int), 0, h - 1)
        return dist[yi, xi] <= radius

    keep = ~near(base_xy)
    xy_parts, desc_parts, area = [base_xy[keep]], [base_desc[keep]], 0
    for x0, y0, x1, y1 in crops(changed, margin, align):
        xy, desc = sift_arrays(sift, np.ascontiguousarray(gray[y0:y1, x0:x1]))
        xy = xy + [x0, y0]
        inside = near(xy) & (xy[:, 0] >= x0) & (xy[:, 0] < x1) & (xy[:, 1] >= y0) & (xy[:, 1] < y1)
        xy_parts.append(xy[inside])
        desc_parts.append(desc[inside])
        area += (x1 - x0) * (y1 - y0)
    return np.concatenate(xy_parts), np.concatenate(desc_parts), area / (h * w)


def reproduced(xy_full, desc_full, xy_local, desc_local) -> int:
    """How many whole-image keypoints the local variant gives (same place, same descriptor)."""
    from scipy.spatial import cKDTree

    if len(xy_full) == 0 or len(xy_local) == 0:
        return 0
    dd, ii = cKDTree(xy_local).query(xy_full, k=4, distance_upper_bound=0.05)
    count = 0
    for j in range(len(xy_full)):
        cands = ii[j][ii[j] < len(xy_local)]
        if len(cands) and np.min(np.linalg.norm(desc_local[cands] - desc_full[j], axis=1)) < 2.0:
            count += 1
    return count


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="office", help="built-in scene name (default office)")
    ap.add_argument("--poses", required=True, type=Path, help="test_poses_<set>.npz written by evaluate")
    ap.add_argument("--placement", required=True, type=Path, help="placement.json")
    ap.add_argument("--k", type=int, default=20, help="first k markers of the placement (default 20)")
    ap.add_argument("--images", type=int, default=100, help="images measured (default 100)")
    ap.add_argument("--radius", type=float, default=40.0, help="keypoints this close to a changed pixel are "
                    "re-extracted, pixels (default 40)")
    ap.add_argument("--margin", type=int, default=96, help="crop margin around changed pixels (default 96)")
    ap.add_argument("--align", type=int, default=32, help="crop origins on multiples of this (default 32)")
    ap.add_argument("--rest-ms", type=float, default=21.6, help="per-image cost besides render and SIFT, ms")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, stream=sys.stderr)
    if args.margin <= args.radius:
        sys.exit("error: --margin must exceed --radius (the crop must hold every re-extracted keypoint)")

    import cv2

    from markerplace.imaging.engine import EngineSpec, ImagingEngine
    from markerplace.localization.sift import _sift, to_gray
    from markerplace.markers import load_markers
    from markerplace.plan.config import PlanConfig
    from markerplace.runtime.workers import single_threaded_libraries
    from markerplace.scene.spec import SceneSpec
    from markerplace.scene.worldframe import markers_to_internal, world_offset
    from markerplace.simulation.map_setup import testbed_imaging_config
    from markerplace.simulation.pose_sampling import TestPoses

    single_threaded_libraries()
    cv2.setNumThreads(1)
    spec = SceneSpec(args.scene)
    scene = spec.load()
    markers = markers_to_internal(load_markers(args.placement), world_offset(scene))[: args.k]
    poses = TestPoses.load(args.poses).world_from_cam[: args.images]
    imaging = testbed_imaging_config(PlanConfig())
    sift = _sift(imaging.sift)
    engine = ImagingEngine(EngineSpec(spec, imaging, {}))
    t_render, t_full, t_base, t_local, areas, changed_images = [], [], [], [], [], 0
    total, kept, worst = 0, 0, 1.0
    try:
        engine.render(poses[0], markers)  # warm-up
        for world_from_cam in poses:
            t0 = time.perf_counter()
            marked = engine.render(world_from_cam, markers)
            t1 = time.perf_counter()
            gray = to_gray(marked.rgb)
            xy_full, desc_full = sift_arrays(sift, gray)
            t2 = time.perf_counter()
            base = engine.render(world_from_cam, ())
            t3 = time.perf_counter()
            base_xy, base_desc = sift_arrays(sift, to_gray(base.rgb))  # cached in the testbed: not timed
            t4 = time.perf_counter()
            changed = np.any(marked.rgb != base.rgb, axis=2)
            if changed.any():
                changed_images += 1
                xy_local, desc_local, area = local_sift(sift, gray, changed, base_xy, base_desc, args.radius,
                                                        args.margin, args.align)
                areas.append(area)
            else:
                xy_local, desc_local = base_xy, base_desc
            t5 = time.perf_counter()
            for acc, dt in ((t_render, t1 - t0), (t_full, t2 - t1), (t_base, t3 - t2), (t_local, t5 - t4)):
                acc.append(1000.0 * dt)
            n = reproduced(xy_full, desc_full, xy_local, desc_local)
            total, kept = total + len(xy_full), kept + n
            if len(xy_full):
                worst = min(worst, n / len(xy_full))
    finally:
        engine.close()
    render, full, base_ms, local = (float(np.mean(t)) for t in (t_render, t_full, t_base, t_local))
    emit("scene", args.scene)
    emit("images", len(poses))
    emit("k", len(markers))
    emit("radius_px", args.radius)
    emit("margin_px", args.margin)
    emit("align_px", args.align)
    emit("render_ms", render)
    emit("full_sift_ms", full)
    emit("base_render_ms", base_ms)
    emit("local_sift_ms", local)
    emit("changed_images_fraction", changed_images / len(poses))
    emit("crop_area_fraction", float(np.mean(areas)) if areas else 0.0)
    emit("keypoints_reproduced", kept / max(total, 1))
    emit("keypoints_reproduced_min", worst)
    emit("speedup_per_image", (render + full + args.rest_ms) / (render + base_ms + local + args.rest_ms))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
