"""WPILib / PhotonVision ``AprilTagFieldLayout`` JSON: tag frame W with x out of the visible face,
y to a facing viewer's right, z up: ``world_from_W = world_from_marker @ MARKER_FROM_WPILIB``."""

from __future__ import annotations

import json
from typing import Sequence

import numpy as np

from markerplace.report.tagmaps.format import TAG_MAP_FORMATS, TagMapContext, TagMapFormat, quaternion_wxyz
from markerplace.runtime.atomic_io import clean_numbers

__all__ = ["MARKER_FROM_WPILIB", "WpilibLayout", "wpilib_layout"]

MARKER_FROM_WPILIB = np.array([[0.0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
"""(4, 4) pose of WPILib's tag frame in markerplace's marker frame: WPILib x = marker z (out of
the face), WPILib y = marker x (a facing viewer's right), WPILib z = marker y (up)."""


def wpilib_layout(markers: Sequence, field: tuple[float, float]) -> dict:
    """WPILib ``AprilTagFieldLayout`` JSON object: ``tags`` (ID, pose: translation x/y/z,
    rotation quaternion W/X/Y/Z) and ``field`` (length, width), metres."""
    tags = []
    for m in markers:
        T = np.asarray(m.world_from_marker, float) @ MARKER_FROM_WPILIB
        w, x, y, z = quaternion_wxyz(T[:3, :3])
        tags.append({"ID": int(m.tag_id),
                     "pose": {"translation": {"x": float(T[0, 3]), "y": float(T[1, 3]), "z": float(T[2, 3])},
                              "rotation": {"quaternion": {"W": float(w), "X": float(x), "Y": float(y), "Z": float(z)}}}})
    return {"tags": tags, "field": {"length": float(field[0]), "width": float(field[1])}}


@TAG_MAP_FORMATS.register
class WpilibLayout(TagMapFormat):
    name = "wpilib"
    summary = "WPILib / PhotonVision AprilTagFieldLayout JSON"
    file = "wpilib_field_layout.json"

    @staticmethod
    def text(markers: Sequence, context: TagMapContext) -> str:
        return json.dumps(clean_numbers(wpilib_layout(markers, context.field), None), indent=2) + "\n"
