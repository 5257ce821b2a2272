"""The consumer side of markerplace's tag maps: a camera's pose in the map from ONE detected tag,
computed the way each localization system that reads a ``PLAN_DIR/tagmaps/`` file computes it.

Nothing here imports markerplace: every consumer reads its file with a plain JSON/YAML parser (or
the consumer's own library, robotpy-apriltag for WPILib), detects the tags with the detector that
consumer runs, estimates the tag's pose with the consumer's own method and object points, and
composes the transforms in the consumer's own order. The point is to catch a convention error in
markerplace's files (a tag frame turned by 180 degrees, a swapped axis, a transform published the
wrong way round), so nothing of markerplace's marker frame is assumed.

Every function returns, per detected tag id, ``world_from_cam``: a (4, 4) rigid transform, metres,
of the camera in the map's frame (the frame the file's poses are in: markerplace's model frame, or
the scene file's axes for the ``_yup``/... files), with the camera in the **OpenCV convention**
(x right, y down, z forward along the optical axis), so that callers compare it with a truth
directly. ``K`` is the (3, 3) OpenCV intrinsic matrix of the undistorted image (pixel centres at
integer coordinates, as OpenCV's ``calibrateCamera`` estimates it); ``image`` is (H, W) uint8.

Sources followed (commits of the mirrors read; a file path and line is cited at each step):

* WPILib / PhotonVision (``wpilib_field_layout.json``): robotpy-apriltag 2026.2.2 (WPILib's own
  ``AprilTagFieldLayout``, ``AprilTagDetector``, ``AprilTagPoseEstimator``) and
  ``wpimath.geometry`` (``CoordinateSystem``, ``Transform3d``, ``Pose3d``), composed as
  PhotonVision v2026.3.4 does (PhotonVision/photonvision, photon-core ``AprilTagPipeline.java``,
  ``TrackedTarget.java``, ``MathUtils.java``; photon-lib ``PhotonUtils.java``).
* apriltag_ros, ROS 1 (``apriltag_ros_bundle.yaml``): AprilRobotics/apriltag_ros @ 94b3b84,
  ``apriltag_ros/src/common_functions.cpp``.
* TagSLAM (``tagslam_tags.yaml``): berndpfrommer/tagslam @ a8afd5d, ``src/tag.cpp``,
  ``src/init_pose.cpp``, ``src/graph_updater.cpp``, ``src/xml.cpp``, ``src/geometry.cpp``; corner
  numbering documented in berndpfrommer/tagslam_web ``content/measurements/_index.md`` (picture
  ``content/media/tag_corners.png``); the detector it is built with in tagslam_root is
  versatran01/apriltag (``apriltag_ros/src/apriltag_detector.cpp``, ``ApriltagDetectorUmich``:
  the AprilTag 3 library's ``p`` copied unchanged).
* ROS 2 apriltag_ros node (``ros2_apriltag_params.yaml`` + ``ros2_tag_transforms.launch.yaml``):
  christianrauch/apriltag_ros @ beffb4c, ``src/AprilTagNode.cpp``, ``src/pose_estimation.cpp``,
  ``src/conversion.cpp``; ``static_transform_publisher`` arguments as ros2/geometry2
  ``tf2_ros/src/static_transform_broadcaster_program.cpp`` and
  ``static_transform_broadcaster_node.cpp`` parse them.

Pixel convention of the AprilTag C library (AprilRobotics/apriltag @ 1c21707): its corners put
pixel centres at +0.5 (``apriltag_quad_thresh.c`` line 630, ``delta = 0.5; // adjust for pixel
center bias``; ``apriltag.c`` line 539 samples pixel values at ``px - 0.5``), while OpenCV's K puts
them at integers. Every consumer here hands the library's corners (or its homography) to its
pose solver with an OpenCV-style K unchanged, so a detection sits 0.5 px right of and below
where an OpenCV camera model projects the corner. The consumers replicate that literally
(``pixel_offset=0.0``); ``pixel_offset=-0.5`` moves the corners into OpenCV's convention first, to
quantify the effect (a few millimetres at a few metres).
"""

from __future__ import annotations

import math
import shlex
from pathlib import Path

import cv2
import numpy as np
import yaml
from scipy.spatial.transform import Rotation

FILES = {
    "wpilib": ("wpilib_field_layout.json",),
    "apriltag_ros": ("apriltag_ros_bundle.yaml",),
    "tagslam": ("tagslam_tags.yaml",),
    "ros2": ("ros2_apriltag_params.yaml", "ros2_tag_transforms.launch.yaml"),
}
"""Files each consumer reads from ``tagmaps/`` (a file-axes suffix goes before the first dot)."""
FORMATS = tuple(FILES)


