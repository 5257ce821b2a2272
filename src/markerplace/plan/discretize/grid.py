"""A regular xy grid over a model: the raster that floor maps, occupancy and free space share.

Frames: world z up, metres. ``H`` rows from ``y0`` up, ``W`` columns from ``x0``, cells of
``res`` metres; cell (r, c) has centre ``(x0 + (c + .5) res, y0 + (r + .5) res)``. Images on
the grid are (H, W) arrays indexed [row, col]. The corner sits on a multiple of ``res`` so two
models of one building share cells.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Grid"]


@dataclass(frozen=True)
class Grid:
    """A regular xy grid: ``H`` rows from ``y0`` up, ``W`` columns from ``x0``, cells of ``res`` metres."""

    x0: float
    y0: float
    res: float
    H: int
    W: int

    @classmethod
    def covering(cls, lo: np.ndarray, hi: np.ndarray, res: float, margin: float = 0.5) -> "Grid":
        """The grid of cell size ``res`` covering the xy box [lo, hi] plus ``margin`` metres,
        its corner on a multiple of ``res`` (two models of one building share cells)."""
        lo = np.floor((np.asarray(lo, dtype=float)[:2] - margin) / res) * res
        hi = np.asarray(hi, dtype=float)[:2] + margin
        return cls(float(lo[0]), float(lo[1]), float(res), int(np.ceil((hi[1] - lo[1]) / res)),
                   int(np.ceil((hi[0] - lo[0]) / res)))

    @property
    def shape(self) -> tuple[int, int]:
        return (self.H, self.W)

    def to_px(self, xy: np.ndarray) -> np.ndarray:
        """World xy -> continuous pixel coordinates (col, row) with cell centres at integers."""
        xy = np.asarray(xy, dtype=float)
        return np.stack([(xy[..., 0] - self.x0) / self.res - 0.5, (xy[..., 1] - self.y0) / self.res - 0.5], axis=-1)

    def cell(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, col, inside) integer cells of (M, 2) world xy points (clipped into the grid)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            c = np.floor((xy[:, 0] - self.x0) / self.res)
            r = np.floor((xy[:, 1] - self.y0) / self.res)
        inside = (c >= 0) & (c < self.W) & (r >= 0) & (r < self.H)
        c = np.clip(np.nan_to_num(c), 0, self.W - 1).astype(np.int64)
        r = np.clip(np.nan_to_num(r), 0, self.H - 1).astype(np.int64)
        return r, c, inside

    def centres(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """(M, 2) world xy of cell centres."""
        return np.column_stack([self.x0 + (np.asarray(cols) + 0.5) * self.res,
                                self.y0 + (np.asarray(rows) + 0.5) * self.res])

    def lookup(self, image: np.ndarray, xy: np.ndarray, outside=0):
        """(M,) values of an (H, W) image at world xy points (``outside`` where off the grid)."""
        r, c, inside = self.cell(xy)
        return np.where(inside, image[r, c], outside)
