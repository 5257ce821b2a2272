"""Writers of RGB-D sequences in the layouts ``markerplace fuse`` reads, each in that format's own
documented conventions, written here independently of the readers (so a convention error in a
reader shows as a pose or surface error, not as a matching error in both):

* 7-Scenes: ``frame-NNNNNN.{color.png,depth.png,pose.txt}``, millimetres with 65535 for no
  reading, 4x4 camera-to-world (OpenCV camera), ``camera-intrinsics.txt``, ``gravity-direction.txt``
  (gravity, pointing down);
* nerfstudio: ``transforms.json`` with OpenGL camera axes (the pose's y and z columns negated),
  principal point in nerfstudio's pixel convention (centre of pixel (0, 0) at (0.5, 0.5)),
  optional OPENCV distortion applied to the stored images, depth PNGs in millimetres at a lower
  resolution;
* Stray Scanner: ``odometry.csv`` rows as the app's ``OdometryEncoder.swift`` writes them (ARKit
  camera transform, OpenGL axes, times the 180 deg x rotation ``q_AC``; quaternion scalar last),
  ``camera_matrix.csv``, depth (millimetres) and confidence at a lower resolution, colour as
  ``rgb.mp4`` or ``rgb/`` images;
* TUM RGB-D: ``rgb.txt``, ``depth.txt``, ``groundtruth.txt`` (quaternion scalar last), depth
  x5000.

A frame is (rgb (H, W, 3) uint8, depth (H, W) float metres with 0 = no reading, (4, 4)
``world_from_cam`` in OpenCV camera axes in the world the files are to be written in).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from markerplace.geometry import Intrinsics

Frame = tuple[np.ndarray, np.ndarray, np.ndarray]


def quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w) of a rotation matrix (Shepperd's method), w >= 0."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array([(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s])
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.zeros(4)
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def hamilton(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (x, y, z, w)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def opengl_pose(T_cv: np.ndarray) -> np.ndarray:
    """The same camera with OpenGL axes (x right, y up, z back): y and z columns negated."""
    T = np.array(T_cv, dtype=np.float64)
    T[:3, 1] *= -1.0
    T[:3, 2] *= -1.0
    return T


def _mm(depth_m: np.ndarray) -> np.ndarray:
    return np.rint(np.asarray(depth_m) * 1000.0).astype(np.uint16)


def _save_png(path: Path, img: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if img.ndim == 3:
        Image.fromarray(img).save(path)
    elif not cv2.imwrite(str(path), img):
        raise OSError(f"cannot write {path}")


def write_7scenes(root: Path, frames: list[Frame], intr: Intrinsics, gravity_down=None, intrinsics_file: bool = True) -> None:
    """A 7-Scenes sequence folder (module docstring); ``gravity_down`` (3,) in the poses' world."""
    root.mkdir(parents=True, exist_ok=True)
    for i, (rgb, depth, T) in enumerate(frames):
        name = f"frame-{i:06d}"
        _save_png(root / f"{name}.color.png", rgb)
        d = _mm(depth)
        d[depth <= 0] = 65535
        _save_png(root / f"{name}.depth.png", d)
        (root / f"{name}.pose.txt").write_text("".join(" ".join(f"{v:.18e}" for v in row) + "\n" for row in T))
    if intrinsics_file:
        K = [[intr.fx, 0, intr.cx], [0, intr.fy, intr.cy], [0, 0, 1]]
        (root / "camera-intrinsics.txt").write_text("".join(" ".join(f"{v:.18e}" for v in row) + "\n" for row in K))
    if gravity_down is not None:
        (root / "gravity-direction.txt").write_text("".join(f"{v:.18e}\n" for v in gravity_down))


def distort_image(img: np.ndarray, intr: Intrinsics, coeffs, interpolation) -> np.ndarray:
    """The image an OPENCV-distorted lens with K of ``intr`` records of the pinhole ``img``:
    each stored pixel looks up its undistorted position (``cv2.undistortPoints``)."""
    K = np.asarray(intr.K, dtype=np.float64)
    v, u = np.mgrid[0:intr.height, 0:intr.width].astype(np.float64)
    pts = np.stack([u.ravel(), v.ravel()], axis=1).reshape(-1, 1, 2)
    und = cv2.undistortPoints(pts, K, np.asarray(coeffs, dtype=np.float64), P=K).reshape(intr.height, intr.width, 2)
    return cv2.remap(img, und[..., 0].astype(np.float32), und[..., 1].astype(np.float32), interpolation,
                     borderMode=cv2.BORDER_CONSTANT)


