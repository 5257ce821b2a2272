"""Every built-in scene renders non-degenerate, deterministic images from its default pose."""

import numpy as np
import pytest

from markerplace.geometry import Intrinsics
from markerplace.render.renderer import Renderer
from markerplace.render.views import default_pose
from markerplace.scene import load_scene
from markerplace.scene.builtin.catalogue import builtin_names


@pytest.mark.parametrize("name", builtin_names())
def test_builtin_renders_non_degenerate_and_deterministic(name):
    scene = load_scene(name)
    pose = default_pose(scene)
    with Renderer(scene, Intrinsics(width=300, height=225, fx=150, fy=150, cx=150, cy=112.5)) as r:
        a = r.render(pose)
        b = r.render(pose)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
    # inside a closed interior nearly every pixel hits something at a plausible distance (a
    # window of house or apartment shows the sky outside)
    hit = a.depth > 0
    assert hit.mean() > 0.95
    assert 0.1 < np.median(a.depth[hit]) < 20.0
    # not a flat colour: textures, shading and several surfaces are visible
    gray = a.rgb.mean(axis=2)
    assert gray.std() > 10.0
    assert len(np.unique(a.rgb.reshape(-1, 3), axis=0)) > 500
    normals = a.normal[hit]
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-3)
    # floor (up) and walls (horizontal normals) are both in view
    assert (normals[:, 2] > 0.9).mean() > 0.01
    assert (np.abs(normals[:, 2]) < 0.1).mean() > 0.2
