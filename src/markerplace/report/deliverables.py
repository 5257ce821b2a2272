"""What a plan hands to the person with the ladder and to the robot: ``tags.pdf`` and the
known-tag maps (``tagmaps/``), written by :func:`markerplace.report.plan_outputs.write_plan_outputs`.

Everything here is in the user's frame (z up, metres, the file's coordinates; the caller has
already undone the recentring offset of :mod:`markerplace.scene.worldframe`).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.report.pdf import write_tags_pdf
from markerplace.report.tagmaps.write import write_tag_maps
from markerplace.runtime import run_folder
from markerplace.scene.source import file_up_axis, world_from_file_rotation

__all__ = ["write_deliverables", "write_known_tag_maps", "field_extent"]


def field_extent(disc) -> tuple[float, float]:
    """WPILib ``field`` (length, width) in metres: the far x and y edges of the discretization's
    floor grid (``disc`` in the user frame), measured from the frame's origin, at least 0."""
    occ = np.asarray(disc.occupancy)
    x_max = float(disc.grid_origin[0]) + occ.shape[-1] * float(disc.grid_resolution)
    y_max = float(disc.grid_origin[1]) + occ.shape[-2] * float(disc.grid_resolution)
    return max(x_max, 0.0), max(y_max, 0.0)


def write_deliverables(out_dir: str | Path, records: Sequence[dict], markers: Sequence, existing: Sequence, disc,
                       scene_source: str, scene_options: dict | None, paper: str = "a4") -> None:
    """Write ``tags.pdf`` (the placed tags, ``records`` as in placement.json) and ``tagmaps/``
    (placed and existing markers: every tag on the walls), all in the user frame.

    ``scene_options`` (``up``, ``unit_scale``, ``seed``) tells the file's axes: for a mesh file
    whose up axis is not z (every glTF) the maps are also written in the file's axes.
    """
    out_dir = Path(out_dir)
    write_tags_pdf(out_dir / "tags.pdf", records, paper)
    name = re.sub(r"\W+", "_", Path(str(scene_source)).stem).strip("_") or "markerplace"
    write_known_tag_maps(out_dir / "tagmaps", list(markers) + list(existing), name, disc, scene_source,
                         (scene_options or {}).get("up"))


def write_known_tag_maps(folder: Path, markers: Sequence, name: str, disc, scene_source: str, up: str | None) -> list:
    """``tagmaps/``: the known-tag maps of ``markers`` (user frame) in the model frame and, for a
    file whose up axis is not z, in the file's axes (``*_<axis>up.*``); maps an earlier run
    wrote in other axes are removed (other files are left alone). Returns the files written."""
    axis = file_up_axis(scene_source, up)
    written = write_tag_maps(folder, list(markers), name=name, field=field_extent(disc),
                             world_from_file=world_from_file_rotation(scene_source, up),
                             file_suffix=f"_{axis.replace('-', 'neg')}up" if axis else "_yup")
    run_folder.remove_stale(folder, written)  # maps of an earlier run in other axes
    return written
