"""The xy grid of the discretization: cells, centres and look-ups in world metres."""

from __future__ import annotations

import numpy as np

from markerplace.plan.discretize.grid import Grid


def test_covering_grid_snaps_its_corner_and_covers_the_box_with_margin():
    g = Grid.covering(np.array([0.13, -0.27, 5.0]), np.array([2.0, 1.0, 9.0]), 0.1, margin=0.5)
    assert np.isclose(g.x0, -0.4) and np.isclose(g.y0, -0.8) and g.res == 0.1
    assert g.shape == (g.H, g.W) == (23, 29)  # (1.5 - -0.8) / 0.1 rows, (2.5 - -0.4) / 0.1 columns
    assert g.x0 + g.W * g.res >= 2.5 - 1e-9 and g.y0 + g.H * g.res >= 1.5 - 1e-9


def test_cells_centres_pixels_and_lookup_agree():
    g = Grid(x0=1.0, y0=2.0, res=0.5, H=4, W=6)
    xy = np.array([[1.1, 2.1], [3.9, 3.9], [0.9, 2.1], [1.1, np.nan]])
    r, c, inside = g.cell(xy)
    assert r.tolist() == [0, 3, 0, 0] and c.tolist() == [0, 5, 0, 0]
    assert inside.tolist() == [True, True, False, False]  # left of the grid; NaN is nowhere
    np.testing.assert_allclose(g.centres(r[:2], c[:2]), [[1.25, 2.25], [3.75, 3.75]])
    np.testing.assert_allclose(g.to_px(g.centres(np.array([1]), np.array([2]))), [[2.0, 1.0]])  # (col, row)
    image = np.arange(24).reshape(4, 6)
    assert g.lookup(image, xy, outside=-1).tolist() == [0, 23, -1, -1]
