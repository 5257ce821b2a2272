"""Tag maps (WPILib, apriltag_ros ROS 1 and ROS 2, TagSLAM): read each back with a JSON/YAML
parser (WPILib's with robotpy-apriltag's own AprilTagFieldLayout) and the formats' own
conventions, and recover every world_from_marker to 1e-9."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml

from markerplace.geometry import world_from_marker_pose
from markerplace.markers import Marker
from markerplace.report.tagmaps.wpilib import MARKER_FROM_WPILIB
from markerplace.report.tagmaps.write import write_tag_maps
from markerplace.scene.loader import up_rotation


def quat_to_matrix(w, x, y, z) -> np.ndarray:
    """Textbook unit-quaternion rotation matrix (independent of the writer's conversion)."""
    n = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def rotvec_to_matrix(v) -> np.ndarray:
    """Rodrigues' formula."""
    v = np.asarray(v, float)
    t = np.linalg.norm(v)
    if t < 1e-15:
        return np.eye(3)
    k = v / t
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def pose(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def read_wpilib(path):
    d = json.loads(path.read_text())
    out = {}
    for tag in d["tags"]:
        tr, q = tag["pose"]["translation"], tag["pose"]["rotation"]["quaternion"]
        W = pose(quat_to_matrix(q["W"], q["X"], q["Y"], q["Z"]), [tr["x"], tr["y"], tr["z"]])
        out[tag["ID"]] = W @ np.linalg.inv(MARKER_FROM_WPILIB)
    return out, d["field"]


def read_apriltag_ros(path):
    d = yaml.safe_load(path.read_text())
    assert d["standalone_tags"] == []
    (bundle,) = d["tag_bundles"]
    return {t["id"]: (t["size"], pose(quat_to_matrix(t["qw"], t["qx"], t["qy"], t["qz"]), [t["x"], t["y"], t["z"]]))
            for t in bundle["layout"]}


def read_tagslam(path):
    d = yaml.safe_load(path.read_text())
    (body,) = d["bodies"]
    (name, b), = body.items()
    assert b["is_static"] is True and b["type"] == "simple"
    out = {}
    for t in b["tags"]:
        p, r = t["pose"]["position"], t["pose"]["rotation"]
        assert set(t["pose"]) == {"position", "rotation", "position_noise", "rotation_noise"}
        out[t["id"]] = (t["size"], pose(rotvec_to_matrix([r["x"], r["y"], r["z"]]), [p["x"], p["y"], p["z"]]))
    return out


def read_ros2(folder, suffix=""):
    """{id: (size, map_from_tag)} from the ROS 2 parameter file and the static-transform launch
    file, as the apriltag node and tf2_ros' static_transform_publisher read them."""
    params = yaml.safe_load((folder / f"ros2_apriltag_params{suffix}.yaml").read_text())
    p = params["/**"]["ros__parameters"]
    assert p["family"] == "36h11" and p["pose_estimation_method"] == "pnp"
    tag = p["tag"]
    assert len(tag["ids"]) == len(tag["frames"]) == len(tag["sizes"])
    launch = yaml.safe_load((folder / f"ros2_tag_transforms{suffix}.launch.yaml").read_text())["launch"]
    known = {}
    for entry in launch:
        node = entry["node"]
        assert node["pkg"] == "tf2_ros" and node["exec"] == "static_transform_publisher"
        a = node["args"].split()
        kv = dict(zip(a[0::2], a[1::2]))
        assert kv["--frame-id"] == "map"
        known[kv["--child-frame-id"]] = pose(quat_to_matrix(*(float(kv[k]) for k in ("--qw", "--qx", "--qy", "--qz"))),
                                             [float(kv[k]) for k in ("--x", "--y", "--z")])
    out = {}
    for i, frame, size in zip(tag["ids"], tag["frames"], tag["sizes"]):
        assert frame == f"tag36h11_{i}"
        out[i] = (size, known[f"map_{frame}"])
    assert len(known) == len(out)
    return out


def random_markers(rng, n=12, offset=(0.0, 0.0, 0.0)):
    ms = []
    for i in range(n):
        if i % 3 == 0:  # wall tags as the planner makes them (horizontal normal, y up)
            yaw = rng.uniform(-np.pi, np.pi)
            T = world_from_marker_pose(rng.uniform(-20, 20, 3) + offset, np.array([np.cos(yaw), np.sin(yaw), 0.0]))
        else:  # any rotation, including angles near pi (rotation vectors' hard case)
            q = rng.normal(size=4)
            R = quat_to_matrix(*q)
            if i % 3 == 2:
                axis = rng.normal(size=3)
                axis /= np.linalg.norm(axis)
                R = rotvec_to_matrix(axis * (np.pi - 1e-7))
            T = pose(R, rng.uniform(-20, 20, 3) + offset)
        ms.append(Marker(int(i * 7 % 587), float(rng.uniform(0.05, 0.6)), T))
    return ms


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (512345.0, 5412345.0, 310.0)])
def test_every_format_recovers_world_from_marker(tmp_path, offset):
    rng = np.random.default_rng(3)
    markers = random_markers(rng, offset=offset)
    paths = write_tag_maps(tmp_path, markers, name="office", field=(12.5, 8.0))
    assert sorted(p.name for p in paths) == ["apriltag_ros_bundle.yaml", "ros2_apriltag_params.yaml",
                                             "ros2_tag_transforms.launch.yaml", "tagslam_tags.yaml",
                                             "wpilib_field_layout.json"]
    wp, field = read_wpilib(tmp_path / "wpilib_field_layout.json")
    ar = read_apriltag_ros(tmp_path / "apriltag_ros_bundle.yaml")
    ts = read_tagslam(tmp_path / "tagslam_tags.yaml")
    r2 = read_ros2(tmp_path)
    assert field == {"length": 12.5, "width": 8.0}
    for m in markers:
        T = m.world_from_marker
        assert np.abs(wp[m.tag_id] - T).max() < 1e-9
        assert ar[m.tag_id][0] == m.size and np.abs(ar[m.tag_id][1] - T).max() < 1e-9
        assert ts[m.tag_id][0] == m.size and np.abs(ts[m.tag_id][1] - T).max() < 1e-9
        assert r2[m.tag_id][0] == m.size and np.abs(r2[m.tag_id][1] - T).max() < 1e-9


