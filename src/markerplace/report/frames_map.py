"""``camera_path.png`` of a frames plan (``plan --frames``): the top-down grid (free where the
cameras went, obstacles), the frames' camera path with each pose's heading, the candidate spots
and the placed tags, in the frames' world frame (metres)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.runtime.atomic_io import atomic_path

__all__ = ["camera_path_map"]


def camera_path_map(path: str | Path, disc, markers: Sequence, offset: np.ndarray, title: str) -> Path:
    """Write the map (module docstring); ``disc`` and ``markers`` in the internal frame, moved
    to the user frame by ``offset`` (3,)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    off = np.asarray(offset, float)[:2]
    occ = disc.occupancy[0]
    res = float(disc.grid_resolution)
    x0, y0 = np.asarray(disc.grid_origin, float) + off
    H, W = occ.shape
    img = np.full((H, W, 3), 0.85)
    img[occ == 0] = 1.0
    img[occ == 1] = 0.35
    fig, ax = plt.subplots(figsize=(7, 7 * max(H, 1) / max(W, 1) + 0.6))
    ax.imshow(img, origin="lower", extent=(x0, x0 + W * res, y0, y0 + H * res), interpolation="nearest")
    xy = disc.locations + off
    ax.plot(xy[:, 0], xy[:, 1], "-", color="tab:blue", lw=1.0, label="camera path")
    step = max(1, len(xy) // 60)
    head = np.column_stack([np.cos(disc.yaw), np.sin(disc.yaw)])[::step] * 0.25
    ax.quiver(xy[::step, 0], xy[::step, 1], head[:, 0], head[:, 1], color="tab:blue", angles="xy", scale_units="xy",
              scale=1, width=0.003)
    if len(xy):
        ax.plot(*xy[0], "o", color="tab:green", label="first frame")
    cand = disc.candidate_position[:, :2] + off
    ax.plot(cand[:, 0], cand[:, 1], ".", color="tab:orange", ms=4, label="candidate spots")
    for i, m in enumerate(markers):
        p = np.asarray(m.position, float)[:2] + off
        ax.plot(*p, "s", color="tab:red", ms=7)
        ax.annotate(str(i + 1), p, textcoords="offset points", xytext=(4, 4), color="tab:red", fontsize=9)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=9)
    ax.legend(loc="best", fontsize=7)
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    return path