def _suffixed(name: str, suffix: str) -> str:
    stem, _, ext = name.partition(".")
    return f"{stem}{suffix}.{ext}"


def _pose(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = np.asarray(R, float)
    T[:3, 3] = np.asarray(t, float).ravel()
    return T


def _inv(T: np.ndarray) -> np.ndarray:
    R, t = T[:3, :3], T[:3, 3]
    return _pose(R.T, -R.T @ t)


# ------------------------------------------------------------------------------------------------
# The AprilTag C library's detections (pupil-apriltags), as the ROS nodes and TagSLAM receive them
# ------------------------------------------------------------------------------------------------

_PUPIL_DETECTORS: dict = {}


def _pupil_detector(quad_decimate: float):
    """One pupil-apriltags detector per setting, kept for the process. pupil-apriltags 1.0.4
    crashes the process when a Detector is destroyed (it frees the tag families before the
    detector that still reads them: pupil-labs/apriltags PR #65), so the detector comes from
    markerplace's ``make_detector``, which is pupil-apriltags' class with only its destructor
    fixed; every setting here is the consumers' own."""
    if quad_decimate not in _PUPIL_DETECTORS:
        from markerplace.localization.tags import make_detector  # the destructor fix only

        _PUPIL_DETECTORS[quad_decimate] = make_detector(families="tag36h11", nthreads=1, quad_decimate=quad_decimate,
                                                        quad_sigma=0.0, refine_edges=1, decode_sharpening=0.25)
    return _PUPIL_DETECTORS[quad_decimate]


def apriltag_detections(image: np.ndarray, *, quad_decimate: float = 1.0, max_hamming: int = 0) -> list[dict]:
    """tag36h11 detections of the AprilTag C library (pupil-apriltags) in ``image``.

    Returns a list of dicts: ``id``, ``hamming``, ``corners`` (4, 2) = the library's
    ``apriltag_detection_t.p`` in pixels (library convention: pixel centres at +0.5; order
    counter-clockwise from the tag's bottom-left as printed: BL, BR, TR, TL), ``H`` (3, 3) = the
    library's homography from tag coordinates ((-1, -1)..(1, 1), y down) to pixels.
    """
    det = _pupil_detector(float(quad_decimate))
    out = []
    for d in det.detect(np.ascontiguousarray(image, dtype=np.uint8)):
        if d.hamming > max_hamming:
            continue
        out.append({"id": int(d.tag_id), "hamming": int(d.hamming),
                    "corners": np.asarray(d.corners, float).reshape(4, 2),
                    "H": np.asarray(d.homography, float).reshape(3, 3)})
    return out


def _shift_homography(H: np.ndarray, offset: float) -> np.ndarray:
    """The homography whose image points are ``offset`` pixels further in x and in y."""
    S = np.array([[1.0, 0, offset], [0, 1, offset], [0, 0, 1]])
    return S @ H


def homography_project(H: np.ndarray, x: float, y: float) -> tuple[float, float]:
    """The AprilTag library's ``homography_project`` (common/homography.h): ``H @ (x, y, 1)``,
    dehomogenised."""
    xx = H[0, 0] * x + H[0, 1] * y + H[0, 2]
    yy = H[1, 0] * x + H[1, 1] * y + H[1, 2]
    zz = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    return xx / zz, yy / zz


# ------------------------------------------------------------------------------------------------
# 1. WPILib / PhotonVision: wpilib_field_layout.json
# ------------------------------------------------------------------------------------------------

NWU_FROM_EDN = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])
"""(3, 3) rotation of an OpenCV (EDN: x east/right, y down, z north/forward) camera frame in the
WPILib (NWU: x forward, y left, z up) camera frame: columns are E, D, N written in NWU."""


