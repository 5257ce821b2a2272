"""ROS 2 (the ``apriltag_ros`` node of christianrauch/apriltag_ros, the AprilTag node of ROS 2
Humble/Jazzy): a parameter file (``tag.ids``/``frames``/``sizes``, family ``36h11``, pose
estimation ``pnp``) and a YAML launch file of ``tf2_ros static_transform_publisher`` nodes,
``map`` -> ``map_tag36h11_<id>`` per tag; two formats of one stack, so one module."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from markerplace.report.tagmaps.format import TAG_MAP_FORMATS, TagMapContext, TagMapFormat, quaternion_wxyz, yaml_number

__all__ = ["ROS2_MAP_FRAME", "Ros2Params", "Ros2Transforms", "ros2_known_frame", "ros2_params_yaml", "ros2_tag_frame",
           "ros2_transforms_launch"]


ROS2_MAP_FRAME = "map"
"""Parent frame of the ROS 2 static transforms: REP 105's world-fixed frame (the model frame)."""


def ros2_tag_frame(tag_id: int) -> str:
    """The child frame the ROS 2 apriltag node publishes for a detected tag (set in the
    parameter file's ``tag.frames``)."""
    return f"tag36h11_{int(tag_id)}"


def ros2_known_frame(tag_id: int) -> str:
    """The frame of the tag as installed, child of :data:`ROS2_MAP_FRAME` in the static transforms."""
    return f"{ROS2_MAP_FRAME}_tag36h11_{int(tag_id)}"


def ros2_params_yaml(markers: Sequence, default_size: float, frame_note: str) -> str:
    """ROS 2 parameter file of the ``apriltag_ros`` node (``apriltag_node``; christianrauch/
    apriltag_ros): family ``36h11``, ``pnp`` pose estimation, and ``tag.ids``, ``tag.frames``,
    ``tag.sizes`` (black-square edge, metres) of every tag, so the node publishes only these tags
    under the frame names the static transforms use."""
    ids = [int(m.tag_id) for m in markers]
    frames = [ros2_tag_frame(i) for i in ids]
    sizes = [yaml_number(m.size) for m in markers]
    return "\n".join([
        "# ROS 2 apriltag_ros node parameters written by markerplace:",
        "#   ros2 run apriltag_ros apriltag_node --ros-args -r image_rect:=<image> -r camera_info:=<info> \\",
        "#     --params-file ros2_apriltag_params.yaml",
        "# The node publishes <camera optical frame> -> tag36h11_<id> on /tf; tag frame: origin at the",
        "# tag centre, x right and y up as a facing viewer sees the tag, z out of the wall towards the camera.",
        f"# Known poses of the same tags: ros2_tag_transforms.launch.yaml ({ROS2_MAP_FRAME} -> map_tag36h11_<id>; {frame_note}).",
        "/**:",
        "  ros__parameters:",
        "    image_transport: raw",
        "    family: 36h11",
        f"    size: {yaml_number(default_size)}",
        "    max_hamming: 0",
        "    pose_estimation_method: pnp",
        "    tag:",
        f"      ids: [{', '.join(str(i) for i in ids)}]",
        f"      frames: [{', '.join(frames)}]",
        f"      sizes: [{', '.join(sizes)}]",
        ""])


def ros2_transforms_launch(markers: Sequence, frame_note: str) -> str:
    """ROS 2 YAML launch file: one ``tf2_ros static_transform_publisher`` per tag publishing
    ``map`` -> ``map_tag36h11_<id>`` (translation in metres, quaternion x, y, z, w; the tag frame
    M), run with ``ros2 launch ros2_tag_transforms.launch.yaml``."""
    lines = [
        "# ROS 2 static transforms of the installed tags, written by markerplace:",
        "#   ros2 launch ros2_tag_transforms.launch.yaml",
        f"# {ROS2_MAP_FRAME}: {frame_note}",
        "# map_tag36h11_<id>: the tag as installed; origin at the tag centre, x right and y up as a facing",
        "# viewer sees the tag, z out of the wall (the frame the apriltag node calls tag36h11_<id>).",
        "launch:",
    ]
    for m in markers:
        T = np.asarray(m.world_from_marker, float)
        qw, qx, qy, qz = quaternion_wxyz(T[:3, :3])
        args = " ".join(f"--{k} {yaml_number(v)}" for k, v in zip(("x", "y", "z", "qx", "qy", "qz", "qw"),
                                                            (*T[:3, 3], qx, qy, qz, qw)))
        lines += ["- node:",
                  "    pkg: tf2_ros",
                  "    exec: static_transform_publisher",
                  f"    name: {ros2_known_frame(m.tag_id)}_publisher",
                  f"    args: \"{args} --frame-id {ROS2_MAP_FRAME} --child-frame-id {ros2_known_frame(m.tag_id)}\""]
    if not markers:
        lines[-1] = "launch: []"
    return "\n".join(lines) + "\n"


@TAG_MAP_FORMATS.register
class Ros2Params(TagMapFormat):
    name = "ros2_params"
    summary = "ROS 2 apriltag_ros node parameters"
    file = "ros2_apriltag_params.yaml"

    @staticmethod
    def text(markers: Sequence, context: TagMapContext) -> str:
        return ros2_params_yaml(markers, context.default_size, context.frame_note)


@TAG_MAP_FORMATS.register
class Ros2Transforms(TagMapFormat):
    name = "ros2_transforms"
    summary = "ROS 2 static transforms of the tags (launch file)"
    file = "ros2_tag_transforms.launch.yaml"

    @staticmethod
    def text(markers: Sequence, context: TagMapContext) -> str:
        return ros2_transforms_launch(markers, context.frame_note)
