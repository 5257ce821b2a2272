"""Settings of the real-photograph testbed (``evaluate --frames``)."""

from __future__ import annotations

from dataclasses import dataclass, field

from markerplace.errors import UserError
from markerplace.imaging.composite import CompositeConfig
from markerplace.testbed.frames.split import FrameSplitConfig

__all__ = ["MAP_KINDS", "FramesEvalConfig"]

MAP_KINDS = ("frames", "render")
"""``frames``: the map images are the real map frames (the paper's real experiment);
``render``: renders of the fused surface at the map frames' poses (what a plan from a scan assumes)."""


@dataclass(frozen=True)
class FramesEvalConfig:
    """How real frames are evaluated.

    Attributes:
        split: the block split into map and query frames.
        maps: map kinds to evaluate (:data:`MAP_KINDS`; default both).
        gap: also localize the query poses rendered from the fused surface against the rendered
            map (``render@render``), for the gap table (needs ``render`` in ``maps``).
        composite: how tags are put into the photographs.
        sheet: composited query frames shown in report.html.
    """

    split: FrameSplitConfig = field(default_factory=FrameSplitConfig)
    maps: tuple[str, ...] = MAP_KINDS
    gap: bool = True
    composite: CompositeConfig = field(default_factory=CompositeConfig)
    sheet: int = 8

    def validate(self) -> None:
        """Raise :class:`UserError` for unknown map kinds or split settings that cannot work."""
        self.split.validate()
        bad = [m for m in self.maps if m not in MAP_KINDS]
        if bad or not self.maps:
            raise UserError(f"--map {','.join(self.maps)!r}: choose frames, render or both (frames,render)")
