"""Write every registered tag-map format, in the model frame and, for a scene file with another
up axis, in the file's own axes too (``*_yup.*``)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Sequence

import numpy as np

# every format module registers its class on import, in the order the files are listed; a new
# format is one more line here
# isort: off
from markerplace.report.tagmaps import wpilib  # noqa: F401
from markerplace.report.tagmaps import apriltag_ros  # noqa: F401
from markerplace.report.tagmaps import tagslam  # noqa: F401
from markerplace.report.tagmaps import ros2  # noqa: F401
# isort: on
from markerplace.report.tagmaps.format import TAG_MAP_FORMATS, TagMapContext
from markerplace.runtime.atomic_io import atomic_path

__all__ = ["write_tag_maps", "tag_map_patterns"]


def _in_file_axes(markers: Sequence, world_from_file: np.ndarray) -> list:
    F = np.eye(4)
    F[:3, :3] = np.asarray(world_from_file, float).T
    return [replace(m, world_from_marker=F @ np.asarray(m.world_from_marker, float)) for m in markers]


def _suffixed(name: str, suffix: str) -> str:
    """``name`` with ``suffix`` before its extensions (``a.launch.yaml`` -> ``a_yup.launch.yaml``)."""
    stem, _, ext = name.partition(".")
    return f"{stem}{suffix}.{ext}"


def tag_map_patterns(folder: str = "tagmaps") -> list[str]:
    """The names :func:`write_tag_maps` gives its files in ``folder``, as ``fnmatch`` patterns (the
    suffix of the file-axes copies depends on the axis) for :func:`markerplace.runtime.claims.refuse_foreign`."""
    return [f"{folder}/{name}" for fmt in TAG_MAP_FORMATS.values() for name in (fmt.file, _suffixed(fmt.file, "_*up"))]


def write_tag_maps(folder: str | Path, markers: Sequence, *, name: str, field: tuple[float, float],
                   world_from_file: np.ndarray | None = None, file_suffix: str = "_yup") -> list[Path]:
    """Write the tag maps of ``markers`` (every format of :data:`~markerplace.report.tagmaps.format.TAG_MAP_FORMATS`) into ``folder`` (atomically).

    Args:
        folder: output folder (created).
        markers: :class:`~markerplace.markers.Marker` list in the model frame (user
            coordinates, z up, metres).
        name: bundle / body name (letters, digits, ``_``).
        field: WPILib ``field`` (length, width), metres.
        world_from_file: (3, 3) the loader's up-axis rotation of the scene file; when given
            and not the identity, the maps are also written in the file's axes, with
            ``file_suffix`` before each extension.

    Returns:
        The written paths.
    """
    folder = Path(folder)
    size = float(markers[0].size) if len(markers) else 0.0
    frames = [("", markers, "the model frame: z up, metres, the user's coordinates (markerplace world)")]
    if world_from_file is not None and not np.allclose(world_from_file, np.eye(3)):
        frames.append((file_suffix, _in_file_axes(markers, world_from_file),
                       "the scene file's own axes (model frame with the up-axis rotation undone), metres"))
    written = []
    for suffix, ms, note in frames:
        context = TagMapContext(name, field, note, size)
        for fmt in TAG_MAP_FORMATS.values():
            path = folder / _suffixed(fmt.file, suffix)
            with atomic_path(path) as tmp:
                tmp.write_text(fmt.text(ms, context))
            written.append(path)
    return written