def test_wpilib_layout_loads_in_robotpy_apriltag(tmp_path):
    """WPILib's own AprilTagFieldLayout (robotpy-apriltag) reads the file: same ids, field and
    poses (WPILib's tag frame, x out of the face, z up) to 1e-9."""
    import robotpy_apriltag

    rng = np.random.default_rng(4)
    markers = random_markers(rng, n=6, offset=(3.0, 2.0, 0.0))
    write_tag_maps(tmp_path, markers, name="office", field=(12.5, 8.0))
    layout = robotpy_apriltag.AprilTagFieldLayout(str(tmp_path / "wpilib_field_layout.json"))
    assert layout.getFieldLength() == pytest.approx(12.5) and layout.getFieldWidth() == pytest.approx(8.0)
    assert sorted(t.ID for t in layout.getTags()) == sorted(m.tag_id for m in markers)
    for m in markers:
        p = layout.getTagPose(m.tag_id)
        q = p.rotation().getQuaternion()
        W = pose(quat_to_matrix(q.W(), q.X(), q.Y(), q.Z()), [p.X(), p.Y(), p.Z()])
        assert np.abs(W - m.world_from_marker @ MARKER_FROM_WPILIB).max() < 1e-9


def test_wpilib_tag_frame_faces_out_of_the_wall(tmp_path):
    """A tag on a wall facing +x (viewer standing at +x): WPILib's identity rotation, as the
    FRC field layouts have it for tags facing down the field's +x."""
    m = Marker(3, 0.2, world_from_marker_pose(np.array([0.0, 2.0, 1.5]), np.array([1.0, 0.0, 0.0])))
    write_tag_maps(tmp_path, [m], name="t", field=(1.0, 1.0))
    q = json.loads((tmp_path / "wpilib_field_layout.json").read_text())["tags"][0]["pose"]["rotation"]["quaternion"]
    assert np.allclose([q["W"], q["X"], q["Y"], q["Z"]], [1, 0, 0, 0], atol=1e-12)
    # apriltag_ros / TagSLAM: z out of the wall (+x), y up: a rotation of 120 deg about (1, 1, 1)
    ts = read_tagslam(tmp_path / "tagslam_tags.yaml")[3][1]
    assert np.allclose(ts[:3, 2], [1, 0, 0]) and np.allclose(ts[:3, 1], [0, 0, 1])
    rv = yaml.safe_load((tmp_path / "tagslam_tags.yaml").read_text())["bodies"][0]["t"]["tags"][0]["pose"]["rotation"]
    assert np.allclose([rv["x"], rv["y"], rv["z"]], np.full(3, 2 * np.pi / 3 / np.sqrt(3)))


def test_file_axes_maps_for_a_y_up_model(tmp_path):
    rng = np.random.default_rng(5)
    markers = random_markers(rng, n=6)
    R = up_rotation("y")  # glTF: world_from_file
    paths = write_tag_maps(tmp_path, markers, name="scan", field=(3.0, 4.0), world_from_file=R)
    assert len(paths) == 10
    F = pose(R, [0, 0, 0])  # world_from_file as a pose
    wp, _ = read_wpilib(tmp_path / "wpilib_field_layout_yup.json")
    ar = read_apriltag_ros(tmp_path / "apriltag_ros_bundle_yup.yaml")
    ts = read_tagslam(tmp_path / "tagslam_tags_yup.yaml")
    r2 = read_ros2(tmp_path, "_yup")
    for m in markers:
        for T_file in (wp[m.tag_id], ar[m.tag_id][1], ts[m.tag_id][1], r2[m.tag_id][1]):
            assert np.abs(F @ T_file - m.world_from_marker).max() < 1e-9
        # in y-up axes the height is the file's +y
        assert ar[m.tag_id][1][1, 3] == pytest.approx(m.world_from_marker[2, 3], abs=1e-12)


def test_empty_plan_writes_valid_files(tmp_path):
    write_tag_maps(tmp_path, [], name="none", field=(0.0, 0.0))
    assert read_wpilib(tmp_path / "wpilib_field_layout.json")[0] == {}
    assert read_tagslam(tmp_path / "tagslam_tags.yaml") == {}
    assert read_apriltag_ros(tmp_path / "apriltag_ros_bundle.yaml") == {}
    assert yaml.safe_load((tmp_path / "ros2_tag_transforms.launch.yaml").read_text()) == {"launch": []}
