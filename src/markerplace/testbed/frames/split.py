"""The fixed block split of a frame sequence into map and query frames.

A handheld RGB-D sequence is one path through a space: neighbouring frames see almost the same
image, so a query taken next to a map frame would be localized against a near copy of itself.
The split cuts the sequence into blocks of ``block`` consecutive frames; even blocks are map
blocks, odd blocks query blocks. The ``gap`` frames at each end of every query block are used by
neither, so a map frame and a query frame are at least ``gap + 1`` frames apart in time. Map
frames are then every ``map_step``-th frame of the map blocks and queries every
``query_step``-th frame of the query blocks (counted from the block's first kept frame).

Nothing here is random: the split is a function of the sequence length and the settings, fixed
before any run (docs/protocols.md states the kitchen's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplace.errors import UserError

__all__ = ["FrameSplitConfig", "block_split"]


@dataclass(frozen=True)
class FrameSplitConfig:
    """How a sequence is split (module docstring).

    Attributes:
        block: frames per block (default 50: about 1.7 s of 30 Hz video).
        gap: frames dropped at each end of a query block (default 10).
        map_step: every n-th frame of a map block is a map image (default 2).
        query_step: every n-th frame of a query block is a query (default 2).
    """

    block: int = 50
    gap: int = 10
    map_step: int = 2
    query_step: int = 2

    def validate(self) -> None:
        """Raise :class:`UserError` for settings that leave no frame or let the sets touch."""
        for name in ("block", "map_step", "query_step"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise UserError(f"frame split: {name} {value!r} must be a positive integer")
        if int(self.gap) != self.gap or self.gap < 1:
            raise UserError(f"frame split: gap {self.gap!r} must be a positive integer (map and query frames "
                            "must never be adjacent in time)")
        if 2 * self.gap >= self.block:
            raise UserError(f"frame split: gap {self.gap} leaves no query frame in blocks of {self.block}; "
                            "use a gap under half the block")


def block_split(num_frames: int, config: FrameSplitConfig = FrameSplitConfig()) -> tuple[np.ndarray, np.ndarray]:
    """Map and query frame indices of a sequence of ``num_frames`` frames.

    Returns:
        (map_indices, query_indices): sorted int64 arrays of frame indices, disjoint, and no
        query index within ``config.gap`` frames of a map index.

    Raises:
        UserError: bad settings, or a sequence too short for one map and one query block.
    """
    config.validate()
    n = int(num_frames)
    if n < 2 * config.block:
        raise UserError(f"{n} frames are too few for the block split: it needs at least two blocks of "
                        f"{config.block} frames (one map block, one query block)")
    idx = np.arange(n)
    block_of = idx // config.block
    offset = idx % config.block
    is_map = block_of % 2 == 0
    map_idx = idx[is_map & (offset % config.map_step == 0)]
    block_len = np.minimum(config.block, n - block_of * config.block)
    kept = ~is_map & (offset >= config.gap) & (offset < block_len - config.gap)
    query_idx = idx[kept & ((offset - config.gap) % config.query_step == 0)]
    if len(query_idx) == 0:
        raise UserError(f"{n} frames give no query frame with blocks of {config.block} and a gap of {config.gap}")
    return map_idx.astype(np.int64), query_idx.astype(np.int64)
