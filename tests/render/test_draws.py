"""Every output combination of the renderer gives the same colour image, on a scan-like scene of
several texture atlases whose big ones are drawn in chunks through occlusion queries (a
single-attachment RGB-only framebuffer once took the queries' boxes into its colour: coloured
blocks in every RGB-only view of a scan, :mod:`markerplace.render.draws`)."""

from __future__ import annotations

import numpy as np

from helpers.atlas_scenes import PALETTE, foreign_colours, multi_atlas_room
from helpers.poses import look_at_pose
from markerplace.geometry import Intrinsics, world_from_marker_pose
from markerplace.markers import Marker
from markerplace.render.culling import MIN_TRIANGLES
from markerplace.render.renderer import Renderer

K = Intrinsics.from_fov(200, 150, 75.0)


POSES = [look_at_pose((1.5, 1.2, 1.5), t) for t in [(5.9, 2.5, 1.4), (2.5, 4.9, 0.5), (0.1, 0.2, 2.2), (3.0, 2.5, 0.0)]]
POSES.append(look_at_pose((-2.0, 2.5, 1.5), (3.0, 2.5, 1.4)))  # outside, through a wall: most chunks hidden
MARKERS = [Marker(0, 0.3, world_from_marker_pose(np.array([6.0, 2.5, 1.4]), np.array([-1.0, 0.0, 0.0]))),
           Marker(1, 0.3, world_from_marker_pose(np.array([2.5, 5.0, 1.4]), np.array([0.0, -1.0, 0.0])))]


def test_every_output_combination_renders_the_same_colours():
    scene = multi_atlas_room()
    with Renderer(scene, K, MARKERS) as culled, Renderer(scene, K, MARKERS, cull=False) as whole:
        chunked = [d for d in culled._scene_draws if d.chunks is not None]
        assert len(culled._scene_draws) == 3 and len(chunked) == 2  # two big atlases in chunks, the table whole
        assert all(d.n >= 3 * MIN_TRIANGLES and len(d.chunks.n_vertices) > 50 for d in chunked)
        assert chunked[0].ibo is not None and chunked[1].ibo is None  # the indexed and the de-indexed path
        queried = []
        for d in chunked:
            test = d.occlusion.passed
            d.occlusion.passed = lambda fbo, cam, ids, test=test: queried.append(len(ids)) or test(fbo, cam, ids)
        for T in POSES:
            reference = whole.render(T).rgb
            assert (reference.max(axis=2) > 0).mean() > 0.9  # the view sees the room
            for outputs in ({}, {"depth": False, "normal": False}, {"normal": False}, {"depth": False}):
                np.testing.assert_array_equal(culled.render(T, **outputs).rgb, reference, err_msg=str(outputs))
            np.testing.assert_array_equal(whole.render(T, depth=False, normal=False).rgb, reference)
            assert not foreign_colours(reference).any()
        assert sum(queried) > 0  # the occlusion queries ran
        seen = whole.render(POSES[0]).rgb  # the tag on the wall ahead: its black and white
        assert (seen.max(axis=2) < 30).any() and (seen.min(axis=2) > 240).any()


def test_foreign_colours_tells_the_queries_garbage_from_the_scene():
    """The check the report test relies on: shaded, filtered palette colours pass; the colours
    the old RGB-only views showed (blue and cyan blocks) do not."""
    shades = (PALETTE[:, None, :].astype(float) * np.linspace(0.0, 1.0, 11)[None, :, None]).round().astype(np.uint8)
    mixed = ((shades[3].astype(int) + shades[0]) // 2).astype(np.uint8)
    assert not foreign_colours(shades).any() and not foreign_colours(mixed[None]).any()
    garbage = np.array([[[0, 0, 255], [0, 92, 255], [0, 0, 104], [40, 200, 40]]], np.uint8)
    assert foreign_colours(garbage).all()