def wpilib_camera_poses(layout_path: str | Path, image: np.ndarray, K: np.ndarray, tag_size: float | dict, *,
                        pixel_offset: float = 0.0, detections: list[dict] | None = None, n_iters: int = 40,
                        decision_margin: float = 35.0) -> dict[int, np.ndarray]:
    """``world_from_cam`` (OpenCV camera) per detected tag of the layout, the PhotonVision way.

    Chain (PhotonVision v2026.3.4 and robotpy-apriltag 2026.2.2, i.e. allwpilib v2026.2.2):

    1. ``AprilTagFieldLayout(path)`` (WPILib's JSON reader; apriltag/.../AprilTagFieldLayout.java).
    2. ``AprilTagDetector`` with ``addFamily("tag36h11")`` and PhotonVision's AprilTag pipeline
       defaults (photon-core .../pipeline/AprilTagPipelineSettings.java lines 27-34: decimate 1,
       blur 0, refineEdges, hammingDist 0, decisionMargin 35; AprilTagPipeline.java lines 90-106:
       minClusterPixels 5 and the WPILib 2025 quad thresholds); detections with a larger Hamming
       distance or a smaller decision margin are dropped (AprilTagPipeline.java ``process``).
    3. ``AprilTagPoseEstimator(Config(tagSize, fx, fy, cx, cy)).estimateOrthogonalIteration(det,
       40)`` (AprilTagPoseEstimatorPipe.java line 85; numIterations 40). The layout has no tag
       size: ``tag_size`` (metres, black-square edge; one value or {id: size}) is given here, as a
       WPILib robot program gives its ``Config``. PhotonVision itself cannot be told: it hard-codes
       6.5 in = 0.1651 m for tag36h11 (AprilTagPipeline.java lines 80-82, and TargetModel
       ``kAprilTag36h11`` for multi-tag), so with other tags its distances scale by
       0.1651 / size. The result is camera-to-tag in EDN with the AprilTag library's tag frame (x
       right, y down, z into the tag; apriltag_pose.c object points).
    4. best = pose1 if error1 <= error2 else pose2 (TrackedTarget.java line 105).
    5. ``MathUtils.convertApriltagtoOpenCV``: rotation = Rotation3d(axis (0, 1, 0), 180 deg)
       .rotateBy(rotation) (MathUtils.java lines 195-209): the tag frame turned half a turn about
       its y axis (z now out of the tag).
    6. ``MathUtils.convertOpenCVtoPhotonTransform``: ``CoordinateSystem.convert(t, EDN, NWU)``
       (MathUtils.java line 178-182; wpimath CoordinateSystem.java ``convert(Transform3d, ...)``):
       camera-to-target in WPILib's frames (AprilTagPipeline.java line 227).
    7. ``PhotonUtils.estimateFieldToRobotAprilTag(cameraToTarget, tagPose, cameraToRobot=identity)``
       = ``tagPose.plus(cameraToTarget.inverse())`` (PhotonUtils.java line 184): the camera's pose
       on the field, camera frame NWU (x forward, y left, z up).
    8. Here only: the NWU camera frame re-expressed as OpenCV's, ``@ NWU_FROM_EDN``.

    ``detections`` (default: :func:`wpilib_detections` of ``image``) lets a caller pass ideal
    corners; ``pixel_offset`` is added to the corners and homography before step 3 (as
    PhotonVision replaces them by undistorted corners in AprilTagPoseEstimatorPipe.java).
    """
    import robotpy_apriltag as at
    from wpimath.geometry import CoordinateSystem, Rotation3d, Transform3d, Translation3d

    layout = at.AprilTagFieldLayout(str(layout_path))
    sizes = dict(tag_size) if isinstance(tag_size, dict) else {None: float(tag_size)}
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    dets = detections if detections is not None else wpilib_detections(image)

    apriltag_base_rotation = Rotation3d(np.array([0.0, 1.0, 0.0]), math.pi)  # MathUtils.java 195-196
    out: dict[int, np.ndarray] = {}
    for d in dets:
        if d["hamming"] > 0 or d["decision_margin"] < decision_margin:     # AprilTagPipeline.java
            continue
        tag_pose = layout.getTagPose(d["id"])
        if tag_pose is None:  # not in the layout
            continue
        size = float(sizes.get(d["id"], sizes.get(None)))
        estimator = at.AprilTagPoseEstimator(at.AprilTagPoseEstimator.Config(size, fx, fy, cx, cy))
        est = estimator.estimateOrthogonalIteration(
            tuple(_shift_homography(d["H"], pixel_offset).ravel()), tuple((d["corners"] + pixel_offset).ravel()),
            n_iters)
        best = est.pose1 if est.error1 <= est.error2 else est.pose2                  # TrackedTarget.java 105
        best = Transform3d(best.translation(), apriltag_base_rotation.rotateBy(best.rotation()))  # MathUtils 207
        camera_to_target = CoordinateSystem.convert(best, CoordinateSystem.EDN(), CoordinateSystem.NWU())
        camera_to_robot = Transform3d(Translation3d(), Rotation3d())                  # the robot is the camera
        # Java Pose3d.plus is Python's + (Pose3d.__add__ = transformBy)
        field_to_camera = tag_pose + camera_to_target.inverse() + camera_to_robot    # PhotonUtils.java 184
        T = np.asarray(field_to_camera.toMatrix(), float)
        T[:3, :3] = T[:3, :3] @ NWU_FROM_EDN
        out[d["id"]] = T
    return out


