"""Uniform downsampling of candidate spots: a kept spot blocks close spots facing a similar way,
and a refused spot blocks nothing."""

from __future__ import annotations

import numpy as np

from markerplace.plan.discretize.spacing import space_out


def _line(n, step):
    return np.column_stack([np.arange(n) * step, np.zeros(n)]), np.tile([0.0, 1.0], (n, 1))


def test_keeps_one_spot_per_spacing_along_a_wall():
    xy, n = _line(10, 0.1)  # spots every 10 cm, all facing +y
    assert space_out(xy, n, 0.25, 0.9, lambda idx: np.ones(len(idx), bool)) == [0, 3, 6, 9]


def test_opposite_facings_do_not_block_each_other():
    xy = np.array([[0.0, 0.0], [0.05, 0.0], [0.1, 0.0]])
    n = np.array([[0.0, 1.0], [0.0, -1.0], [0.0, 1.0]])  # two sides of a thin wall
    assert space_out(xy, n, 0.5, 0.9, lambda idx: np.ones(len(idx), bool)) == [0, 1]


def test_a_refused_spot_leaves_its_neighbours_free_and_batches_are_asked_in_order():
    xy, n = _line(6, 0.1)
    asked = []

    def accept(idx):
        asked.append(idx.tolist())
        return idx != 0  # the first spot is refused (say, a door)

    assert space_out(xy, n, 0.25, 0.9, accept, batch=2) == [1, 4]
    assert all(a[0] < b[0] for a, b in zip(asked, asked[1:]))
    assert space_out(np.zeros((0, 2)), np.zeros((0, 2)), 0.25, 0.9, accept) == []
