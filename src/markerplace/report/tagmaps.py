"""Known-tag maps for localization systems: WPILib / PhotonVision, apriltag_ros (ROS 1 and ROS 2),
TagSLAM.

Every file holds the placed tags' poses in one frame, metres:

* the **model frame** (default): markerplace's world, z up, in the user's coordinates (the file's
  coordinates rotated to z up and scaled to metres; the loader's recentring is undone, see
  :mod:`markerplace.scene.worldframe`);
* the **file axes** (``*_yup.*`` for a y-up file such as any glTF): the same poses with the
  loader's up-axis rotation undone, ``p_file_axes = R^T p_model`` with ``R`` the loader's
  ``world_from_file`` rotation (:func:`markerplace.scene.loader.up_rotation`); still metres.

Each format has its own tag frame; docs/tag_maps.md has the pictures in words. In short, with
markerplace's marker frame M (origin at the tag centre, z out of the wall towards viewers, x to
a facing viewer's right, y up):

* WPILib / PhotonVision ``AprilTagFieldLayout`` JSON: tag frame W with x out of the visible
  face, y to a facing viewer's right, z up: ``world_from_W = world_from_marker @ MARKER_FROM_WPILIB``.
* apriltag_ros tag bundle YAML: its tag frame is M (object corners (+-s/2, +-s/2, 0)
  counter-clockwise from the bottom-left, z out of the tag): the layout pose is ``world_from_marker``,
  the bundle frame is the model frame.
* TagSLAM ``bodies`` YAML: its tag frame is M too (object corners (+-s/2, +-s/2, 0) from the
  bottom-left); rotations are rotation vectors (axis x angle, radians).
* ROS 2 (the ``apriltag_ros`` node of christianrauch/apriltag_ros, the AprilTag node of ROS 2
  Humble/Jazzy): a parameter file (``tag.ids``/``frames``/``sizes``, family ``36h11``, pose
  estimation ``pnp``) and a YAML launch file of ``tf2_ros static_transform_publisher`` nodes,
  ``map`` -> ``map_tag36h11_<id>`` per tag. The node's tag frame is M (its ``pnp`` object points
  are (-s/2, -s/2, 0), (s/2, -s/2, 0), (s/2, s/2, 0), (-s/2, s/2, 0) for the detector's corners
  BL, BR, TR, TL), and it publishes ``camera optical frame -> tag36h11_<id>``, so
  ``map_from_camera = map_from_(map_tag36h11_<id>) @ inverse(camera_from_(tag36h11_<id>))``: the
  two tag frames are one physical frame under two names (a tf2 frame has one parent).

Numbers are written with Python's shortest round-trip repr (never ``-0.0``:
:func:`markerplace.runtime.atomic_io.clean_float` without rounding), so reading a file back gives the
poses to the last bit of the quaternion / rotation-vector conversion (well under 1e-9).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Sequence

import numpy as np

from markerplace.runtime.atomic_io import atomic_path, clean_float, clean_numbers

MARKER_FROM_WPILIB = np.array([[0.0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
"""(4, 4) pose of WPILib's tag frame in markerplace's marker frame: WPILib x = marker z (out of
the face), WPILib y = marker x (a facing viewer's right), WPILib z = marker y (up)."""
TAGSLAM_POSITION_NOISE = 0.01
"""TagSLAM position sigma of a planned tag, metres (how well a person hangs a tag)."""
TAGSLAM_ROTATION_NOISE = 0.02
"""TagSLAM rotation sigma of a planned tag, radians (about 1 degree)."""
FILES = {"wpilib": "wpilib_field_layout.json", "apriltag_ros": "apriltag_ros_bundle.yaml",
         "tagslam": "tagslam_tags.yaml", "ros2_params": "ros2_apriltag_params.yaml",
         "ros2_transforms": "ros2_tag_transforms.launch.yaml"}
"""File name per format, in the model frame; file-axes versions insert a suffix before the extension."""


def quaternion_wxyz(R: np.ndarray) -> np.ndarray:
    """(4,) unit quaternion (w, x, y, z), w >= 0, of a (3, 3) rotation matrix."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    q = np.array([w, x, y, z])
    return -q if q[0] < 0 else q


def rotation_vector(R: np.ndarray) -> np.ndarray:
    """(3,) axis x angle (radians) of a (3, 3) rotation matrix (angle in [0, pi])."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(np.asarray(R, float)).as_rotvec()


def _num(v: float) -> str:
    """A float as YAML 1.1 and 1.2 both read it back exactly (``1e-05`` -> ``1.0e-05``)."""
    s = repr(clean_float(v, None))  # exact, never -0.0
    if "e" in s and "." not in s.split("e")[0]:
        s = s.replace("e", ".0e", 1)
    return s


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


def apriltag_ros_yaml(markers: Sequence, name: str, frame_note: str) -> str:
    """apriltag_ros ``tags.yaml`` text: one ``tag_bundles`` entry whose ``layout`` holds every
    tag (id, size = black-square edge in metres, x, y, z, qw, qx, qy, qz) in the bundle frame."""
    rows = []
    for m in markers:
        T = np.asarray(m.world_from_marker, float)
        qw, qx, qy, qz = quaternion_wxyz(T[:3, :3])
        vals = ", ".join(f"{k}: {_num(v)}" for k, v in
                         zip(("x", "y", "z", "qw", "qx", "qy", "qz"), (*T[:3, 3], qw, qx, qy, qz)))
        rows.append(f"          {{id: {int(m.tag_id)}, size: {_num(m.size)}, {vals}}}")
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
    sizes = [_num(m.size) for m in markers]
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
        f"    size: {_num(default_size)}",
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
        args = " ".join(f"--{k} {_num(v)}" for k, v in zip(("x", "y", "z", "qx", "qy", "qz", "qw"),
                                                            (*T[:3, 3], qx, qy, qz, qw)))
        lines += ["- node:",
                  "    pkg: tf2_ros",
                  "    exec: static_transform_publisher",
                  f"    name: {ros2_known_frame(m.tag_id)}_publisher",
                  f"    args: \"{args} --frame-id {ROS2_MAP_FRAME} --child-frame-id {ros2_known_frame(m.tag_id)}\""]
    if not markers:
        lines[-1] = "launch: []"
    return "\n".join(lines) + "\n"


def tagslam_yaml(markers: Sequence, name: str, frame_note: str, default_size: float) -> str:
    """TagSLAM ``bodies`` text: one static body (the building, identity pose, pinned) whose
    ``tags`` list has each tag's id, size (metres) and pose (position, rotation vector, noise)."""

    def vec(v) -> str:
        return "{" + ", ".join(f"{k}: {_num(x)}" for k, x in zip("xyz", v)) + "}"

    pn, rn = vec([TAGSLAM_POSITION_NOISE] * 3), vec([TAGSLAM_ROTATION_NOISE] * 3)
    lines = [
        "# TagSLAM known tags written by markerplace (tag family tag36h11)",
        f"# body frame: {frame_note}",
        "# tag frame: origin at the tag centre, x right and y up as a facing viewer sees the tag, z out of the wall;",
        "# rotation: rotation vector (axis x angle, radians); noise: sigmas (metres, radians)",
        "bodies:",
        f" - {name}:",
        "     is_static: true",
        f"     default_tag_size: {_num(default_size)}",
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
                  f"         size: {_num(m.size)}",
                  "         pose:",
                  f"           position: {vec(T[:3, 3])}",
                  f"           rotation: {vec(rotation_vector(T[:3, :3]))}",
                  f"           position_noise: {pn}",
                  f"           rotation_noise: {rn}"]
    if not markers:
        lines[-1] = "     tags: []"
    return "\n".join(lines) + "\n"


def _in_file_axes(markers: Sequence, world_from_file: np.ndarray) -> list:
    from dataclasses import replace

    F = np.eye(4)
    F[:3, :3] = np.asarray(world_from_file, float).T
    return [replace(m, world_from_marker=F @ np.asarray(m.world_from_marker, float)) for m in markers]


def _suffixed(name: str, suffix: str) -> str:
    """``name`` with ``suffix`` before its extensions (``a.launch.yaml`` -> ``a_yup.launch.yaml``)."""
    stem, _, ext = name.partition(".")
    return f"{stem}{suffix}.{ext}"


def write_tag_maps(folder: str | Path, markers: Sequence, *, name: str, field: tuple[float, float],
                   world_from_file: np.ndarray | None = None, file_suffix: str = "_yup") -> list[Path]:
    """Write the tag maps of ``markers`` (every format of :data:`FILES`) into ``folder`` (atomically).

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
        texts = {"wpilib": json.dumps(clean_numbers(wpilib_layout(ms, field), None), indent=2) + "\n",
                 "apriltag_ros": apriltag_ros_yaml(ms, name, note),
                 "tagslam": tagslam_yaml(ms, name, note, size),
                 "ros2_params": ros2_params_yaml(ms, size, note),
                 "ros2_transforms": ros2_transforms_launch(ms, note)}
        for key, text in texts.items():
            path = folder / _suffixed(FILES[key], suffix)
            with atomic_path(path) as tmp:
                tmp.write_text(text)
            written.append(path)
    return written
