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

from markerplace.errors import UserError
from markerplace.geometry import marker_corners_local, transform_points, world_from_marker_pose
from markerplace.jsonfile import read_json
from markerplace.runtime.atomic_io import clean_array
from markerplace.scene.raycast import RayCaster
from markerplace.scene.worldframe import points_to_user, world_offset
from markerplace.tagfamily import NUM_TAGS

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


ROTATION_TOLERANCE = 1e-3
"""Largest |R^T R - I| entry of a ``world_from_marker`` rotation read from a file (float32 round trips
and 6-digit exports stay far below it; a scaled, sheared or mirrored matrix does not)."""


def check_tag_id(value, where: str = "tag_id") -> int:
    """``value`` as a tag36h11 id: a JSON integer (not ``true``, ``1.5``, ``"3"`` or ``1e30``) in
    0..586. Raises :class:`UserError` naming ``where``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise UserError(f"{where} {_short(value)} is not an integer: give a "
                        f"{FAMILY} id, 0..{NUM_TAGS - 1}")
    if not 0 <= int(value) < NUM_TAGS:
        raise UserError(f"{where} {int(value)} is outside {FAMILY} (0..{NUM_TAGS - 1}): give the id printed on the tag")
    return int(value)


def _jsonable(value) -> bool:
    try:
        json.dumps(value)
        return True
    except (TypeError, ValueError):
        return False


def _numbers(value, shape: tuple, what: str) -> np.ndarray:
    """A nested list of JSON numbers of ``shape`` as a finite float64 array, or :class:`UserError`."""
    def ok(v) -> bool:
        if isinstance(v, list):
            return all(ok(x) for x in v)
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    if not isinstance(value, list) or not ok(value):
        raise UserError(f"'{what}' must be {_shape_text(shape)} numbers, not {_short(value)}")
    try:
        arr = np.asarray(value, dtype=float)
    except (ValueError, OverflowError):  # ragged lists, huge integers
        raise UserError(f"'{what}' must be {_shape_text(shape)} numbers, not {_short(value)}") from None
    if arr.shape != shape:
        raise UserError(f"'{what}' must be {_shape_text(shape)} numbers, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise UserError(f"'{what}' holds NaN or infinite numbers: give finite coordinates in metres")
    return arr


def _shape_text(shape: tuple) -> str:
    return "a 4x4 nested list of" if shape == (4, 4) else f"{shape[0]}"


def _short(value) -> str:
    text = json.dumps(value) if _jsonable(value) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def check_pose(T: np.ndarray, what: str = "world_from_marker", tolerance: float = ROTATION_TOLERANCE) -> np.ndarray:
    """``T`` (4, 4) if it is a rigid pose: finite, last row (0, 0, 0, 1), rotation orthonormal
    within ``tolerance`` with determinant +1; else :class:`UserError`."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise UserError(f"'{what}' must be a 4x4 matrix of finite numbers")
    if np.abs(T[3] - (0.0, 0.0, 0.0, 1.0)).max() > tolerance:
        raise UserError(f"'{what}' must have the last row 0, 0, 0, 1 (a rigid pose)")
    R = T[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > tolerance:
        raise UserError(f"'{what}' has a rotation that is not orthonormal (|R^T R - I| = {err:.2g}, tolerance "
                        f"{tolerance:g}): give a rotation without scale or shear")
    if np.linalg.det(R) < 0:
        raise UserError(f"'{what}' has a mirroring rotation (determinant -1): give a right-handed pose")
    return T


def marker_from_json(d: dict, default_size: float = DEFAULT_TAG_SIZE) -> Marker:
    """Parse one marker dict (see module docstring). Raises :class:`UserError` on bad input:
    a tag id that is not an integer of tag36h11 (:func:`check_tag_id`), a size that is not a
    number in 0.01-5 m, a pose that is not finite and rigid (:func:`check_pose`), a normal of
    length 0 or vertical."""
    if not isinstance(d, dict):
        raise UserError("not an object with tag_id, size, position/normal")
    key = "tag_id" if "tag_id" in d else "id"
    if key not in d:
        raise UserError("marker entry has no 'tag_id': give each marker an AprilTag id")
    tag_id = check_tag_id(d[key], key)
    family = d.get("family", FAMILY)
    if family != FAMILY:
        raise UserError(f"marker family {_short(family)} is not supported: use {FAMILY}")
    size = d.get("size", default_size)
    if isinstance(size, bool) or not isinstance(size, (int, float)) or not 0.01 <= size <= 5.0:
        raise UserError(f"marker size {_short(size)} is not a number of metres in 0.01-5: give the black-square edge")
    if "world_from_marker" in d:
        T = check_pose(_numbers(d["world_from_marker"], (4, 4), "world_from_marker"))
    elif "position" in d and "normal" in d:
        position = _numbers(d["position"], (3,), "position")
        normal = _numbers(d["normal"], (3,), "normal")
        if np.linalg.norm(normal[:2]) < 1e-6 * max(1.0, float(np.linalg.norm(normal))):
            raise UserError(f"'normal' {_short(d['normal'])} is zero or vertical: give the wall normal towards "
                            "viewers (tags hang on walls)")
        T = world_from_marker_pose(position, normal)
    else:
        raise UserError("marker entry needs 'world_from_marker' or both 'position' and 'normal'")
    # at the precision JSON files are written with (runtime.atomic_io.write_json): a marker written back
    # (config.json's existing markers) and read again is bit for bit the one used
    return Marker(tag_id, float(size), clean_array(T), family)


def load_markers(path: str | Path, option: str | None = None,
                 default_size: float = DEFAULT_TAG_SIZE) -> list[Marker]:
    """Read a marker JSON file (:func:`markerplace.jsonfile.read_json`'s guards). Raises
    :class:`UserError` with a one-line message on bad input, duplicate tag ids included.

    Args:
        path: the file.
        option: how the user gave it (``"--existing"``), for messages; default "marker file".
        default_size: black-square edge (metres) of entries without ``size``.
    """
    path = Path(path)
    what = f"{option} {path}" if option else f"marker file {path}"
    data = read_json(path, what)
    entries = data.get("markers") if isinstance(data, dict) else data
    if not isinstance(entries, list):
        raise UserError(f"{what} must hold a list of markers or an object with a 'markers' list")
    markers: list[Marker] = []
    seen: dict[int, int] = {}
    for i, entry in enumerate(entries):
        try:
            m = marker_from_json(entry, default_size=default_size)
        except UserError as err:
            raise UserError(f"{what}, entry {i}: {err}") from None
        if m.tag_id in seen:
            raise UserError(f"{what}: tag id {m.tag_id} is listed twice (entries {seen[m.tag_id]} and {i}); each "
                            "printed tag id hangs once")
        seen[m.tag_id] = i
        markers.append(m)
    return markers


def free_tag_ids(existing: list[Marker], first_tag_id: int = 0) -> int:
    """How many new tags can get ids of their own in tag36h11 (ids count up from
    ``first_tag_id``, skipping the ``existing`` ones); may be <= 0."""
    return NUM_TAGS - first_tag_id - sum(1 for m in existing if m.tag_id >= first_tag_id)


def check_tag_budget(k: int, existing: list[Marker], first_tag_id: int = 0) -> None:
    """Refuse a plan whose ``k`` new tags cannot get ids of their own in tag36h11 next to the
    ``existing`` ones (placed ids count up from ``first_tag_id``, skipping existing ids)."""
    free = free_tag_ids(existing, first_tag_id)
    if k > free:
        raise UserError(f"-k {k}: {FAMILY} has {NUM_TAGS} ids and {len(existing)} are taken by existing tags, so at most "
                        f"{max(free, 0)} new tags can be placed")


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
