"""The block split of a frame sequence into map and query frames."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.testbed.frames.split import FrameSplitConfig, block_split


@pytest.mark.parametrize("n", [100, 137, 1000])
@pytest.mark.parametrize("config", [FrameSplitConfig(), FrameSplitConfig(20, 3, 1, 1), FrameSplitConfig(50, 10, 2, 2)])
def test_disjoint_and_never_adjacent(n, config):
    map_idx, query_idx = block_split(n, config)
    assert len(map_idx) and len(query_idx)
    assert not set(map_idx) & set(query_idx)
    assert np.all((map_idx >= 0) & (map_idx < n)) and np.all((query_idx >= 0) & (query_idx < n))
    # no query within `gap` frames of any map frame
    assert np.abs(map_idx[:, None] - query_idx[None, :]).min() > config.gap
    assert np.all(np.diff(map_idx) > 0) and np.all(np.diff(query_idx) > 0)


def test_the_kitchen_protocol_split():
    """The split docs/protocols.md fixes for the 1000-frame kitchen: 250 map frames, 150 queries."""
    map_idx, query_idx = block_split(1000, FrameSplitConfig(block=50, gap=10, map_step=2, query_step=2))
    assert len(map_idx) == 250 and len(query_idx) == 150
    assert map_idx[:3].tolist() == [0, 2, 4] and query_idx[:3].tolist() == [60, 62, 64]
    assert query_idx.max() <= 989  # the last query block also keeps its gap at the end
    assert np.abs(map_idx[:, None] - query_idx[None, :]).min() == 12


def test_too_short_or_bad_settings():
    with pytest.raises(UserError, match="too few"):
        block_split(60, FrameSplitConfig(block=50))
    with pytest.raises(UserError, match="gap"):
        block_split(1000, FrameSplitConfig(block=20, gap=10))
    with pytest.raises(UserError, match="gap"):
        block_split(1000, FrameSplitConfig(gap=0))
    with pytest.raises(UserError, match="positive integer"):
        block_split(1000, FrameSplitConfig(query_step=0))