def wpilib_detections(image: np.ndarray) -> list[dict]:
    """tag36h11 detections of WPILib's ``AprilTagDetector`` with PhotonVision's AprilTag pipeline
    settings (AprilTagPipelineSettings.java lines 27-34, AprilTagPipeline.java lines 90-106):
    dicts ``id``, ``hamming``, ``decision_margin``, ``corners`` (4, 2; the library's order and
    pixel convention, BL, BR, TR, TL), ``H`` (3, 3; tag (-1..1, y down) -> pixels)."""
    import robotpy_apriltag as at

    detector = at.AprilTagDetector()
    detector.addFamily("tag36h11", 0)
    cfg = at.AprilTagDetector.Config()
    cfg.numThreads, cfg.refineEdges, cfg.quadSigma, cfg.quadDecimate = 1, True, 0.0, 1.0
    detector.setConfig(cfg)
    qp = at.AprilTagDetector.QuadThresholdParameters()
    qp.minClusterPixels, qp.maxNumMaxima, qp.criticalAngle = 5, 10, 45 * math.pi / 180.0
    qp.maxLineFitMSE, qp.minWhiteBlackDiff, qp.deglitch = 10.0, 5, False
    detector.setQuadThresholdParameters(qp)
    return [{"id": int(det.getId()), "hamming": int(det.getHamming()),
             "decision_margin": float(det.getDecisionMargin()),
             "corners": np.asarray(det.getCorners(tuple([0.0] * 8)), float).reshape(4, 2),
             "H": np.asarray(det.getHomography(), float).reshape(3, 3)}
            for det in detector.detect(np.ascontiguousarray(image, dtype=np.uint8))]


def tag_sizes(params_path: str | Path) -> dict:
    """Black-square edge per tag id (key ``None``: the default), metres, from a ROS 2 apriltag
    parameter file (``tag.ids``/``tag.sizes``, ``size``): what the WPILib consumer is told, the
    WPILib layout having no size."""
    node = _ros2_node_params(Path(params_path))
    sizes = {None: float(node["size"])}
    sizes.update({int(i): float(s) for i, s in zip(node["tag"]["ids"], node["tag"]["sizes"])})
    return sizes


# ------------------------------------------------------------------------------------------------
# 2. apriltag_ros (ROS 1): apriltag_ros_bundle.yaml
# ------------------------------------------------------------------------------------------------

def _ros1_bundle(path: Path) -> tuple[str, dict[int, tuple[float, np.ndarray]]]:
    """(bundle name, {id: (size, T_oi (4, 4))}) of the file's single bundle, parsed as
    ``TagDetector::parseTagBundles`` (common_functions.cpp lines 661-742): x, y, z default 0, qw
    default 1, qx/qy/qz default 0, the quaternion normalised (Eigen ``q_tag.normalize()``), and
    ``T_mj = [R_oi, (x, y, z)]``: the member tag's pose in the bundle frame."""
    doc = yaml.safe_load(Path(path).read_text())
    (bundle,) = doc["tag_bundles"]
    members = {}
    for t in bundle["layout"]:
        q = np.array([t.get("qx", 0.0), t.get("qy", 0.0), t.get("qz", 0.0), t.get("qw", 1.0)], float)
        R = Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()   # Hamilton, as Eigen
        members[int(t["id"])] = (float(t["size"]), _pose(R, [t.get("x", 0.0), t.get("y", 0.0), t.get("z", 0.0)]))
    return bundle.get("name", "bundle_0"), members


def _ros1_object_points(s: float, T_oi: np.ndarray) -> list[np.ndarray]:
    """``TagDetector::addObjectPoints(s, T_oi)`` (common_functions.cpp lines 463-472) with
    s = size / 2: T_oi @ (-s, -s), (s, -s), (s, s), (-s, s), counter-clockwise from the bottom left."""
    return [(T_oi @ np.array([x, y, 0.0, 1.0]))[:3] for x, y in ((-s, -s), (s, -s), (s, s), (-s, s))]


def _ros1_image_points(H: np.ndarray) -> list[tuple[float, float]]:
    """``TagDetector::addImagePoints`` (common_functions.cpp lines 474-492): the detection's
    homography at tag_x = (-1, 1, 1, -1), tag_y = (1, 1, -1, -1) ("negated because AprilTag tag
    local frame has y-axis pointing DOWN")."""
    return [homography_project(H, x, y) for x, y in ((-1, 1), (1, 1), (1, -1), (-1, -1))]


