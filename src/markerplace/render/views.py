"""Default camera poses and writing render outputs to disk."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplace.geometry import world_from_cam_pose
from markerplace.runtime.atomic_io import write_image, write_npy
from markerplace.scene.types import Scene

EYE_HEIGHT = 1.5
"""Camera height above the floor, metres."""


def default_pose(scene: Scene) -> np.ndarray:
    """(4, 4) ``world_from_cam`` of a sensible level view inside ``scene``.

    With rooms: centre of the largest room, ``EYE_HEIGHT`` above ``scene.floor_z`` (or the
    bounding-box bottom), looking along the room's longer axis (+x or +y). Without rooms: the
    bounding-box centre in xy, ``EYE_HEIGHT`` above the bounding-box bottom, looking along +x
    if the box is longer in x, else +y.
    """
    bounds = scene.bounds
    floor = float(scene.floor_z) if scene.floor_z is not None else float(bounds[0, 2])
    if scene.rooms:
        room = max(scene.rooms, key=lambda r: r.area)
        x0, y0, x1, y1 = room.bounds
    else:
        x0, y0 = bounds[0, :2]
        x1, y1 = bounds[1, :2]
        floor = float(bounds[0, 2])
    centre = np.array([(x0 + x1) / 2.0, (y0 + y1) / 2.0, floor + EYE_HEIGHT])
    yaw = 0.0 if (x1 - x0) >= (y1 - y0) else np.pi / 2.0
    return world_from_cam_pose(centre, yaw)


def normal_to_image(normal: np.ndarray) -> np.ndarray:
    """(H, W, 3) float normals in [-1, 1] -> (H, W, 3) uint8 image ``(n + 1) / 2 * 255``."""
    return np.clip(np.round((np.asarray(normal, dtype=np.float64) + 1.0) * 127.5), 0, 255).astype(np.uint8)


def write_render_outputs(prefix: str | Path, result) -> list[Path]:
    """Write a :class:`~markerplace.render.renderer.RenderResult` next to ``prefix``.

    Writes ``PREFIX_rgb.png``, ``PREFIX_depth.npy`` (float32 planar depth, metres, 0 = no hit)
    and ``PREFIX_normal.png`` (world normals as ``(n + 1) / 2 * 255``), atomically, creating
    parent directories. Outputs that are None in ``result`` are skipped.

    Returns:
        The paths written.
    """
    prefix = str(prefix)
    paths: list[Path] = []
    if result.rgb is not None:
        p = Path(prefix + "_rgb.png")
        write_image(p, result.rgb)
        paths.append(p)
    if result.depth is not None:
        p = Path(prefix + "_depth.npy")
        write_npy(p, np.asarray(result.depth, dtype=np.float32))
        paths.append(p)
    if result.normal is not None:
        p = Path(prefix + "_normal.png")
        write_image(p, normal_to_image(result.normal))
        paths.append(p)
    return paths
