"""What would it cost the plan's observe stage to also extract the testbed's map features?

``plan``'s observe stage (:mod:`markerplace.plan.observe`) renders every feasible pose and
extracts SIFT with the scoring preset; ``evaluate``'s marker-free map
(:class:`~markerplace.simulation.rendered_images.BaseImages`) renders the same poses again and extracts SIFT
with OpenCV's defaults and detects tags. This times, per pose, on a sample of a scene's
feasible poses in one process: the render (RGB and depth), the scoring preset's features, the
default preset's features plus tag detection, and a depth-only render (what the map's in-view
mask would still need if its features came from observe). It prints ``name: value`` lines
(milliseconds per pose, and the extrapolated seconds over all poses on one core):

    .venv/bin/python benchmarks/observe_presets.py room --poses 60
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from markerplace.imaging.engine import EngineSpec, ImagingEngine
from markerplace.localization.sift import SIFT_DEFAULT
from markerplace.localization.tags import detect_tags
from markerplace.plan.config import PlanConfig
from markerplace.plan.discretize.stage import run_discretize
from markerplace.scene.spec import SceneSpec


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", nargs="?", default="room")
    ap.add_argument("--poses", type=int, default=60, help="poses timed (evenly spread over the feasible ones)")
    args = ap.parse_args()
    spec, config = SceneSpec(args.scene), PlanConfig()
    scene = spec.load()
    with tempfile.TemporaryDirectory() as tmp:
        disc, _ = run_discretize(scene, config.discretize, config.placement.tag_size, Path(tmp), {})
    poses = np.asarray(disc.world_from_cam, float)
    pick = np.unique(np.linspace(0, len(poses) - 1, min(args.poses, len(poses))).astype(int))
    scoring = ImagingEngine(EngineSpec(spec, config.imaging))
    default_config = replace(config.imaging, sift=SIFT_DEFAULT)
    default = ImagingEngine(EngineSpec(spec, default_config))
    t = {"render": 0.0, "sift_scoring": 0.0, "sift_default": 0.0, "tags": 0.0, "depth_render": 0.0}
    n_scoring = n_default = 0
    scoring.render(poses[0])  # warm-up: GL context, scene upload
    for i in pick:
        t0 = time.perf_counter()
        res = scoring.render(poses[i])
        t1 = time.perf_counter()
        n_scoring += len(scoring.features(res).with_3d_only().keypoints)
        t2 = time.perf_counter()
        n_default += len(default.features(res).with_3d_only().keypoints)
        t3 = time.perf_counter()
        detect_tags(res.rgb)
        t4 = time.perf_counter()
        scoring.render(poses[i], rgb=False)
        t5 = time.perf_counter()
        for name, dt in zip(t, (t1 - t0, t2 - t1, t3 - t2, t4 - t3, t5 - t4)):
            t[name] += dt
    scoring.close()
    default.close()
    m = len(pick)
    print(f"scene: {args.scene}")
    print(f"poses_total: {len(poses)}")
    print(f"poses_timed: {m}")
    for name, total in t.items():
        print(f"{name}_ms_per_pose: {1000 * total / m:.1f}")
    observe = t["render"] + t["sift_scoring"]
    extra = t["sift_default"] + t["tags"]
    testbed_map = t["render"] + t["sift_default"] + t["tags"]
    print(f"features_per_pose_scoring: {n_scoring / m:.0f}")
    print(f"features_per_pose_default: {n_default / m:.0f}")
    print(f"observe_s_all_poses_one_core: {observe / m * len(poses):.1f}")
    print(f"observe_with_map_features_s_all_poses_one_core: {(observe + extra) / m * len(poses):.1f}")
    print(f"observe_cost_ratio: {(observe + extra) / observe:.2f}")
    print(f"testbed_map_s_all_poses_one_core: {testbed_map / m * len(poses):.1f}")
    print(f"testbed_map_after_sharing_s_all_poses_one_core: {t['depth_render'] / m * len(poses):.1f}")


if __name__ == "__main__":
    main()
