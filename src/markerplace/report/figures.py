"""Top-down figures like the paper's Fig. 5 and Fig. 7(b, c).

All maps share one frame: world x to the right, world y up, metres. The occupancy grid (walls
dark grey, free space white) is the background; dots are camera locations coloured by a
per-location value (the mean over that location's yaws); arrows are markers pointing along
their wall normal, numbered in placement order.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.runtime.atomic_io import atomic_path


def _pyplot():
    """matplotlib's pyplot on the Agg backend (no display), imported when a figure is drawn:
    it takes half a second, which ``markerplace --help`` should not pay."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt

MISSING_COLOR = "#ff00ff"
"""Colour of the crosses that mark missing tags (magenta: no colour map here uses it)."""


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
              candidates_xy: np.ndarray | None = None, panel_titles: Sequence[str] | None = None,
              location_panel: np.ndarray | None = None, marker_panel: np.ndarray | None = None,
              candidate_panel: np.ndarray | None = None, value_range: tuple[float, float] | None = None,
              missing_xy: np.ndarray | None = None, missing_labels: Sequence[str] | None = None,
              missing_panel: np.ndarray | None = None) -> None:
    """Write a top-down map as PNG, one panel per storey.

    Args:
        path: output PNG.
        occupancy: (H, W) or (S, H, W) int8 grid per panel (-1 unknown, 0 free, 1 occupied),
            row 0 at ``origin`` y.
        origin: (x0, y0) world metres of the grid's lower-left corner.
        resolution: grid cell size, metres.
        locations: (L, 2) camera locations, world xy metres.
        values: (L,) value per location (e.g. mean localizability score); with the default
            grey colour map dark means low. One colour scale for all panels.
        title / colorbar_label: text.
        markers_xy / markers_normal: (M, 2) arrow positions and directions; marker_labels (M,).
        candidates_xy: (C, 2) optional candidate marker positions drawn as small ticks.
        panel_titles: (S,) one title per panel (e.g. "storey 1, floor 3.00 m").
        location_panel / marker_panel / candidate_panel: panel index of each location, marker
            and candidate (default: all on panel 0).
        value_range: (lo, hi) the colour scale must include (default: the values' range).
        missing_xy / missing_labels / missing_panel: (K, 2) spots where a tag is missing, drawn as
            large :data:`MISSING_COLOR` crosses with their labels, and their panels.
    """
    occ = np.asarray(occupancy)
    if occ.ndim == 2:
        occ = occ[None]
    S = len(occ)

    def panel_of(idx, n):
        return np.zeros(n, int) if idx is None else np.asarray(idx, int)

    loc_p = panel_of(location_panel, len(locations))
    cols = min(S, 2)
    rows = int(np.ceil(S / cols))
    plt = _pyplot()
    fig, axes = plt.subplots(rows, cols, figsize=(8 * cols, 6.5 * rows), dpi=110, squeeze=False)
    vmin, vmax = (float(np.min(values)), float(np.max(values))) if len(values) else (0.0, 1.0)
    if value_range is not None:  # a fixed scale (e.g. 0 = nothing lost), widened to hold every value
        vmin, vmax = min(vmin, value_range[0]), max(vmax, value_range[1])
    sc = None
    for k in range(rows * cols):
        ax = axes.flat[k]
        if k >= S:
            ax.axis("off")
            continue
        _background(ax, occ[k], origin, resolution)
        on = loc_p == k
        sc = ax.scatter(locations[on, 0], locations[on, 1], c=np.asarray(values)[on], cmap=cmap, vmin=vmin, vmax=vmax,
                        s=22, edgecolors="0.5", linewidths=0.3, zorder=3)
        if candidates_xy is not None and len(candidates_xy):
            cp = panel_of(candidate_panel, len(candidates_xy)) == k
            ax.scatter(candidates_xy[cp, 0], candidates_xy[cp, 1], marker="|", s=12, c="tab:blue", alpha=0.6, zorder=4)
        if markers_xy is not None and len(markers_xy):
            mp = panel_of(marker_panel, len(markers_xy)) == k
            labels = None if marker_labels is None else [lab for lab, m in zip(marker_labels, mp) if m]
            _arrows(ax, np.asarray(markers_xy)[mp], np.asarray(markers_normal)[mp], labels)
        if missing_xy is not None and len(missing_xy):
            xy = np.asarray(missing_xy, float).reshape(-1, 2)
            kp = panel_of(missing_panel, len(xy)) == k
            ax.scatter(xy[kp, 0], xy[kp, 1], marker="x", s=160, linewidths=3, c=MISSING_COLOR, zorder=7)
            for p, text in zip(xy[kp], [t for t, m in zip(missing_labels or [""] * len(xy), kp) if m]):
                ax.annotate(text, (p[0], p[1]), xytext=(8, 8), textcoords="offset points", color=MISSING_COLOR,
                            fontsize=8, fontweight="bold", zorder=7)
        _crop(ax, occ[k], origin, resolution)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(title if S == 1 else (panel_titles[k] if panel_titles else f"storey {k}"))
    if S > 1:
        fig.suptitle(title)
    fig.colorbar(sc, ax=list(axes.flat), shrink=0.8, label=colorbar_label)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)


def _crop(ax, occupancy: np.ndarray, origin: Sequence[float], resolution: float, margin: float = 1.0) -> None:
    """Zoom a panel onto its storey's free and occupied cells."""
    rr, cc = np.nonzero(occupancy >= 0)
    if len(rr) == 0:
        return
    x0, y0 = origin
    ax.set_xlim(x0 + cc.min() * resolution - margin, x0 + (cc.max() + 1) * resolution + margin)
    ax.set_ylim(y0 + rr.min() * resolution - margin, y0 + (rr.max() + 1) * resolution + margin)


def recall_vs_k(path: str | Path, ks: Sequence[int], curves: dict[str, tuple[np.ndarray, np.ndarray | None]],
                title: str, ylabel: str = "recall (%)") -> None:
    """Recall against number of markers, one line per method (mean, optional std band).

    ``curves`` maps a method name to (mean (len(ks),), std (len(ks),) or None).
    """
    plt = _pyplot()
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
