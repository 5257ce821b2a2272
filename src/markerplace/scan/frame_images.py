"""A frame's images as fusion wants them: pinhole colour and registered depth of the same size.

:func:`load_frame` reads one :class:`~markerplace.scan.frameset.FrameRecord`'s colour (an image
file, or frame ``color_index`` of a video, decoded with OpenCV frame by frame) and depth PNG,
and returns

* colour (H, W, 3) uint8 RGB, undistorted to the pinhole camera of
  :func:`~markerplace.scan.frameset.frame_intrinsics` when the frame has a lens distortion
  (same K; ``cv2`` undistortion maps, bilinear);
* depth (H, W) uint16 in ``fs.depth_scale`` units per metre, 0 = no reading: 7-Scenes' 65535
  read as 0, readings below :data:`~markerplace.scan.frameset.CONFIDENCE_MIN` confidence
  dropped, a smaller depth image of the same aspect ratio (Stray, nerfstudio) upsampled to the
  colour size by nearest neighbour with pixel centres aligned, depth of another camera (7-Scenes:
  ``FrameSet.depth_intrinsics``) resampled into the colour camera (:func:`register_depth`), and
  undistorted like the colour (nearest neighbour). A frame without depth (nerfstudio) gives all zeros.

Every problem raises :class:`~markerplace.errors.UserError` with one line naming the frame and file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.scan.frameset import CONFIDENCE_MIN, Distortion, FrameRecord, FrameSet, frame_intrinsics

RESAMPLED_DEPTH_FORMATS = ("stray", "nerfstudio")
"""Layouts whose depth images may be smaller than the colour (resized to it, nearest neighbour)."""
INVALID_DEPTH = {"7scenes": 65535}
"""Per layout, a depth value that means no reading (read as 0)."""


class _VideoCursor:
    """Sequential reader of one video; reopened when a frame before the current one is asked for."""

    def __init__(self, path: Path):
        import cv2

        self.path = path
        self.cap = cv2.VideoCapture(str(path))
        if not self.cap.isOpened():
            raise UserError(f"cannot decode {path} (not a video OpenCV can read?)")
        self.next = 0

    def read(self, index: int, name: str) -> np.ndarray:
        while self.next < index:
            if not self.cap.grab():
                raise UserError(f"frame {name}: {self.path} ends after {self.next} frames (frame {index} asked for)")
            self.next += 1
        ok, bgr = self.cap.read()
        if not ok or bgr is None:
            raise UserError(f"frame {name}: {self.path} ends after {self.next} frames (frame {index} asked for)")
        self.next += 1
        return np.ascontiguousarray(bgr[..., ::-1])

    def close(self) -> None:
        self.cap.release()


_video: _VideoCursor | None = None


def read_video_frame(path: Path, index: int, name: str) -> np.ndarray:
    """Frame ``index`` (0-based) of the video ``path`` as (H, W, 3) uint8 RGB."""
    global _video
    if not Path(path).is_file():
        raise UserError(f"frame {name}: colour video {path} not found")
    if _video is None or _video.path != Path(path) or index < _video.next:
        if _video is not None:
            _video.close()
        _video = None
        _video = _VideoCursor(Path(path))
    return _video.read(index, name)


def _read_colour(rec: FrameRecord) -> np.ndarray:
    from PIL import Image

    try:
        with Image.open(rec.color_path) as img:
            mode = img.mode
            if mode not in ("RGB", "RGBA", "L", "LA", "P"):
                raise UserError(f"frame {rec.name}: colour image {rec.color_path} has mode {mode}; it must be 8-bit RGB")
            return np.ascontiguousarray(np.asarray(img.convert("RGB")))
    except UserError:
        raise
    except Exception as err:  # PIL raises many kinds on corrupt files
        raise UserError(f"frame {rec.name}: cannot read colour image {rec.color_path} ({err.__class__.__name__})") from None


_maps: dict = {}


def undistort_maps(intr: Intrinsics, dist: Distortion) -> tuple[np.ndarray, np.ndarray]:
    """(map_x, map_y) float32 (H, W): the stored-image position of each pinhole pixel (same K)."""
    import cv2

    key = (intr, dist)
    if key not in _maps:
        K = np.asarray(intr.K, dtype=np.float64)
        D = np.array(dist.coeffs, dtype=np.float64)
        size = (int(intr.width), int(intr.height))
        if dist.model == "fisheye":
            m = cv2.fisheye.initUndistortRectifyMap(K, D.reshape(4, 1), np.eye(3), K, size, cv2.CV_32FC1)
        else:
            m = cv2.initUndistortRectifyMap(K, D, None, K, size, cv2.CV_32FC1)
        _maps.clear()  # one camera at a time is the common case; keep memory flat
        _maps[key] = m
    return _maps[key]


def nearest_resize(img: np.ndarray, width: int, height: int) -> np.ndarray:
    """Nearest-neighbour resize with pixel centres aligned: target pixel u takes source
    ``floor((u + 0.5) * w_src / width)``."""
    h, w = img.shape[:2]
    cols = np.minimum(((np.arange(width) + 0.5) * w / width).astype(np.int64), w - 1)
    rows = np.minimum(((np.arange(height) + 0.5) * h / height).astype(np.int64), h - 1)
    return np.ascontiguousarray(img[rows[:, None], cols[None, :]])


def _read_depth(fs: FrameSet, rec: FrameRecord, W: int, H: int) -> np.ndarray:
    import cv2

    depth = cv2.imread(str(rec.depth_path), cv2.IMREAD_UNCHANGED)
    if depth is None:
        raise UserError(f"frame {rec.name}: cannot read depth image {rec.depth_path} (not an image?)")
    if depth.dtype != np.uint16 or depth.ndim != 2:
        kind = f"{depth.dtype} with {1 if depth.ndim == 2 else depth.shape[2]} channel(s)"
        raise UserError(f"frame {rec.name}: depth image {rec.depth_path} is {kind}; it must be a 16-bit single-channel PNG")
    invalid = INVALID_DEPTH.get(fs.format)
    if invalid is not None:
        depth[depth == invalid] = 0
    if rec.confidence_path is not None:
        if not rec.confidence_path.is_file():
            raise UserError(f"frame {rec.name}: confidence image {rec.confidence_path} not found")
        conf = cv2.imread(str(rec.confidence_path), cv2.IMREAD_UNCHANGED)
        if conf is None or conf.ndim != 2 or conf.shape != depth.shape:
            got = "unreadable" if conf is None else f"{conf.shape[1]}x{conf.shape[0]}" + ("" if conf.ndim == 2 else " colour")
            raise UserError(f"frame {rec.name}: confidence image {rec.confidence_path} is {got}; it must be a single-channel "
                            f"PNG of the depth image's size {depth.shape[1]}x{depth.shape[0]}")
        depth[conf < CONFIDENCE_MIN] = 0
    if fs.depth_intrinsics is not None:
        return register_depth(depth, fs.depth_intrinsics, frame_intrinsics(fs, rec), rec)
    if depth.shape != (H, W):
        h, w = depth.shape
        if fs.format in RESAMPLED_DEPTH_FORMATS and abs(w * H - h * W) <= 0.01 * w * H and w <= W:
            depth = nearest_resize(depth, W, H)
        else:
            raise UserError(f"frame {rec.name}: depth image {rec.depth_path} is {w}x{h}, the intrinsics say {W}x{H}")
    return depth


def register_depth(depth: np.ndarray, depth_intr: Intrinsics, colour_intr: Intrinsics, rec: FrameRecord) -> np.ndarray:
    """Depth of another pinhole camera at the same pose resampled into the colour camera
    (nearest neighbour): colour pixel ``(u, v)`` takes the depth pixel ``K_depth K_colour^-1
    (u, v, 1)``, 0 where that falls outside the depth image. Planar depth is unchanged (same
    optical axis). (H_d, W_d) uint16 -> (H, W) uint16 of ``colour_intr``."""
    h, w = depth.shape
    if (w, h) != (depth_intr.width, depth_intr.height):
        raise UserError(f"frame {rec.name}: depth image {rec.depth_path} is {w}x{h}, the intrinsics say "
                        f"{depth_intr.width}x{depth_intr.height} (the depth camera)")
    u = np.arange(colour_intr.width, dtype=np.float64)
    v = np.arange(colour_intr.height, dtype=np.float64)
    ud = np.rint(depth_intr.cx + (u - colour_intr.cx) * depth_intr.fx / colour_intr.fx).astype(np.int64)
    vd = np.rint(depth_intr.cy + (v - colour_intr.cy) * depth_intr.fy / colour_intr.fy).astype(np.int64)
    out = np.zeros((colour_intr.height, colour_intr.width), np.uint16)
    cols, rows = (ud >= 0) & (ud < w), (vd >= 0) & (vd < h)
    out[np.ix_(rows, cols)] = depth[np.ix_(vd[rows], ud[cols])]
    return out


def load_frame(fs: FrameSet, rec: FrameRecord) -> tuple[np.ndarray, np.ndarray]:
    """Read one frame's images (module docstring) and check them against its intrinsics.

    Returns:
        rgb (H, W, 3) uint8 and depth (H, W) uint16 in ``fs.depth_scale`` units per metre, both
        of the pinhole camera :func:`~markerplace.scan.frameset.frame_intrinsics` ``(fs, rec)``.

    Raises:
        UserError: missing or unreadable file, wrong size, colour not 8-bit, depth not 16-bit
            single-channel, a video shorter than the frame list.
    """
    import cv2

    intr = frame_intrinsics(fs, rec)
    W, H = intr.width, intr.height
    paths = [(rec.color_path, "colour video" if rec.color_index is not None else "colour image")]
    if rec.depth_path is not None:
        paths.append((rec.depth_path, "depth image"))
    for p, what in paths:
        if not p.is_file():
            raise UserError(f"frame {rec.name}: {what} {p} not found")
    depth = _read_depth(fs, rec, W, H) if rec.depth_path is not None else np.zeros((H, W), np.uint16)
    rgb = read_video_frame(rec.color_path, rec.color_index, rec.name) if rec.color_index is not None else _read_colour(rec)
    if rgb.shape[:2] != (H, W):
        raise UserError(f"frame {rec.name}: colour image {rec.color_path} is {rgb.shape[1]}x{rgb.shape[0]}, the intrinsics say {W}x{H}")
    if rec.distortion is not None and not rec.distortion.is_zero:
        mx, my = undistort_maps(intr, rec.distortion)
        rgb = cv2.remap(rgb, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        depth = cv2.remap(depth, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
    return np.ascontiguousarray(rgb), np.ascontiguousarray(depth)


__all__ = ["RESAMPLED_DEPTH_FORMATS", "INVALID_DEPTH", "read_video_frame", "undistort_maps", "nearest_resize", "register_depth",
           "load_frame"]
