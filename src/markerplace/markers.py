"""Marker records (AprilTag tag36h11) and their JSON file format.

A marker file is JSON: either a list of markers or an object with a ``"markers"`` list (the
format ``plan`` writes as placement.json). Each marker needs ``tag_id`` (or ``id``), ``size``
(metres, edge of the black square) and either ``world_from_marker`` (4x4 nested list) or
``position`` (x, y, z) + ``normal`` (wall normal towards viewers).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import UserError
from .geometry import marker_corners_local, transform_points, world_from_marker_pose

FAMILY = "tag36h11"
DEFAULT_TAG_SIZE = 0.4


@dataclass(frozen=True, eq=False)
class Marker:
    """One square fiducial marker.

    Attributes:
        tag_id: AprilTag id in the family.
        size: edge of the black square, metres.
        world_from_marker: (4, 4) pose; origin at the tag centre, z out of the wall.
        family: tag family name (only ``tag36h11`` is supported).
    """

    tag_id: int
    size: float
    world_from_marker: np.ndarray
    family: str = FAMILY

    @property
    def position(self) -> np.ndarray:
        """(3,) tag centre, world metres."""
        return self.world_from_marker[:3, 3]

    @property
    def normal(self) -> np.ndarray:
        """(3,) unit normal out of the wall (marker z axis), world frame."""
        return self.world_from_marker[:3, 2]

    def corners_world(self) -> np.ndarray:
        """(4, 3) black-square corners in world (order of :func:`marker_corners_local`)."""
        return transform_points(self.world_from_marker, marker_corners_local(self.size))

    def to_json(self) -> dict:
        return {
            "tag_id": int(self.tag_id),
            "family": self.family,
            "size": float(self.size),
            "position": [float(v) for v in self.position],
            "normal": [float(v) for v in self.normal],
            "world_from_marker": np.asarray(self.world_from_marker, dtype=float).tolist(),
        }


def marker_from_json(d: dict, default_size: float = DEFAULT_TAG_SIZE) -> Marker:
    """Parse one marker dict (see module docstring). Raises :class:`UserError` on bad input."""
    tag_id = d.get("tag_id", d.get("id"))
    if tag_id is None:
        raise UserError("marker entry has no 'tag_id': give each marker an AprilTag id")
    family = d.get("family", FAMILY)
    if family != FAMILY:
        raise UserError(f"marker family {family!r} is not supported: use {FAMILY}")
    size = float(d.get("size", default_size))
    if not 0.01 <= size <= 5.0:
        raise UserError(f"marker size {size} m is out of range: give the black-square edge in metres (0.01-5)")
    if "world_from_marker" in d:
        T = np.asarray(d["world_from_marker"], dtype=float)
        if T.shape != (4, 4):
            raise UserError("marker 'world_from_marker' must be a 4x4 nested list")
    elif "position" in d and "normal" in d:
        position, normal = np.asarray(d["position"], float), np.asarray(d["normal"], float)
        if position.shape != (3,) or normal.shape != (3,):
            raise UserError("marker 'position' and 'normal' must each be 3 numbers")
        T = world_from_marker_pose(position, normal)
    else:
        raise UserError("marker entry needs 'world_from_marker' or both 'position' and 'normal'")
    return Marker(int(tag_id), size, T, family)


def load_markers(path: str | Path) -> list[Marker]:
    """Read a marker JSON file. Raises :class:`UserError` with a one-line message on bad input."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"marker file not found: {path}")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise UserError(f"marker file {path} is not valid JSON ({exc.__class__.__name__}): fix or re-export it")
    entries = data.get("markers") if isinstance(data, dict) else data
    if not isinstance(entries, list):
        raise UserError(f"marker file {path} must hold a list of markers or an object with a 'markers' list")
    markers = []
    for i, entry in enumerate(entries):
        try:
            if not isinstance(entry, dict):
                raise UserError(f"entry {i} is not an object with tag_id, size, position/normal")
            markers.append(marker_from_json(entry))
        except UserError as err:
            raise UserError(f"marker file {path}, entry {i}: {err}") from None
        except (ValueError, TypeError) as err:
            raise UserError(f"marker file {path}, entry {i}: malformed value ({err}); "
                            "tag_id is an integer, size a number, position/normal 3 numbers, "
                            "world_from_marker a 4x4 list") from None
    return markers
