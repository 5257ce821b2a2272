"""Install round trip of the tag maps: markerplace writes ``tagmaps/``, each consumer
(tests/helpers/consumers.py: WPILib/PhotonVision, apriltag_ros ROS 1, TagSLAM, the ROS 2 apriltag node)
turns ONE detected tag of an image into the camera's pose, and that pose must be the camera that
took the image.

The ground truth avoids markerplace's tag conventions: a tag hangs upright on a wall (centre c,
facing the horizontal direction n, black-square edge s; its corners computed here from "top edge
up, a facing viewer's right = (-n) x up"), the official AprilRobotics/apriltag-imgs bitmap (top
edge up, tests/helpers/official_tags.py) is warped into a 1600 x 1200 image with cv2.warpPerspective for a
camera placed here (OpenCV camera: x right, y down, z forward; K with pixel centres at integers),
and the only markerplace code in the loop is the code under test: ``Marker`` +
``world_from_marker_pose(centre, normal)`` (the documented marker frame) and the real writer
``write_tag_maps``. All poses are world_from_cam (4, 4), metres.
"""

from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np
import pytest

from helpers import consumers as C
from helpers.official_tags import official_square
from markerplace.geometry import world_from_marker_pose
from markerplace.markers import Marker
from markerplace.report.tagmaps.write import write_tag_maps
from markerplace.scene.loader import up_rotation

W, H = 1600, 1200
K = np.array([[1100.0, 0.0, 799.5], [0.0, 1100.0, 599.5], [0.0, 0.0, 1.0]])
"""OpenCV intrinsics of the rendered images (pixel centres at integers, principal point at the
image centre)."""
SIZE = 0.4
"""Black-square edge of every tag, metres (markerplace's default)."""
SUPERSAMPLE = 2
UP = np.array([0.0, 0.0, 1.0])
WORLD_FROM_YUP_FILE = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
"""A glTF (y-up) file's axes in the z-up model frame: file (x, y, z) -> model (x, -z, y)."""
MAX_DT, MAX_DR = 0.03, 1.0
"""Tolerances: metres, degrees."""


# ------------------------------------------------------------------------------------------------
# Ground truth without markerplace's conventions
# ------------------------------------------------------------------------------------------------

def wall_tag_corners(centre, facing, s: float = SIZE) -> np.ndarray:
    """(4, 3) world corners TL, TR, BR, BL (as printed: top edge up) of an upright tag whose
    visible face looks along the horizontal ``facing``; right = the right of a viewer facing it."""
    n = np.asarray(facing, float)
    n = n / np.linalg.norm(n)
    right = np.cross(-n, UP)  # the viewer looks along -n, up is +z
    c, h = np.asarray(centre, float), s / 2
    return np.array([c - right * h + UP * h, c + right * h + UP * h, c + right * h - UP * h, c - right * h - UP * h])


def look_at(position, target, roll_deg: float = 0.0) -> np.ndarray:
    """world_from_cam (OpenCV camera) at ``position`` looking at ``target``, image top towards
    +z, then rolled by ``roll_deg`` about the optical axis."""
    z = np.asarray(target, float) - np.asarray(position, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, UP)
    x /= np.linalg.norm(x)
    a = np.radians(roll_deg)
    roll = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, np.cross(z, x), z]) @ roll
    T[:3, 3] = position
    return T


def project(world_from_cam: np.ndarray, X: np.ndarray, Kmat: np.ndarray = K) -> np.ndarray:
    """(n, 2) OpenCV pixels of world points (n, 3); all must be in front of the camera."""
    pc = (np.asarray(X, float) - world_from_cam[:3, 3]) @ world_from_cam[:3, :3]
    assert (pc[:, 2] > 0.1).all()
    uv = pc @ Kmat.T
    return uv[:, :2] / uv[:, 2:]