def _ros1_relative_transform(obj, img, K) -> np.ndarray:
    """``TagDetector::getRelativeTransform`` (common_functions.cpp lines 494-522): cv::solvePnP
    (default flags, SOLVEPNP_ITERATIVE) with the camera matrix (fx, 0, cx; 0, fy, cy; 0, 0, 1) and
    zero distortion (4 coefficients); returns [R(rvec), tvec], the object frame in the camera."""
    Kc = np.array([[K[0, 0], 0, K[0, 2]], [0, K[1, 1], K[1, 2]], [0, 0, 1.0]])
    ok, rvec, tvec = cv2.solvePnP(np.asarray(obj, np.float64).reshape(-1, 1, 3),
                                  np.asarray(img, np.float64).reshape(-1, 1, 2), Kc, np.zeros(4, np.float32))
    if not ok:
        raise RuntimeError("cv::solvePnP failed")
    return _pose(cv2.Rodrigues(rvec)[0], tvec)


def apriltag_ros_camera_poses(bundle_path: str | Path, image: np.ndarray, K: np.ndarray, *,
                              pixel_offset: float = 0.0, detections: list[dict] | None = None
                              ) -> dict[int, np.ndarray]:
    """``world_from_cam`` (OpenCV camera; world = the bundle frame) per detected member tag, each
    from that ONE tag: the bundle pose apriltag_ros publishes when only that member is seen.

    ``TagDetector::detectTags`` (common_functions.cpp lines 212-409): for a bundle member, object
    points = ``addObjectPoints(size / 2, T_oi)``, image points = ``addImagePoints(detection)``,
    ``getRelativeTransform`` = camera_from_bundle, published on /tf as camera -> bundle name
    (lines 393-405: ``image->header.frame_id`` -> the bundle's name). Its camera frame is the
    optical one (comment at lines 331-336: x right, y down, z ahead). So world_from_cam =
    inverse(camera_from_bundle). Detector settings: apriltag_ros config/settings.yaml (decimate
    1.0, blur 0, refine_edges 1); duplicates of an id are removed (``removeDuplicates``, default on).
    """
    _, members = _ros1_bundle(Path(bundle_path))
    dets = _dedupe(detections if detections is not None else apriltag_detections(image, quad_decimate=1.0, max_hamming=2))
    out = {}
    for d in dets:
        if d["id"] not in members:
            continue
        size, T_oi = members[d["id"]]
        obj = _ros1_object_points(size / 2, T_oi)
        img = _ros1_image_points(_shift_homography(d["H"], pixel_offset))
        out[d["id"]] = _inv(_ros1_relative_transform(obj, img, K))
    return out


def apriltag_ros_bundle_pose(bundle_path: str | Path, image: np.ndarray, K: np.ndarray, *,
                             pixel_offset: float = 0.0) -> tuple[np.ndarray | None, list[int]]:
    """(``world_from_cam``, member ids used): the bundle pose apriltag_ros publishes from EVERY
    detected member at once (one solvePnP over all their corners, common_functions.cpp lines
    295-301 and 363-391); (None, []) when no member is seen."""
    _, members = _ros1_bundle(Path(bundle_path))
    obj, img, used = [], [], []
    for d in _dedupe(apriltag_detections(image, quad_decimate=1.0, max_hamming=2)):
        if d["id"] in members:
            size, T_oi = members[d["id"]]
            obj += _ros1_object_points(size / 2, T_oi)
            img += _ros1_image_points(_shift_homography(d["H"], pixel_offset))
            used.append(d["id"])
    if not used:
        return None, []
    return _inv(_ros1_relative_transform(obj, img, K)), used


def _dedupe(dets: list[dict]) -> list[dict]:
    """``TagDetector::removeDuplicates``: drop every detection of an id seen more than once."""
    ids = [d["id"] for d in dets]
    return [d for d in dets if ids.count(d["id"]) == 1]


# ------------------------------------------------------------------------------------------------
# 3. TagSLAM: tagslam_tags.yaml
# ------------------------------------------------------------------------------------------------

def _tagslam_transform(pose: dict) -> np.ndarray:
    """``xml::parse<Transform>`` (src/xml.cpp lines 27-41): ``make_transform(rotation, position)``,
    the rotation a rotation vector (src/geometry.cpp lines 24-34: axis = r / |r|, angle = |r|)."""
    p, r = pose["position"], pose["rotation"]
    rv = np.array([r["x"], r["y"], r["z"]], float)
    return _pose(Rotation.from_rotvec(rv).as_matrix(), [p["x"], p["y"], p["z"]])


