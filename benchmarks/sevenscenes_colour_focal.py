"""Which focal length fits 7-Scenes' colour images? Measures it on real frames.

7-Scenes does not calibrate its colour camera against its depth camera; the published focal
length 585 is the depth camera's. markerplace reads 7-Scenes colour with fx = fy = 525 (the value
the relocalization literature uses) and resamples the depth into that camera
(:mod:`markerplace.scan.sevenscenes`). This benchmark checks that choice against the frames
themselves, with no renderer and no model of ours in the loop: for pairs of frames ``--gap``
apart, SIFT matches between the two colour images (ratio 0.7), each match's first keypoint
lifted by the depth of its frame under a colour focal length hypothesis f (colour pixel x reads
the depth pixel ``K_depth K_f^-1 x``, then the depth camera's back-projection), moved by the two
poses and projected with K_f into the second frame. The reprojection error against the matched
keypoint is smallest near the right f.

Prints ``reproj_median_px_f<F>: value`` (the median over pairs of each pair's median error) per
hypothesis, ``best_f`` and ``ratio_585_to_best`` (the error at 585 over the best).

    .venv/bin/python benchmarks/sevenscenes_colour_focal.py runs/kitchen/frames [--pairs 40] [--gap 6]

The frames are licensed (7-Scenes, non-commercial research): give a path, nothing is copied.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from markerplace.scan.sevenscenes import SEVENSCENES_INVALID_DEPTH, read_7scenes

HYPOTHESES = (495.0, 505.0, 510.0, 515.0, 520.0, 525.0, 530.0, 545.0, 565.0, 585.0)


def pair_errors(gray_a, depth_a, T_a, gray_b, T_b, K_depth: np.ndarray, focals) -> dict:
    """Median reprojection error (pixels) of the a->b SIFT matches per colour focal length."""
    sift = cv2.SIFT_create()
    ka, da = sift.detectAndCompute(gray_a, None)
    kb, db = sift.detectAndCompute(gray_b, None)
    if da is None or db is None:
        return {}
    good = [m for m, n in cv2.BFMatcher().knnMatch(da, db, k=2) if m.distance < 0.7 * n.distance]
    pa = np.float64([ka[m.queryIdx].pt for m in good]).reshape(-1, 2)
    pb = np.float64([kb[m.trainIdx].pt for m in good]).reshape(-1, 2)
    h, w = depth_a.shape
    cx, cy = K_depth[0, 2], K_depth[1, 2]
    out = {}
    for f in focals:
        ud = np.rint(cx + (pa[:, 0] - cx) * K_depth[0, 0] / f).astype(int)
        vd = np.rint(cy + (pa[:, 1] - cy) * K_depth[1, 1] / f).astype(int)
        ok = (ud >= 0) & (ud < w) & (vd >= 0) & (vd < h)
        z = np.zeros(len(pa))
        z[ok] = depth_a[vd[ok], ud[ok]]
        ok &= z > 0
        if ok.sum() < 10:
            continue
        X = np.stack([(ud[ok] - cx) / K_depth[0, 0] * z[ok], (vd[ok] - cy) / K_depth[1, 1] * z[ok], z[ok], np.ones(ok.sum())])
        Xb = np.linalg.inv(T_b) @ T_a @ X
        u = f * Xb[0] / Xb[2] + cx
        v = f * Xb[1] / Xb[2] + cy
        out[f] = float(np.median(np.hypot(u - pb[ok, 0], v - pb[ok, 1])))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("frames", help="a 7-Scenes sequence folder (e.g. runs/kitchen/frames)")
    ap.add_argument("--pairs", type=int, default=40, help="frame pairs, spread over the sequence (default 40)")
    ap.add_argument("--gap", type=int, default=6, help="frames between the two of a pair (default 6)")
    args = ap.parse_args()
    fs = read_7scenes(args.frames)  # poses as written: both frames of a pair in the same world
    K_depth = fs.depth_intrinsics.K
    starts = np.linspace(0, len(fs.frames) - 1 - args.gap, args.pairs).astype(int)
    errors = {f: [] for f in HYPOTHESES}
    for i in starts:
        a, b = fs.frames[i], fs.frames[i + args.gap]
        imgs = [cv2.imread(str(r.color_path), cv2.IMREAD_GRAYSCALE) for r in (a, b)]
        depth = cv2.imread(str(a.depth_path), cv2.IMREAD_UNCHANGED).astype(np.float64)
        depth[depth == SEVENSCENES_INVALID_DEPTH] = 0
        for f, e in pair_errors(imgs[0], depth / fs.depth_scale, a.world_from_cam, imgs[1], b.world_from_cam,
                                K_depth, HYPOTHESES).items():
            errors[f].append(e)
    medians = {f: float(np.median(v)) for f, v in errors.items() if v}
    for f, m in medians.items():
        print(f"reproj_median_px_f{f:g}: {m:.3f}")
    best = min(medians, key=medians.get)
    print(f"pairs: {len(starts)}")
    print(f"best_f: {best:g}")
    print(f"reproj_median_px_at_525: {medians[525.0]:.3f}")
    print(f"ratio_585_to_best: {medians[585.0] / medians[best]:.2f}")


if __name__ == "__main__":
    main()