def render(tags, world_from_cam: np.ndarray) -> np.ndarray:
    """(H, W) uint8 image of the official tags ``[(id, corners TL, TR, BR, BL), ...]`` (each with
    a white quiet zone two cells wide) on a grey wall, rendered at SUPERSAMPLE x and averaged
    down (pixel i of the image covers supersampled pixels S i .. S i + S - 1)."""
    S = SUPERSAMPLE
    Ks = np.array([[S, 0, (S - 1) / 2], [0, S, (S - 1) / 2], [0, 0, 1]]) @ K
    canvas = np.full((H * S, W * S), 90.0, np.float32)
    cell = 40
    side, m = 8 * cell, 2 * cell
    for tag_id, X in tags:
        uv = project(world_from_cam, X)
        assert (uv > 40).all() and (uv[:, 0] < W - 40).all() and (uv[:, 1] < H - 40).all(), uv
        patch = np.full((side + 2 * m, side + 2 * m), 255, np.uint8)
        patch[m:m + side, m:m + side] = official_square(tag_id, side)  # row 0 = the top edge
        # black-square corners TL, TR, BR, BL of the patch (pixel centres at integers)
        src = np.float32([[m - 0.5, m - 0.5], [m + side - 0.5, m - 0.5],
                          [m + side - 0.5, m + side - 0.5], [m - 0.5, m + side - 0.5]])
        M = cv2.getPerspectiveTransform(src, project(world_from_cam, X, Ks).astype(np.float32))
        warped = cv2.warpPerspective(patch.astype(np.float32), M, (W * S, H * S), flags=cv2.INTER_LINEAR)
        alpha = cv2.warpPerspective(np.ones(patch.shape, np.float32), M, (W * S, H * S), flags=cv2.INTER_LINEAR)
        canvas = alpha * warped + (1 - alpha) * canvas
    img = cv2.resize(canvas, (W, H), interpolation=cv2.INTER_AREA)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def file_axes(T: np.ndarray) -> np.ndarray:
    """A model-frame pose in the y-up file's axes: [R^T 0; 0 1] @ T."""
    F = np.eye(4)
    F[:3, :3] = WORLD_FROM_YUP_FILE.T
    return F @ T


# Walls facing +x, -y, a diagonal and -x; cameras 20-40 degrees off the tag's normal, above and
# below it, some rolled.
SCENES = {
    "facing+x": ([(3, (0.0, 2.0, 1.5), (1, 0, 0))], ((2.2, 3.3, 1.65), (0.0, 2.0, 1.5), 0.0)),
    "facing-y": ([(17, (3.0, 5.0, 1.4), (0, -1, 0))], ((1.6, 3.3, 1.2), (3.1, 5.0, 1.45), 8.0)),
    "facing_diagonal": ([(101, (4.0, 1.0, 1.6), (-1, 1, 0))], ((3.0, 3.2, 1.5), (4.0, 1.0, 1.6), -5.0)),
    "facing-x_from_below": ([(101, (6.0, 1.0, 1.9), (-1, 0, 0))], ((4.2, 0.0, 1.1), (6.0, 1.0, 1.9), 0.0)),
    "two_tags": ([(3, (0.0, 2.0, 1.5), (1, 0, 0)), (17, (0.0, 3.2, 1.5), (1, 0, 0))],
                 ((2.5, 1.6, 1.55), (0.0, 2.6, 1.5), 3.0)),
}


@lru_cache(maxsize=None)
def scene(name: str):
    """(image, world_from_cam truth, markers) of a scene."""
    tags, (position, target, roll) = SCENES[name]
    truth = look_at(np.array(position), np.array(target), roll)
    image = render([(i, wall_tag_corners(c, n)) for i, c, n in tags], truth)
    markers = [Marker(i, SIZE, world_from_marker_pose(np.array(c, float), np.array(n, float))) for i, c, n in tags]
    return image, truth, markers


def write_maps(folder: Path, markers) -> Path:
    write_tag_maps(folder, markers, name="office", field=(8.0, 6.0), world_from_file=up_rotation("y"))
    return folder


