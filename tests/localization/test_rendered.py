"""The localizer on rendered images of the `tiny` scene (not synthetic warps)."""

import numpy as np
import pytest

from markerplace.geometry import Intrinsics, rotation_angle_deg
from markerplace.localization.database import MapDatabase, map_image_from_rgbd
from markerplace.localization.localizer import LocalizerConfig, SiftPnP
from markerplace.localization.pnp import pose_errors
from markerplace.localization.vlad import VladCodebook
from markerplace.markers import Marker
from markerplace.plan.discretize.stage import DiscretizeConfig, discretize
from markerplace.render.renderer import Renderer
from markerplace.scene import load_scene


@pytest.fixture(scope="module")
def tiny_world():
    scene = load_scene("tiny")
    disc = discretize(scene, DiscretizeConfig(grid_spacing=1.0, num_yaws=4))
    intr = Intrinsics()
    marker = Marker(7, 0.4, disc.candidate_world_from_marker[0].copy())
    poses = disc.world_from_cam
    with Renderer(scene, intr, markers=[marker]) as renderer:
        renders = [renderer.render(T, normal=False) for T in poses]
        images = [map_image_from_rgbd(r.rgb, r.depth, T, intr.K) for r, T in zip(renders, poses)]
        codebook = VladCodebook.train(np.concatenate([im.descriptors for im in images]), num_clusters=16, seed=0)
        db = MapDatabase.build(images, [marker], codebook)
        yield dict(renderer=renderer, db=db, poses=poses, renders=renders, marker=marker, intr=intr)


def test_query_rendered_at_a_map_pose_localizes_within_1cm_1deg(tiny_world):
    loc = SiftPnP(tiny_world["db"], tiny_world["intr"].K, LocalizerConfig(use_tags=False))
    db = tiny_world["db"]
    richest = np.argsort([-len(db.features(i)[0]) for i in range(len(tiny_world["poses"]))])[:3]
    for i in richest:  # textured views: exact
        res = loc.localize(tiny_world["renders"][i].rgb)
        assert res.world_from_cam is not None
        t_err, r_err = pose_errors(res.world_from_cam, tiny_world["poses"][i])
        assert t_err <= 0.01 and r_err <= 1.0, (i, t_err, r_err)
    successes, tried = 0, range(0, len(tiny_world["poses"]), 3)
    for i in tried:  # every third map pose, plain walls included
        res = loc.localize(tiny_world["renders"][i].rgb)
        if res.world_from_cam is not None:
            t_err, r_err = pose_errors(res.world_from_cam, tiny_world["poses"][i])
            successes += (t_err <= 0.01) and (r_err <= 1.0)
    assert successes >= 0.7 * len(tried), (successes, len(tried))


def test_query_that_sees_the_tag_detects_it_and_localizes(tiny_world):
    marker = tiny_world["marker"]
    # a camera 1.8 m in front of the tag, looking at it, slightly off axis
    n = marker.normal
    pos = marker.position + 1.8 * n + np.array([0.2 * n[1], -0.2 * n[0], 0.0])
    yaw = np.arctan2(-n[1], -n[0]) + np.radians(8)
    from markerplace.geometry import world_from_cam_pose

    truth = world_from_cam_pose(pos, yaw)
    rgb = tiny_world["renderer"].render(truth, depth=False, normal=False).rgb
    loc = SiftPnP(tiny_world["db"], tiny_world["intr"].K, LocalizerConfig(use_tags=True))
    res = loc.localize(rgb)
    assert marker.tag_id in res.detected_tag_ids
    assert res.world_from_cam is not None
    t_err, r_err = pose_errors(res.world_from_cam, truth)
    assert t_err < 0.05 and r_err < 5.0, (t_err, r_err)
    # the map images that saw the tag are among the retrieved candidates
    assert set(res.candidates) & set(tiny_world["db"].tag_index[marker.tag_id])
    assert rotation_angle_deg(res.world_from_cam[:3, :3], truth[:3, :3]) < 5.0