def write_nerfstudio(root: Path, frames: list[Frame], intr: Intrinsics, depth_every: int | None = 1,
                     depth_size: tuple[int, int] | None = None, opencv_coeffs=None, per_frame_camera: bool = False) -> dict:
    """A nerfstudio data folder; ``opencv_coeffs`` (k1, k2, p1, p2, k3) distorts the stored images;
    ``depth_every`` None writes no depth; ``depth_size`` (w, h) stores depth smaller. Returns the json."""
    root.mkdir(parents=True, exist_ok=True)
    cam = {"fl_x": intr.fx, "fl_y": intr.fy, "cx": intr.cx + 0.5, "cy": intr.cy + 0.5, "w": intr.width, "h": intr.height}
    meta: dict = {"camera_model": "OPENCV"}
    if opencv_coeffs is not None:
        k1, k2, p1, p2, k3 = opencv_coeffs
        cam.update({"k1": k1, "k2": k2, "p1": p1, "p2": p2, "k3": k3})
    if not per_frame_camera:
        meta.update(cam)
    out = []
    for i, (rgb, depth, T) in enumerate(frames):
        d = _mm(depth)
        if opencv_coeffs is not None:
            rgb = distort_image(rgb, intr, opencv_coeffs, cv2.INTER_LINEAR)
            d = distort_image(d, intr, opencv_coeffs, cv2.INTER_NEAREST)
        frame = {"file_path": f"images/frame_{i + 1:05d}.png", "transform_matrix": opengl_pose(T).tolist()}
        if per_frame_camera:
            frame.update(cam)
        _save_png(root / frame["file_path"], rgb)
        if depth_every is not None and i % depth_every == 0:
            frame["depth_file_path"] = f"depth/frame_{i + 1:05d}.png"
            if depth_size is not None:
                d = cv2.resize(d, depth_size, interpolation=cv2.INTER_NEAREST_EXACT)
            _save_png(root / frame["depth_file_path"], d)
        out.append(frame)
    meta["frames"] = out[::-1]  # nerfstudio sorts by file name: the reader must too
    (root / "transforms.json").write_text(json.dumps(meta, indent=2))
    return meta


Q_AC = np.array([1.0, 0.0, 0.0, 0.0])
"""Stray Scanner's ``q_AC`` (x, y, z, w): 180 deg about the camera x axis."""


def stray_row(timestamp: float, frame: int, T_arkit: np.ndarray) -> str:
    """One ``odometry.csv`` row as ``OdometryEncoder.add`` writes it from ARKit's ``camera.transform``."""
    q = hamilton(quaternion_xyzw(T_arkit[:3, :3]), Q_AC)
    x, y, z = T_arkit[:3, 3]
    return f"{timestamp}, {frame:06d}, {x}, {y}, {z}, {q[0]}, {q[1]}, {q[2]}, {q[3]}\n"


def write_stray(root: Path, frames: list[Frame], intr: Intrinsics, depth_frames: list[np.ndarray], video: bool = True,
                confidence: list[np.ndarray] | None = None) -> None:
    """A Stray Scanner export: ``depth_frames`` are the (lower-resolution) depths in metres."""
    root.mkdir(parents=True, exist_ok=True)
    K = [[intr.fx, 0.0, intr.cx], [0.0, intr.fy, intr.cy], [0.0, 0.0, 1.0]]
    (root / "camera_matrix.csv").write_text("\n".join(", ".join(str(v) for v in row) for row in K))
    rows = ["timestamp, frame, x, y, z, qx, qy, qz, qw\n"]
    writer = None
    if video:
        writer = cv2.VideoWriter(str(root / "rgb.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 30, (intr.width, intr.height))
        assert writer.isOpened()
    for i, (rgb, _, T) in enumerate(frames):
        rows.append(stray_row(1000.0 + i / 30.0, i, opengl_pose(T)))
        if writer is not None:
            writer.write(np.ascontiguousarray(rgb[..., ::-1]))
        else:
            _save_png(root / "rgb" / f"{i:06d}.png", rgb)
        _save_png(root / "depth" / f"{i:06d}.png", _mm(depth_frames[i]))
        if confidence is not None:
            _save_png(root / "confidence" / f"{i:06d}.png", confidence[i].astype(np.uint8))
    if writer is not None:
        writer.release()
    (root / "odometry.csv").write_text("".join(rows))


def write_tum(root: Path, frames: list[Frame]) -> None:
    """A TUM RGB-D sequence: 30 Hz colour, depth 5 ms later, ground truth at the colour times."""
    root.mkdir(parents=True, exist_ok=True)
    rgb_lines, depth_lines, gt = ["# color images\n"], ["# depth maps\n"], ["# timestamp tx ty tz qx qy qz qw\n"]
    for i, (rgb, depth, T) in enumerate(frames):
        t = 1305031102.0 + i / 30.0
        rgb_lines.append(f"{t:.6f} rgb/{t:.6f}.png\n")
        depth_lines.append(f"{t + 0.005:.6f} depth/{t + 0.005:.6f}.png\n")
        _save_png(root / "rgb" / f"{t:.6f}.png", rgb)
        _save_png(root / "depth" / f"{t + 0.005:.6f}.png", np.rint(depth * 5000.0).astype(np.uint16))
        q = quaternion_xyzw(T[:3, :3])
        gt.append(f"{t:.6f} {T[0, 3]:.9f} {T[1, 3]:.9f} {T[2, 3]:.9f} {q[0]:.12f} {q[1]:.12f} {q[2]:.12f} {q[3]:.12f}\n")
    (root / "rgb.txt").write_text("".join(rgb_lines))
    (root / "depth.txt").write_text("".join(depth_lines))
    (root / "groundtruth.txt").write_text("".join(gt))
