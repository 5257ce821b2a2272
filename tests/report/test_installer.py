"""The installer's pictures of a scan-like model (several texture atlases, drawn in chunks: see
:mod:`helpers.atlas_scenes`) show the room: every render behind them is the renderer's full
image (the same as with every output on), and outside the drawn-in outline, dimension lines and
labels no pixel has a colour the scene does not contain (the RGB-only renders once showed
coloured blocks on a real scan)."""

from __future__ import annotations

import numpy as np

from helpers.atlas_scenes import foreign_colours, multi_atlas_room
from markerplace.geometry import world_from_marker_pose
from markerplace.markers import Marker
from markerplace.render.renderer import Renderer
from markerplace.report.captions import describe_tag
from markerplace.report.installer import IMAGE_SIZE, render_installer_views
from markerplace.scene.raycast import RayCaster


def test_installer_views_of_a_scan_show_only_the_scenes_colours(monkeypatch):
    scene = multi_atlas_room()
    caster = RayCaster(*scene.geometry())
    tags = [(np.array([6.0, 2.5, 1.4]), np.array([-1.0, 0.0, 0.0])), (np.array([4.5, 5.0, 1.4]), np.array([0.0, -1.0, 0.0]))]
    markers = [Marker(i, 0.2, world_from_marker_pose(p, n)) for i, (p, n) in enumerate(tags)]
    places = [describe_tag(caster, p, n, 0.0) for p, n in tags]

    renders = []  # (the render the installer asked for, the same pose with every output)
    render = Renderer.render

    def spy(self, T, **outputs):
        out = render(self, T, **outputs)
        renders.append((out.rgb.copy(), render(self, T).rgb, outputs))
        return out

    monkeypatch.setattr(Renderer, "render", spy)
    views = render_installer_views(scene, markers, places, caster, lambda i: None, (0, 0), 0.1,
                                   [f"#{i + 1} id {i}" for i in range(len(tags))])
    assert len(renders) == 2 * len(tags)
    for (asked, full, outputs), view in zip(renders, [im for v in views for im in (v.close, v.wide)]):
        assert outputs == {"depth": False, "normal": False}  # the RGB-only path
        assert view.shape == (IMAGE_SIZE[1], IMAGE_SIZE[0], 3)
        drawn_in = (view != asked).any(axis=2)  # outline, dimension lines, labels
        assert 0.0 < drawn_in.mean() < 0.2
        foreign = foreign_colours(view) & ~drawn_in
        assert not foreign.any(), f"{foreign.sum()} pixels of colours the scene does not contain"
        np.testing.assert_array_equal(asked, full)
        assert (asked.max(axis=2) > 0).mean() > 0.95  # the room fills the view