def ideal_detection(tag_id: int, corners_world_tl_tr_br_bl: np.ndarray, world_from_cam: np.ndarray) -> dict:
    """What an exact AprilTag-library detection of the tag reports: corners BL, BR, TR, TL in the
    library's pixel convention (OpenCV pixels + 0.5) and the homography from tag (-1..1, y down)
    coordinates to them."""
    tl, tr, br, bl = corners_world_tl_tr_br_bl
    p = project(world_from_cam, np.array([bl, br, tr, tl])) + 0.5
    Hm, _ = cv2.findHomography(np.array([[-1.0, 1], [1, 1], [1, -1], [-1, -1]]), p)
    return {"id": tag_id, "hamming": 0, "decision_margin": 100.0, "corners": p, "H": Hm}


def consumers_from_detections(folder: Path, dets: list[dict], *, pixel_offset: float = 0.0, suffix: str = ""):
    f = {k: [folder / C._suffixed(n, suffix) for n in names] for k, names in C.FILES.items()}
    sizes = C.tag_sizes(f["ros2"][0])
    return {
        "wpilib": C.wpilib_camera_poses(f["wpilib"][0], None, K, sizes, pixel_offset=pixel_offset, detections=dets),
        "apriltag_ros": C.apriltag_ros_camera_poses(f["apriltag_ros"][0], None, K, pixel_offset=pixel_offset,
                                                    detections=dets),
        "tagslam": C.tagslam_camera_poses(f["tagslam"][0], None, K, pixel_offset=pixel_offset, detections=dets),
        "ros2": C.ros2_camera_poses(f["ros2"][0], f["ros2"][1], None, K, pixel_offset=pixel_offset, detections=dets),
    }


# ------------------------------------------------------------------------------------------------
# The round trip
# ------------------------------------------------------------------------------------------------

def test_the_y_up_file_axes_are_gltf_s():
    """The file-axes truth below uses this test's own glTF rotation; it is the loader's."""
    np.testing.assert_array_equal(up_rotation("y"), WORLD_FROM_YUP_FILE)


@pytest.mark.parametrize("name", list(SCENES))
def test_every_consumer_recovers_the_camera_from_one_rendered_tag(tmp_path, name):
    image, truth, markers = scene(name)
    folder = write_maps(tmp_path, markers)
    ids = sorted(m.tag_id for m in markers)
    for suffix, expected in (("", truth), ("_yup", file_axes(truth))):
        poses = C.camera_poses(folder, image, K, suffix=suffix)
        assert set(poses) == set(C.FORMATS)
        for fmt, per_tag in poses.items():
            assert sorted(per_tag) == ids, (suffix, fmt)
            for tag_id, T in per_tag.items():
                np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
                dt, dr = C.pose_error(T, expected)
                assert dt < MAX_DT and dr < MAX_DR, (name, suffix or "model", fmt, tag_id, dt, dr)


def test_apriltag_ros_bundle_pose_from_every_member(tmp_path):
    """apriltag_ros's own output: one bundle pose from all detected members at once."""
    image, truth, markers = scene("two_tags")
    folder = write_maps(tmp_path, markers)
    for suffix, expected in (("", truth), ("_yup", file_axes(truth))):
        T, used = C.apriltag_ros_bundle_pose(folder / f"apriltag_ros_bundle{suffix}.yaml", image, K)
        assert sorted(used) == [3, 17]
        dt, dr = C.pose_error(T, expected)
        assert dt < MAX_DT / 2 and dr < MAX_DR / 2, (suffix, dt, dr)