def _tagslam_bodies(path: Path) -> dict[int, tuple[float, np.ndarray]]:
    """{tag id: (size, T_w_o = T_w_b @ T_b_o)} of every static body's tags with a pose."""
    doc = yaml.safe_load(Path(path).read_text())
    out = {}
    for entry in doc["bodies"]:
        ((_, body),) = entry.items()
        T_w_b = _tagslam_transform(body["pose"]) if "pose" in body else np.eye(4)
        for t in body.get("tags") or []:
            if "pose" not in t:
                continue
            size = float(t.get("size", body.get("default_tag_size", 0.0)))   # Tag::parseTags
            out[int(t["id"])] = (size, T_w_b @ _tagslam_transform(t["pose"]))
    return out


def _tagslam_object_corners(s: float) -> np.ndarray:
    """``Tag::Tag`` objectCorners_ (src/tag.cpp lines 19-23): (-s/2, -s/2), (s/2, -s/2),
    (s/2, s/2), (-s/2, s/2), z = 0; corner 0 is the bottom left (tagslam_web
    content/measurements/_index.md and media/tag_corners.png: x right, y up, z out of the tag)."""
    h = s / 2
    return np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], float)


def tagslam_pose_from_4(img_points: np.ndarray, obj_points: np.ndarray, K: np.ndarray) -> np.ndarray:
    """``init_pose::pose_from_4`` (src/init_pose.cpp), radtan model with zero distortion: T_c_o.

    Undistort the pixels to normalised coordinates (cv::undistortPoints with K, D), homography
    from the object corners' (x, y) to them (cv::findHomography, method 0), scaled by its second
    singular value, sign flipped if ``trace(iph H wh^T) < 0``; ``decompose_homography_svd`` (R
    from the SVD of [h1, h2, h1 x h2], t = h3 / |h1|) as the initial guess of cv::solvePnP (unit
    camera matrix, zero distortion, useExtrinsicGuess, SOLVEPNP_ITERATIVE). The view-angle /
    ambiguity check that may drop the tag (rpp::check_quality) is not replicated.
    """
    ip = np.asarray(img_points, np.float64).reshape(-1, 1, 2)
    wp = np.asarray(obj_points, np.float64)
    imu = cv2.undistortPoints(ip, np.asarray(K, np.float64), np.zeros(5)).reshape(-1, 2)
    HL, _ = cv2.findHomography(wp[:, :2], imu)
    sv = np.linalg.svd(HL, compute_uv=False)
    H = HL / sv[1]
    iph = np.hstack([imu, np.ones((len(imu), 1))])
    wh = wp.copy()
    wh[:, 2] = 1.0
    H = H if np.trace(iph @ H @ wh.T) >= 0 else -H
    H12 = np.column_stack([H[:, 0], H[:, 1], np.cross(H[:, 0], H[:, 1])])
    U, _, VT = np.linalg.svd(H12)
    R = U @ np.diag([1, 1, np.linalg.det(U @ VT)]) @ VT
    tvec = (H[:, 2] / np.linalg.norm(H[:, 0])).reshape(3, 1)
    rvec = cv2.Rodrigues(R)[0]
    ok, rvec, tvec = cv2.solvePnP(wp.reshape(-1, 1, 3), imu.reshape(-1, 1, 2), np.eye(3), np.zeros(4),
                                  rvec, tvec, True)
    if not ok:
        raise RuntimeError("cv::solvePnP failed")
    return _pose(Rotation.from_rotvec(rvec.ravel()).as_matrix(), tvec)   # make_transform(rvec, tvec)


def tagslam_camera_poses(tags_path: str | Path, image: np.ndarray, K: np.ndarray, *,
                         pixel_offset: float = 0.0, detections: list[dict] | None = None
                         ) -> dict[int, np.ndarray]:
    """``world_from_cam`` (OpenCV camera: TagSLAM projects u = K T_c_o X, init_pose.cpp) per
    detected tag with a known pose, from that ONE tag, as TagSLAM initialises a camera (rig)
    pose from a tag projection factor (src/graph_updater.cpp ``init_from_proj_factor`` lines
    358-387 and ``set_value_from_tag_projection`` case 1, lines 243-247: T_w_r = T_w_b T_b_o
    T_o_c T_c_r, here with T_c_r = identity). Image corners: the detection's corners in the
    detector's order (src/factor/tag_projection.cpp lines 21-23), from the AprilTag 3 library
    (versatran01/apriltag ``ApriltagDetectorUmich::DetectImpl`` copies ``p`` unchanged)."""
    known = _tagslam_bodies(Path(tags_path))
    dets = detections if detections is not None else apriltag_detections(image, quad_decimate=1.0)
    out = {}
    for d in dets:
        if d["id"] not in known:
            continue
        size, T_w_o = known[d["id"]]
        T_c_o = tagslam_pose_from_4(d["corners"] + pixel_offset, _tagslam_object_corners(size), K)
        out[d["id"]] = T_w_o @ _inv(T_c_o)
    return out


