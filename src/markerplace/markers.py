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
from .io_utils import clean_array
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
    # at the precision JSON files are written with (io_utils.write_json): a marker written back
    # (config.json's existing markers) and read again is bit for bit the one used
    return Marker(int(tag_id), size, clean_array(T), family)


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


WALL_TOLERANCE_M = 0.05
"""An existing tag's centre must be within this of a wall surface behind it."""
MIN_OPEN_M = 0.3
"""Free space needed in front of an existing tag (else it faces into the wall or a cupboard)."""
MAX_NORMAL_Z = 0.3
"""|n_z| of an existing tag's normal: tags hang on near-vertical walls."""
MIN_WALL_ALIGNMENT = 0.85
"""|cos| between the tag normal and the wall surface behind it (about 30 deg)."""


def check_markers_on_walls(scene, markers, source: str = "markers", tolerance: float = WALL_TOLERANCE_M) -> None:
    """Refuse markers that do not hang on a wall of ``scene`` (both in the internal frame).

    Each marker needs a near-horizontal normal (|n_z| <= 0.3), a surface roughly parallel to
    the tag (|cos| >= 0.85) within ``tolerance`` metres of its centre along -normal, and at least
    0.3 m of open space in front of it (else its normal points into the wall). Rays are cast
    with :class:`~markerplace.scene.raycast.RayCaster` on ``scene.geometry()``.

    Raises:
        UserError: naming ``source``, the first offending marker's tag id and its position in
            the user's frame (:mod:`markerplace.scene.worldframe`), and what is wrong.
    """
    if not markers:
        return
    from .scene.raycast import RayCaster
    from .scene.worldframe import points_to_user, world_offset

    P = np.array([m.position for m in markers], dtype=float).reshape(-1, 3)
    N = np.array([m.normal for m in markers], dtype=float).reshape(-1, 3)
    N = N / np.maximum(np.linalg.norm(N, axis=1, keepdims=True), 1e-12)
    rc = RayCaster(*scene.geometry())
    ray, t, face = rc.all_hits(P + tolerance * N, -N, max_t=2.0 * tolerance)
    aligned = np.abs(np.einsum("ij,ij->i", rc.face_normal[face], N[ray])) >= MIN_WALL_ALIGNMENT
    on_wall = np.zeros(len(markers), dtype=bool)
    on_wall[ray[aligned]] = True
    back_t = np.full(len(markers), np.inf)
    np.minimum.at(back_t, ray[aligned], t[aligned])
    # open space in front, measured from just in front of the wall surface found behind the tag
    wall = P + tolerance * N - np.where(np.isfinite(back_t), back_t, tolerance)[:, None] * N
    front_t, _ = rc.first_hits(wall + 0.01 * N, N, max_t=MIN_OPEN_M)
    offset = world_offset(scene)
    for i, m in enumerate(markers):
        x, y, z = points_to_user(P[i], offset)
        what = f"{source}: tag {m.tag_id} at ({x:.2f}, {y:.2f}, {z:.2f})"
        if abs(N[i, 2]) > MAX_NORMAL_Z:
            raise UserError(f"{what} has normal ({N[i, 0]:.2f}, {N[i, 1]:.2f}, {N[i, 2]:.2f}), not horizontal: tags hang "
                            "on walls; give the wall's outward normal")
        if not on_wall[i]:
            raise UserError(f"{what} is not on a wall: no wall surface within {100 * tolerance:.0f} cm behind it "
                            "(along -normal); give the tag centre on the wall and the normal pointing out of it")
        if np.isfinite(front_t[i]):
            raise UserError(f"{what} faces into the wall or an obstacle: something is {front_t[i] + 0.01:.2f} m in front "
                            f"of it (under {MIN_OPEN_M:g} m); check that its normal points out of the wall into the room")