@pytest.mark.parametrize("position", [(2.2, 3.3, 1.65), (4.0, 2.5, 1.5), (6.0, 4.0, 1.2)])
def test_exact_corners_give_the_exact_camera_and_the_half_pixel_is_small(tmp_path, position):
    """With an exact detection, every consumer's chain is exact once the library's corners are
    moved to OpenCV's pixel convention (-0.5); fed literally, as the consumers do, the 0.5 px
    costs about 0.5 px / f of rotation (0.04 degrees here) and a few millimetres at most."""
    tag_id, centre, facing = 3, (0.0, 2.0, 1.5), (1, 0, 0)
    truth = look_at(np.array(position), np.array(centre))
    folder = write_maps(tmp_path, [Marker(tag_id, SIZE, world_from_marker_pose(np.array(centre), np.array(facing, float)))])
    dets = [ideal_detection(tag_id, wall_tag_corners(centre, facing), truth)]
    for suffix, expected in (("", truth), ("_yup", file_axes(truth))):
        exact = consumers_from_detections(folder, dets, pixel_offset=-0.5, suffix=suffix)
        literal = consumers_from_detections(folder, dets, pixel_offset=0.0, suffix=suffix)
        for fmt in C.FORMATS:
            dt, dr = C.pose_error(exact[fmt][tag_id], expected)
            assert dt < 1e-4 and dr < 1e-3, (fmt, suffix, dt, dr)  # orthogonal iteration's tolerance
            dt, dr = C.pose_error(literal[fmt][tag_id], expected)
            assert dt < 0.005 and dr < 0.06, (fmt, suffix, dt, dr)
            assert dr > 1e-3 or dt > 1e-4, (fmt, "the half pixel must show")


def test_a_tag_turned_upside_down_in_the_map_is_caught(tmp_path):
    """The round trip has teeth: a map whose tag frame is turned half a turn about its normal
    (the 180-degree error a wrong bitmap or frame gives) puts every consumer's camera half a turn
    off."""
    tag_id, centre, facing = 3, (0.0, 2.0, 1.5), (1, 0, 0)
    truth = look_at(np.array([2.2, 3.3, 1.65]), np.array(centre))
    turned = world_from_marker_pose(np.array(centre), np.array(facing, float)) @ np.diag([-1.0, -1.0, 1.0, 1.0])
    folder = write_maps(tmp_path, [Marker(tag_id, SIZE, turned)])
    poses = consumers_from_detections(folder, [ideal_detection(tag_id, wall_tag_corners(centre, facing), truth)],
                                      pixel_offset=-0.5)
    for fmt in C.FORMATS:
        dt, dr = C.pose_error(poses[fmt][tag_id], truth)
        assert dr > 179.0, (fmt, dt, dr)


def test_photonvision_s_hard_coded_tag_size_scales_the_distance(tmp_path):
    """PhotonVision's AprilTag pipeline cannot be given the tag size: it assumes 6.5 in
    (0.1651 m) tag36h11 tags (photon-core AprilTagPipeline.java). With markerplace's 0.4 m tags
    the WPILib chain then puts the camera 0.1651 / 0.4 of the true distance from the tag."""
    tag_id, centre, facing = 3, np.array([0.0, 2.0, 1.5]), (1, 0, 0)
    truth = look_at(np.array([2.2, 3.3, 1.65]), centre)
    folder = write_maps(tmp_path, [Marker(tag_id, SIZE, world_from_marker_pose(centre, np.array(facing, float)))])
    dets = [ideal_detection(tag_id, wall_tag_corners(centre, facing), truth)]
    T = C.wpilib_camera_poses(folder / "wpilib_field_layout.json", None, K, 0.1651, pixel_offset=-0.5,
                              detections=dets)[tag_id]
    ratio = np.linalg.norm(T[:3, 3] - centre) / np.linalg.norm(truth[:3, 3] - centre)
    assert ratio == pytest.approx(0.1651 / SIZE, rel=1e-4)
    assert C.pose_error(T, truth)[1] < 1e-3  # the orientation is right


# ------------------------------------------------------------------------------------------------
# The consumer module's own pieces
# ------------------------------------------------------------------------------------------------