# ------------------------------------------------------------------------------------------------
# 4. ROS 2 apriltag_ros node: ros2_apriltag_params.yaml + ros2_tag_transforms.launch.yaml
# ------------------------------------------------------------------------------------------------

def _ros2_node_params(path: Path) -> dict:
    """The ``ros__parameters`` of the parameter file (``/**`` or any node name)."""
    doc = yaml.safe_load(Path(path).read_text())
    ((_, node),) = doc.items()
    return node["ros__parameters"]


def ros2_static_transforms(launch_path: str | Path) -> dict[tuple[str, str], np.ndarray]:
    """{(frame_id, child_frame_id): parent_from_child (4, 4)} of every ``tf2_ros
    static_transform_publisher`` node of a ROS 2 YAML launch file.

    Arguments as ``parse_args`` of ros2/geometry2 tf2_ros/src/static_transform_broadcaster_program.cpp
    reads them: ``--x/--y/--z`` translation (default 0), ``--qx/--qy/--qz/--qw`` quaternion
    (default identity) or ``--roll/--pitch/--yaw`` (``setRPY``), ``--frame-id`` parent,
    ``--child-frame-id`` child. The node publishes it as a TransformStamped header.frame_id ->
    child_frame_id (static_transform_broadcaster_node.cpp), tf2's meaning of which is the child
    frame's pose in the parent: p_parent = R p_child + t.
    """
    doc = yaml.safe_load(Path(launch_path).read_text())
    out = {}
    for entry in doc.get("launch") or []:
        node = entry.get("node")
        if not node or node.get("pkg") != "tf2_ros" or node.get("exec") != "static_transform_publisher":
            continue
        args = shlex.split(str(node["args"]))
        vals: dict[str, str] = {}
        i = 0
        while i < len(args):
            if not args[i].startswith("--") or i + 1 >= len(args):
                raise ValueError(f"static_transform_publisher argument not understood: {args[i:]}")
            vals[args[i][2:]] = args[i + 1]
            i += 2
        t = [float(vals.get(k, 0.0)) for k in ("x", "y", "z")]
        if any(k in vals for k in ("roll", "pitch", "yaw")):
            if any(k in vals for k in ("qx", "qy", "qz", "qw")):
                raise ValueError("both quaternion and Euler rotations")
            # tf2 setRPY(roll, pitch, yaw): fixed axes x, y, z
            R = Rotation.from_euler("xyz", [float(vals.get(k, 0.0)) for k in ("roll", "pitch", "yaw")]).as_matrix()
        else:
            q = np.array([float(vals.get(k, d)) for k, d in (("qx", 0), ("qy", 0), ("qz", 0), ("qw", 1))])
            if abs(np.linalg.norm(q) - 1.0) > 1e-6:
                raise ValueError(f"quaternion {q} is not unit length")
            R = Rotation.from_quat(q).as_matrix()
        out[(vals["frame-id"], vals["child-frame-id"])] = _pose(R, t)
    return out


def ros2_pnp(corners: np.ndarray, K: np.ndarray, tagsize: float) -> np.ndarray:
    """christianrauch/apriltag_ros ``pnp`` (src/pose_estimation.cpp): camera_from_tag (4, 4).

    Object points (-s/2, -s/2, 0), (s/2, -s/2, 0), (s/2, s/2, 0), (-s/2, s/2, 0) paired with
    ``detection->p[0..3]``; camera matrix a default-constructed cv::Matx33d (all zero) with only
    fx, fy, cx, cy set (so its (2, 2) entry stays 0, as in the source); distortion ``{}`` (none);
    cv::solvePnP default flags. ``tf2::toMsg(pair(tvec, rvec))`` (src/conversion.cpp): translation
    = tvec, rotation = AngleAxis(|rvec|, rvec / |rvec|), the transform camera -> tag frame.
    Intrinsics from CameraInfo ``p[0], p[5], p[2], p[6]`` (AprilTagNode.cpp ``onCamera``): the
    rectified camera's fx, fy, cx, cy.
    """
    s = float(tagsize)
    obj = np.array([[-s / 2, -s / 2, 0], [s / 2, -s / 2, 0], [s / 2, s / 2, 0], [-s / 2, s / 2, 0]], np.float64)
    cam = np.zeros((3, 3))
    cam[0, 0], cam[1, 1], cam[0, 2], cam[1, 2] = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    ok, rvec, tvec = cv2.solvePnP(obj.reshape(-1, 1, 3), np.asarray(corners, np.float64).reshape(-1, 1, 2), cam, None)
    if not ok:
        raise RuntimeError("cv::solvePnP failed")
    return _pose(Rotation.from_rotvec(rvec.ravel()).as_matrix(), tvec)


