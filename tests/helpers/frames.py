"""A short handheld-like RGB-D sequence of the built-in ``tiny`` room (inner wall faces
at x, y = 0.05 and 3.55) written in the markerplace layout, for the ``plan --frames`` tests.

The camera walks a loop 0.9 m inside the walls at 1.3-1.6 m, looking outwards at the walls
(yaw turning with the loop), pitched -35..+10 degrees and rolled a few degrees: 6-DoF poses, none
level. Frames come from the scan simulator (:class:`~markerplace.scan.simulate.FrameSimulator`:
rendered colour, noisy Kinect-like depth in millimetres), 320 x 240.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

TINY_WALLS = (0.05, 3.55)
"""The ``tiny`` room's inner wall faces (x and y), metres."""


def tiny_poses(n: int = 40) -> np.ndarray:
    """(n, 4, 4) world_from_cam of the loop (module docstring)."""
    from markerplace.scan.walk import world_from_cam_ypr

    out = []
    c = 1.8
    for j in range(n):
        a = 2 * math.pi * j / n
        pos = np.array([c + 0.9 * math.cos(a), c + 0.9 * math.sin(a), 1.45 + 0.15 * math.sin(3 * a)])
        yaw = a + 0.5 * math.sin(2 * a)
        pitch = math.radians(-35 + 45 * (0.5 + 0.5 * math.sin(5 * a)))
        roll = math.radians(4 * math.sin(7 * a))
        out.append(world_from_cam_ypr(pos, yaw, pitch, roll))
    return np.array(out)


def write_tiny_frames(root: str | Path, n: int = 40, seed: int = 0, size: tuple[int, int] = (320, 240)) -> Path:
    """Write the sequence into ``root`` (markerplace layout) at ``size`` (width, height; the
    focal length scales with the width, 262.5 at 320) and return it."""
    from markerplace.scan.frames import FrameWriter
    from markerplace.scan.simulate import FrameSimulator, ScanConfig
    from markerplace.scan.walk import seeded_rng
    from markerplace.scene import load_scene

    root = Path(root)
    cfg = ScanConfig(width=size[0], height=size[1], fx=262.5 * size[0] / 320, fy=262.5 * size[0] / 320)
    rng = seeded_rng(seed, 7)
    with FrameSimulator(load_scene("tiny"), cfg) as sim, FrameWriter(root, cfg.intrinsics) as writer:
        for j, T in enumerate(tiny_poses(n)):
            rgb, depth = sim.frame(T, rng)
            writer.write(f"f{j:03d}", rgb, depth, T)
    return root