def test_static_transform_publisher_arguments_are_parent_from_child(tmp_path):
    """tf2 semantics: --frame-id A --child-frame-id B publishes B's pose in A (p_A = R p_B + t);
    --roll/--pitch/--yaw is tf2's setRPY (fixed axes x, y, z)."""
    q = float(np.sqrt(0.5))
    (tmp_path / "l.launch.yaml").write_text(
        "launch:\n"
        "- node:\n    pkg: tf2_ros\n    exec: static_transform_publisher\n"
        f"    args: \"--x 1 --y 2 --z 3 --qx 0 --qy 0 --qz {q!r} --qw {q!r} --frame-id map --child-frame-id a\"\n"
        "- node:\n    pkg: tf2_ros\n    exec: static_transform_publisher\n"
        "    args: \"--yaw 1.5707963267948966 --roll 0.3 --frame-id map --child-frame-id b\"\n")
    tf = C.ros2_static_transforms(tmp_path / "l.launch.yaml")
    A = tf[("map", "a")]
    np.testing.assert_allclose(A[:3, 3], [1, 2, 3])
    np.testing.assert_allclose(A[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-12)  # a's x is map's y
    np.testing.assert_allclose(A @ [1, 0, 0, 1], [1, 3, 3, 1], atol=1e-12)
    B = tf[("map", "b")]
    c, s = np.cos(0.3), np.sin(0.3)
    np.testing.assert_allclose(B[:3, :3], np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]) @ [[1, 0, 0], [0, c, -s], [0, s, c]],
                               atol=1e-12)


def test_ros1_image_points_are_the_library_corners():
    """apriltag_ros's addImagePoints (homography at (-1, 1), (1, 1), (1, -1), (-1, -1)) gives the
    library's p[0..3] (apriltag.c: p[i] = H (tcx, tcy), the same points)."""
    truth = look_at(np.array([2.2, 3.3, 1.65]), np.array([0.0, 2.0, 1.5]))
    d = ideal_detection(3, wall_tag_corners((0.0, 2.0, 1.5), (1, 0, 0)), truth)
    np.testing.assert_allclose(C._ros1_image_points(d["H"]), d["corners"], atol=1e-9)


def test_real_detectors_report_the_library_s_corner_order_and_pixel_convention():
    """Both detectors (pupil-apriltags for the ROS consumers, WPILib's for PhotonVision) return
    the printed tag's bottom-left corner first, then BR, TR, TL, half a pixel right of and below
    OpenCV's projection (the AprilTag library's pixel centres at +0.5)."""
    errors = []
    for name, (tags, _) in SCENES.items():
        image, truth, _ = scene(name)
        for detect in (C.apriltag_detections, C.wpilib_detections):
            dets = detect(image)
            assert sorted(d["id"] for d in dets) == sorted(t[0] for t in tags), (name, detect)
            for d in dets:
                ((centre, facing),) = [(c, n) for i, c, n in tags if i == d["id"]]
                tl, tr, br, bl = wall_tag_corners(centre, facing)
                errors.append(d["corners"] - project(truth, np.array([bl, br, tr, tl])))
    errors = np.array(errors)
    assert np.abs(errors - 0.5).max() < 0.25, errors
    np.testing.assert_allclose(errors.mean(axis=(0, 1)), [0.5, 0.5], atol=0.05)


def test_consumers_do_not_use_markerplace():
    """The consumer code reads the files with its own parsers and conventions only."""
    tree = ast.parse(Path(C.__file__).read_text())
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    ours = [n for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module and n.module.startswith("markerplace")]
    # only the crash fix of pupil-apriltags' destructor (make_detector), no convention of ours
    assert [(n.module, [a.name for a in n.names]) for n in ours] == [("markerplace.localization.tags", ["make_detector"])]
    imported |= {n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module
                 and not n.module.startswith("markerplace")}
    assert "markerplace" not in imported
    assert imported <= {"__future__", "json", "math", "shlex", "pathlib", "cv2", "numpy", "yaml", "scipy",
                        "robotpy_apriltag", "wpimath", "pupil_apriltags"}, imported