def ros2_camera_poses(params_path: str | Path, launch_path: str | Path, image: np.ndarray, K: np.ndarray, *,
                      pixel_offset: float = 0.0, detections: list[dict] | None = None,
                      map_frame: str = "map") -> dict[int, np.ndarray]:
    """``world_from_cam`` (OpenCV camera = the node's camera optical frame; world = ``map``) per
    detected tag: ``map_from_(map_<tag frame>) @ inverse(camera_from_(<tag frame>))``.

    The node (src/AprilTagNode.cpp): family and detector settings from the parameter file
    (``family``, default detector quad_decimate 2.0), ignores ids not in ``tag.ids`` when
    ``tag.frames`` is set, rejects ``hamming > max_hamming``, sizes ``tag.sizes`` (else ``size``),
    publishes camera -> ``tag.frames[i]`` with :func:`ros2_pnp` when ``pose_estimation_method`` is
    ``pnp``. The static transform of the same physical tag is ``map -> map_<tag frame>`` in the
    launch file (the frame names the parameter file gives, prefixed by the parent frame, as the
    two files' comments say); a tag with no such transform is skipped.
    """
    node = _ros2_node_params(Path(params_path))
    if str(node.get("family", "36h11")) != "36h11":
        raise ValueError(f"family {node.get('family')!r} is not 36h11")
    if node.get("pose_estimation_method", "pnp") != "pnp":
        raise ValueError("only the pnp pose estimation method is replicated")
    ids = [int(i) for i in node["tag"]["ids"]]
    frames = dict(zip(ids, node["tag"].get("frames") or []))
    sizes = dict(zip(ids, node["tag"].get("sizes") or []))
    default_size = float(node.get("size", 1.0))
    max_hamming = int(node.get("max_hamming", 0))
    statics = ros2_static_transforms(launch_path)
    # detector.decimate: default apriltag_detector_create()'s quad_decimate, 2.0 (AprilTagNode.cpp)
    dec = float((node.get("detector") or {}).get("decimate", 2.0))
    dets = detections if detections is not None else apriltag_detections(image, quad_decimate=dec, max_hamming=99)
    out = {}
    for d in dets:
        if frames and d["id"] not in frames:
            continue
        if d["hamming"] > max_hamming:
            continue
        frame = frames.get(d["id"], f"tag36h11:{d['id']}")
        key = (map_frame, f"{map_frame}_{frame}")
        if key not in statics:
            continue
        camera_from_tag = ros2_pnp(d["corners"] + pixel_offset, K, float(sizes.get(d["id"], default_size)))
        out[d["id"]] = statics[key] @ _inv(camera_from_tag)
    return out


# ------------------------------------------------------------------------------------------------
# All at once
# ------------------------------------------------------------------------------------------------

def camera_poses(tagmaps_dir: str | Path, image: np.ndarray, K: np.ndarray, *, suffix: str = "",
                 pixel_offset: float = 0.0) -> dict[str, dict[int, np.ndarray]]:
    """{format: {tag id: world_from_cam (4, 4)}} for every consumer of :data:`FORMATS`, each
    from ONE detected tag, reading ``tagmaps_dir``'s files with ``suffix`` (``""`` for the model
    frame, ``"_yup"`` etc. for the file-axes maps, whose poses are then in the file's axes).
    The WPILib consumer is told the tag sizes of the ROS 2 parameter file (:func:`tag_sizes`)."""
    d = Path(tagmaps_dir)
    f = {k: [d / _suffixed(n, suffix) for n in names] for k, names in FILES.items()}
    return {
        "wpilib": wpilib_camera_poses(f["wpilib"][0], image, K, tag_sizes(f["ros2"][0]), pixel_offset=pixel_offset),
        "apriltag_ros": apriltag_ros_camera_poses(f["apriltag_ros"][0], image, K, pixel_offset=pixel_offset),
        "tagslam": tagslam_camera_poses(f["tagslam"][0], image, K, pixel_offset=pixel_offset),
        "ros2": ros2_camera_poses(f["ros2"][0], f["ros2"][1], image, K, pixel_offset=pixel_offset),
    }


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(position error in metres, rotation error in degrees) between two (4, 4) poses."""
    dt = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
    c = (np.trace(T_est[:3, :3].T @ T_true[:3, :3]) - 1) / 2
    return dt, float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
