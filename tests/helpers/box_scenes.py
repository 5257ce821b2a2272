"""Hand-built box scenes of the discretization tests: walls, floors and furniture as boxes and
quads (two rooms a = [0, 5] x [0, 4] and b = [5, 9] x [0, 4] with a 0.9 m door at x = 5)."""

from __future__ import annotations

import numpy as np

from markerplace.scene.types import MeshPart

T = 0.1  # wall thickness
H = 2.7  # ceiling


def box(name, lo, hi):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float32)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                  [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], np.int32)
    return MeshPart(name, v, f)


def quad(name, corners):
    return MeshPart(name, np.asarray(corners, np.float32), np.array([[0, 1, 2], [0, 2, 3]], np.int32))


# obstacles cut by the plane z = 1.5 as xy rectangles (xmin, ymin, xmax, ymax)
WALLS = [(-T / 2, -T / 2, 9 + T / 2, T / 2), (-T / 2, 4 - T / 2, 9 + T / 2, 4 + T / 2),
         (-T / 2, -T / 2, T / 2, 4 + T / 2), (9 - T / 2, -T / 2, 9 + T / 2, 4 + T / 2),
         (5 - T / 2, 0, 5 + T / 2, 1.5), (5 - T / 2, 2.4, 5 + T / 2, 4)]
SHELF = (7.0, 3.5, 8.9, 3.95)
TABLE = (1.0, 1.0, 2.2, 2.0)
RECTS = WALLS + [SHELF]
DOOR_Y = (1.5, 2.4)


def two_rooms(z0: float = 0.0, rooms: bool = True, prefix: str = "") -> list[MeshPart]:
    """Rooms a = [0, 5] x [0, 4] and b = [5, 9] x [0, 4], a 0.9 m door at x = 5, a table, a shelf."""
    parts = [quad(prefix + "floor", [[0, 0, z0], [9, 0, z0], [9, 4, z0], [0, 4, z0]]),
             quad(prefix + "ceiling", [[0, 0, z0 + H], [0, 4, z0 + H], [9, 4, z0 + H], [9, 0, z0 + H]])]
    for i, (x0, y0, x1, y1) in enumerate(WALLS):
        parts.append(box(f"{prefix}wall{i}", (x0, y0, z0), (x1, y1, z0 + H)))
    parts.append(box(prefix + "lintel", (5 - T / 2, DOOR_Y[0], z0 + 2.1), (5 + T / 2, DOOR_Y[1], z0 + H)))
    parts.append(box(prefix + "table", (TABLE[0], TABLE[1], z0), (TABLE[2], TABLE[3], z0 + 0.75)))
    parts.append(box(prefix + "shelf", (SHELF[0], SHELF[1], z0), (SHELF[2], SHELF[3], z0 + 2.0)))
    return parts
