"""The discretize stage's artifact: :class:`Discretization` (feasible camera poses and candidate
marker poses of the planned storeys) and its file, ``discretization.npz`` in the run folder.

Made by :func:`markerplace.plan.discretize.stage.discretize`; :func:`save` writes it as a compressed
``.npz`` of plain arrays (no pickled objects; the summary as JSON text), :func:`load` reads it.
Poses are 4x4 ``world_from_cam`` / ``world_from_marker`` (OpenCV camera; marker z out of the
wall, y up; see :mod:`markerplace.geometry`).

Frames: world z up, metres (see :mod:`markerplace.geometry`). The occupancy grids have row 0 at
``grid_origin[1]`` and column 0 at ``grid_origin[0]`` (the lower-left corner), cells of
``grid_resolution`` metres; cell (r, c) has centre ``origin + ((c + .5) res, (r + .5) res)``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from markerplace.runtime.atomic_io import write_npz

__all__ = ["Discretization", "save", "load"]


@dataclass(frozen=True, eq=False)
class Discretization:
    """Feasible camera poses and candidate marker poses of the planned storeys.

    Attributes:
        locations: (L, 2) camera locations, world xy metres.
        location_z: (L,) camera heights, world z metres (eye level above the local floor).
        location_storey: (L,) storey index (into ``storeys``) of each location.
        world_from_cam: (N, 4, 4) feasible camera poses, N = L * num_yaws, location-major
            (pose i is at location ``location_index[i]`` with yaw ``yaw[i]``).
        location_index: (N,) int64 index into ``locations``.
        yaw: (N,) radians, 2 pi j / num_yaws.
        candidate_world_from_marker: (C, 4, 4) candidate marker poses (tag centre on the wall,
            z = wall normal towards the free space), ordered by storey, then
            ``perimeter_arclength``.
        candidate_normal: (C, 3) unit horizontal wall normals (towards the free space).
        candidate_position: (C, 3) tag centres, world metres.
        candidate_storey: (C,) storey index of each candidate.
        candidate_surface: (C,) str: what each candidate is on (``"wall"``, ``"column"``, or for
            a category ``plan --allow`` allowed e.g. ``"bookshelf front"``, ``"door"``; see
            :mod:`markerplace.plan.discretize.wall_candidates`); ``""`` when not known.
        candidate_part: (C,) str: the name of the mesh part under each candidate's centre.
        perimeter_arclength: (C,) position of each candidate along the free-space perimeter,
            metres in [0, perimeter_length] (the storeys' perimeter loops concatenated).
        perimeter_length: total length of the free-space perimeter loops, metres.
        occupancy: (S, H, W) int8 grid per planned storey: -1 not free, 0 free, 1 obstacle.
        planned_storeys: (S,) storey indices of the planned storeys (the occupancy layers).
        grid_origin: (2,) world xy of the grids' lower-left corner, metres.
        grid_resolution: cell size, metres.
        storeys: (S_all,) floor heights of all storeys found, world metres, ascending.
        start: (2,) xy of ``start`` or, without it, the most open point of the first storey.
        summary: JSON-ready dict: per storey areas, counts, removed candidates, unreached regions.
    """

    locations: np.ndarray
    location_z: np.ndarray
    location_storey: np.ndarray
    world_from_cam: np.ndarray
    location_index: np.ndarray
    yaw: np.ndarray
    candidate_world_from_marker: np.ndarray
    candidate_normal: np.ndarray
    candidate_position: np.ndarray
    candidate_storey: np.ndarray
    perimeter_arclength: np.ndarray
    perimeter_length: float
    occupancy: np.ndarray
    planned_storeys: np.ndarray
    grid_origin: np.ndarray
    grid_resolution: float
    storeys: np.ndarray
    start: np.ndarray = field(default_factory=lambda: np.zeros(2))
    summary: dict = field(default_factory=dict)
    candidate_surface: np.ndarray | None = None
    candidate_part: np.ndarray | None = None

    def __post_init__(self) -> None:
        """Unknown surfaces (an artifact from before they were recorded) become ``""``."""
        C = len(self.candidate_position)
        for name in ("candidate_surface", "candidate_part"):
            value = getattr(self, name)
            value = np.full(C, "", "<U1") if value is None or len(value) != C else np.asarray(value, dtype=str)
            object.__setattr__(self, name, value)

    @property
    def origin(self) -> np.ndarray:
        """Alias of :attr:`grid_origin`."""
        return self.grid_origin

    @property
    def resolution(self) -> float:
        """Alias of :attr:`grid_resolution`."""
        return self.grid_resolution

    @property
    def num_yaws(self) -> int:
        return int(len(self.world_from_cam) // max(len(self.locations), 1))

    @property
    def floor_z(self) -> float:
        """Floor height of the first planned storey, world metres."""
        return float(self.storeys[int(self.planned_storeys[0])])

    @property
    def pose_storey(self) -> np.ndarray:
        """(N,) storey index of each camera pose."""
        return self.location_storey[self.location_index]

    def occupancy_of(self, storey: int) -> np.ndarray:
        """(H, W) occupancy layer of a planned storey (by storey index)."""
        slot = np.flatnonzero(self.planned_storeys == storey)
        if len(slot) == 0:
            raise KeyError(f"storey {storey} was not planned")
        return self.occupancy[int(slot[0])]

    def with_candidates(self, keep: np.ndarray) -> "Discretization":
        """A copy keeping only the candidates where (C,) bool ``keep`` is true."""
        keep = np.asarray(keep, dtype=bool)
        return replace(self, candidate_world_from_marker=self.candidate_world_from_marker[keep],
                       candidate_normal=self.candidate_normal[keep], candidate_position=self.candidate_position[keep],
                       candidate_storey=self.candidate_storey[keep], perimeter_arclength=self.perimeter_arclength[keep],
                       candidate_surface=self.candidate_surface[keep], candidate_part=self.candidate_part[keep])


_ARRAY_FIELDS = ("locations", "location_z", "location_storey", "world_from_cam", "location_index", "yaw",
                 "candidate_world_from_marker", "candidate_normal", "candidate_position", "candidate_storey",
                 "perimeter_arclength", "occupancy", "planned_storeys", "grid_origin", "storeys", "start")
_SCALAR_FIELDS = ("perimeter_length", "grid_resolution")
_TEXT_FIELDS = ("candidate_surface", "candidate_part")  # fixed-width unicode arrays (no pickle)


def save(d: Discretization, path: str | Path) -> None:
    """Write ``d`` to a compressed ``.npz`` (atomic, no pickled objects)."""
    arrays = {k: np.asarray(getattr(d, k)) for k in _ARRAY_FIELDS}
    arrays.update({k: np.asarray(float(getattr(d, k))) for k in _SCALAR_FIELDS})
    arrays.update({k: np.asarray(getattr(d, k), dtype=str) for k in _TEXT_FIELDS})
    arrays["summary_json"] = np.asarray(json.dumps(d.summary, default=_json_default))
    write_npz(path, **arrays)


def load(path: str | Path) -> Discretization:
    """Read a :class:`Discretization` written by :func:`save`."""
    with np.load(path, allow_pickle=False) as z:
        kw = {k: z[k] for k in _ARRAY_FIELDS}
        kw.update({k: float(z[k]) for k in _SCALAR_FIELDS})
        kw.update({k: z[k] for k in _TEXT_FIELDS if k in z.files})
        kw["summary"] = json.loads(str(z["summary_json"]))
    return Discretization(**kw)


def _json_default(obj):
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (np.floating, np.integer, np.bool_)):
        return obj.item()
    raise TypeError(type(obj))
