"""apriltag_ros (ROS 1) tag bundle YAML: its tag frame is markerplace's marker frame (object
corners (+-s/2, +-s/2, 0) counter-clockwise from the bottom-left, z out of the tag): the layout
pose is ``world_from_marker``, the bundle frame is the model frame."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from markerplace.report.tagmaps.format import TAG_MAP_FORMATS, TagMapContext, TagMapFormat, quaternion_wxyz, yaml_number

__all__ = ["ApriltagRosBundle", "apriltag_ros_yaml"]


def apriltag_ros_yaml(markers: Sequence, name: str, frame_note: str) -> str:
    """apriltag_ros ``tags.yaml`` text: one ``tag_bundles`` entry whose ``layout`` holds every
    tag (id, size = black-square edge in metres, x, y, z, qw, qx, qy, qz) in the bundle frame."""
    rows = []
    for m in markers:
        T = np.asarray(m.world_from_marker, float)
        qw, qx, qy, qz = quaternion_wxyz(T[:3, :3])
        vals = ", ".join(f"{k}: {yaml_number(v)}" for k, v in
                         zip(("x", "y", "z", "qw", "qx", "qy", "qz"), (*T[:3, 3], qw, qx, qy, qz)))
        rows.append(f"          {{id: {int(m.tag_id)}, size: {yaml_number(m.size)}, {vals}}}")
    return "\n".join([
        "# apriltag_ros (ROS 1) tag bundle written by markerplace (tag family tag36h11: set tag_family in settings.yaml)",
        f"# bundle frame: {frame_note}",
        "# tag frame: origin at the tag centre, x right and y up as a facing viewer sees the tag, z out of the wall",
        "standalone_tags:",
        "  [",
        "  ]",
        "tag_bundles:",
        "  [",
        "    {",
        f"      name: '{name}',",
        "      layout:",
        "        [",
        ",\n".join(rows),
        "        ]",
        "    }",
        "  ]",
        ""])


@TAG_MAP_FORMATS.register
class ApriltagRosBundle(TagMapFormat):
    name = "apriltag_ros"
    summary = "apriltag_ros (ROS 1) tag bundle"
    file = "apriltag_ros_bundle.yaml"

    @staticmethod
    def text(markers: Sequence, context: TagMapContext) -> str:
        return apriltag_ros_yaml(markers, context.name, context.frame_note)
