"""Top-down figures like the paper's Fig. 5 and Fig. 7(b, c).

All maps share one frame: world x to the right, world y up, metres. The occupancy grid (walls
dark grey, free space white) is the background; dots are camera locations coloured by a
per-location value (the mean over that location's yaws); arrows are markers pointing along
their wall normal, numbered in placement order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..io_utils import atomic_path  # noqa: E402


def per_location_mean(values: np.ndarray, location_index: np.ndarray, num_locations: int) -> np.ndarray:
    """(N,) per-pose values -> (L,) mean per camera location."""
    sums = np.bincount(location_index, weights=values, minlength=num_locations)
    counts = np.bincount(location_index, minlength=num_locations)
    return sums / np.maximum(counts, 1)


def _background(ax, occupancy: np.ndarray, origin: Sequence[float], resolution: float) -> None:
    H, W = occupancy.shape
    img = np.full((H, W, 3), 0.93)
    img[occupancy == 0] = 1.0
    img[occupancy == 1] = 0.25
    x0, y0 = origin
    ax.imshow(img, origin="lower", extent=(x0, x0 + W * resolution, y0, y0 + H * resolution), interpolation="nearest")


def _arrows(ax, positions: np.ndarray, normals: np.ndarray, labels: Sequence[str] | None, color: str = "red") -> None:
    if len(positions) == 0:
        return
    ax.quiver(positions[:, 0], positions[:, 1], normals[:, 0], normals[:, 1], color=color,
              angles="xy", scale_units="xy", scale=1.6, width=0.006, zorder=5)
    if labels is not None:
        for p, n, text in zip(positions, normals, labels):
            ax.annotate(text, (p[0] + 0.75 * n[0], p[1] + 0.75 * n[1]), color=color, fontsize=8,
                        fontweight="bold", ha="center", va="center", zorder=6)


def floor_map(path: str | Path, *, occupancy: np.ndarray, origin: Sequence[float], resolution: float,
              locations: np.ndarray, values: np.ndarray, title: str, colorbar_label: str,
              cmap: str = "gray", markers_xy: np.ndarray | None = None,
              markers_normal: np.ndarray | None = None, marker_labels: Sequence[str] | None = None,
              candidates_xy: np.ndarray | None = None) -> None:
    """Write one top-down map as PNG.

    Args:
        path: output PNG.
        occupancy: (H, W) int8 grid (-1 unknown, 0 free, 1 occupied), row 0 at ``origin`` y.
        origin: (x0, y0) world metres of the grid's lower-left corner.
        resolution: grid cell size, metres.
        locations: (L, 2) camera locations, world xy metres.
        values: (L,) value per location (e.g. mean localizability score); with the default
            grey colour map dark means low.
        title / colorbar_label: text.
        markers_xy / markers_normal: (M, 2) arrow positions and directions; marker_labels (M,).
        candidates_xy: (C, 2) optional candidate marker positions drawn as small ticks.
    """
    fig, ax = plt.subplots(figsize=(8, 6.5), dpi=110)
    _background(ax, occupancy, origin, resolution)
    sc = ax.scatter(locations[:, 0], locations[:, 1], c=values, cmap=cmap, s=22, edgecolors="0.5", linewidths=0.3, zorder=3)
    fig.colorbar(sc, ax=ax, shrink=0.8, label=colorbar_label)
    if candidates_xy is not None and len(candidates_xy):
        ax.scatter(candidates_xy[:, 0], candidates_xy[:, 1], marker="|", s=12, c="tab:blue", alpha=0.6, zorder=4)
    if markers_xy is not None:
        _arrows(ax, np.asarray(markers_xy), np.asarray(markers_normal), marker_labels)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def recall_vs_k(path: str | Path, ks: Sequence[int], curves: dict[str, tuple[np.ndarray, np.ndarray | None]],
                title: str, ylabel: str = "recall (%)") -> None:
    """Recall against number of markers, one line per method (mean, optional std band).

    ``curves`` maps a method name to (mean (len(ks),), std (len(ks),) or None).
    """
    fig, ax = plt.subplots(figsize=(5.5, 4), dpi=110)
    for name, (mean, std) in curves.items():
        line, = ax.plot(ks, mean, marker="o", label=name)
        if std is not None:
            ax.fill_between(ks, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    ax.set_xlabel("number of markers k")
    ax.set_xticks(list(ks))
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
