"""TagSLAM ``bodies`` YAML: its tag frame is markerplace's marker frame (object corners
(+-s/2, +-s/2, 0) from the bottom-left); rotations are rotation vectors (axis x angle, radians)."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from markerplace.report.tagmaps.format import TAG_MAP_FORMATS, TagMapContext, TagMapFormat, rotation_vector, yaml_number

__all__ = ["TAGSLAM_POSITION_NOISE", "TAGSLAM_ROTATION_NOISE", "TagslamBodies", "tagslam_yaml"]

TAGSLAM_POSITION_NOISE = 0.01
"""TagSLAM position sigma of a planned tag, metres (how well a person hangs a tag)."""
TAGSLAM_ROTATION_NOISE = 0.02
"""TagSLAM rotation sigma of a planned tag, radians (about 1 degree)."""


def tagslam_yaml(markers: Sequence, name: str, frame_note: str, default_size: float) -> str:
    """TagSLAM ``bodies`` text: one static body (the building, identity pose, pinned) whose
    ``tags`` list has each tag's id, size (metres) and pose (position, rotation vector, noise)."""

    def vec(v) -> str:
        return "{" + ", ".join(f"{k}: {yaml_number(x)}" for k, x in zip("xyz", v)) + "}"

    pn, rn = vec([TAGSLAM_POSITION_NOISE] * 3), vec([TAGSLAM_ROTATION_NOISE] * 3)
    lines = [
        "# TagSLAM known tags written by markerplace (tag family tag36h11)",
        f"# body frame: {frame_note}",
        "# tag frame: origin at the tag centre, x right and y up as a facing viewer sees the tag, z out of the wall;",
        "# rotation: rotation vector (axis x angle, radians); noise: sigmas (metres, radians)",
        "bodies:",
        f" - {name}:",
        "     is_static: true",
        f"     default_tag_size: {yaml_number(default_size)}",
        "     pose:",
        f"       position: {vec([0, 0, 0])}",
        f"       rotation: {vec([0, 0, 0])}",
        f"       position_noise: {vec([1e-4] * 3)}",
        f"       rotation_noise: {vec([1e-5] * 3)}",
        "     type: simple",
        "     tags:",
    ]
    for m in markers:
        T = np.asarray(m.world_from_marker, float)
        lines += [f"       - id: {int(m.tag_id)}",
                  f"         size: {yaml_number(m.size)}",
                  "         pose:",
                  f"           position: {vec(T[:3, 3])}",
                  f"           rotation: {vec(rotation_vector(T[:3, :3]))}",
                  f"           position_noise: {pn}",
                  f"           rotation_noise: {rn}"]
    if not markers:
        lines[-1] = "     tags: []"
    return "\n".join(lines) + "\n"


@TAG_MAP_FORMATS.register
class TagslamBodies(TagMapFormat):
    name = "tagslam"
    summary = "TagSLAM known tags (bodies)"
    file = "tagslam_tags.yaml"

    @staticmethod
    def text(markers: Sequence, context: TagMapContext) -> str:
        return tagslam_yaml(markers, context.name, context.frame_note, context.default_size)
