"""Photos of the tags on the walls for ``check --photos``: a folder of JPEG/PNG photos (any size,
a phone's, each with its own camera) or an RGB-D frame folder of the layouts ``fuse`` reads.

A photo's pinhole camera (pixels, principal point at the image centre, no distortion):

1. ``--intrinsics FILE.json`` when given (``width, height, fx, fy, cx, cy``; a photo of another
   size with the same aspect ratio gets them scaled; a calibrated camera beats EXIF);
2. else its EXIF: ``FocalLengthIn35mmFilm`` (f_px = f35 x image diagonal / 43.27 mm, the 35 mm
   film diagonal, as the CIPA DC-008 equivalent focal length is defined), else ``FocalLength``
   (mm) with ``FocalPlaneXResolution`` and its unit (the sensor's pixels per mm, scaled by
   the photo's width over ``ExifImageWidth`` when it was resized);
3. else :class:`~markerplace.errors.UserError`: pass ``--intrinsics``.

EXIF ``Orientation`` is applied (the pixels as a viewer sees the photo). A frame folder
(:func:`markerplace.scan.frames.detect_format` recognises it) brings its own intrinsics and
distortion (:func:`~markerplace.scan.frame_images.load_frame`); its poses are not used.
"""

from __future__ import annotations

import hashlib
import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics
from markerplace.scan.frame_images import load_frame
from markerplace.scan.frames import detect_format, open_frameset
from markerplace.scan.frameset import FrameSet, frame_intrinsics, read_intrinsics

log = logging.getLogger(__name__)

__all__ = ["Photo", "list_photos", "load_photo", "exif_intrinsics", "PHOTO_SUFFIXES"]

PHOTO_SUFFIXES = (".jpg", ".jpeg", ".png")
FILM_DIAGONAL_MM = math.hypot(36.0, 24.0)
_EXIF_IFD = 0x8769
_FOCAL_35 = 0xA405
_FOCAL = 0x920A
_PLANE_XRES = 0xA20E
_PLANE_UNIT = 0xA210
_EXIF_WIDTH = 0xA002
_MM_PER_UNIT = {2: 25.4, 3: 10.0, 4: 1.0, 5: 0.001}
"""FocalPlaneResolutionUnit: 2 inch, 3 cm, 4 mm, 5 micrometre (EXIF 2.32)."""


@dataclass(frozen=True)
class Photo:
    """One photo.

    Attributes:
        name: its file name (relative to the folder) or frame name.
        key: SHA-256 of its file (a video frame: of the video and the frame number), hex.
        intrinsics: its pinhole camera (pixels, as loaded: EXIF orientation applied, undistorted).
        path: the image file.
        frame: (frame set, record) for a frame folder's frame, else None.
    """

    name: str
    key: str
    intrinsics: Intrinsics
    path: Path
    frame: tuple | None = None


def _sha(path: Path, extra: str = "") -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    h.update(extra.encode())
    return h.hexdigest()


def exif_intrinsics(path: Path) -> Intrinsics | None:
    """The pinhole camera of a photo from its EXIF (module docstring), None when EXIF has no
    focal length it can use. Width and height are the photo's as a viewer sees it."""
    from PIL import Image

    try:
        with Image.open(path) as img:
            exif = img.getexif()
            orientation = exif.get(0x0112, 1)
            w, h = img.size
    except (OSError, ValueError) as err:
        raise UserError(f"photo {path}: cannot read it ({err})") from None
    if orientation in (5, 6, 7, 8):
        w, h = h, w
    sub = exif.get_ifd(_EXIF_IFD)
    f35 = _num(sub.get(_FOCAL_35))
    f_px = None
    if f35:
        f_px = f35 * math.hypot(w, h) / FILM_DIAGONAL_MM
    else:
        f_mm, xres, unit = _num(sub.get(_FOCAL)), _num(sub.get(_PLANE_XRES)), sub.get(_PLANE_UNIT, 2)
        if f_mm and xres and unit in _MM_PER_UNIT:
            px_per_mm = xres / _MM_PER_UNIT[unit]
            native = _num(sub.get(_EXIF_WIDTH))
            long_side = max(w, h)
            f_px = f_mm * px_per_mm * (long_side / native if native else 1.0)
    if not f_px or not math.isfinite(f_px) or f_px <= 0:
        return None
    return Intrinsics(w, h, f_px, f_px, (w - 1) / 2.0, (h - 1) / 2.0)


def _num(v) -> float | None:
    try:
        x = float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return x if math.isfinite(x) and x > 0 else None


def _scaled(intr: Intrinsics, w: int, h: int, path: Path, source: Path) -> Intrinsics:
    if (w, h) == (intr.width, intr.height):
        return intr
    s = w / intr.width
    if abs(h / intr.height - s) > 0.01:
        raise UserError(f"photo {path} is {w}x{h}, --intrinsics {source} is for {intr.width}x{intr.height} (another "
                        "aspect ratio): give the camera of these photos")
    return Intrinsics(w, h, intr.fx * s, intr.fy * s, (intr.cx + 0.5) * s - 0.5, (intr.cy + 0.5) * s - 0.5)


def _image_size(path: Path) -> tuple[int, int]:
    from PIL import Image

    try:
        with Image.open(path) as img:
            w, h = img.size
            if img.getexif().get(0x0112, 1) in (5, 6, 7, 8):
                w, h = h, w
    except (OSError, ValueError) as err:
        raise UserError(f"photo {path}: cannot read it ({err})") from None
    return w, h


def list_photos(root: str | Path, intrinsics_path: str | Path | None = None, exclude: str | Path | None = None
                ) -> list[Photo]:
    """The photos of ``root`` (module docstring), sorted by name; none under ``exclude`` (the
    output folder, whose drawn detections are PNGs too).

    Raises:
        UserError: no such folder, no photo in it, a photo without a usable camera.
    """
    root = Path(root)
    if not root.is_dir():
        raise UserError(f"--photos {root}: no such folder")
    try:
        fmt = detect_format(root)
    except UserError:
        fmt = None
    if fmt is not None:
        return _frame_photos(open_frameset(root, fmt, intrinsics_path))
    skip = Path(exclude).resolve() if exclude is not None else None
    files = sorted(p for p in root.rglob("*") if p.is_file() and p.suffix.lower() in PHOTO_SUFFIXES
                   and not (skip is not None and p.resolve().is_relative_to(skip)))
    if not files:
        raise UserError(f"--photos {root}: no JPEG or PNG photo in it (nor an RGB-D frame folder)")
    fixed = read_intrinsics(Path(intrinsics_path), 1000.0)[0] if intrinsics_path is not None else None
    out = []
    for p in files:
        if fixed is not None:
            intr = _scaled(fixed, *_image_size(p), p, Path(intrinsics_path))
        else:
            intr = exif_intrinsics(p)
            if intr is None:
                raise UserError(f"photo {p} has no focal length in its EXIF: pass --intrinsics FILE.json "
                                "(width, height, fx, fy, cx, cy in pixels)")
        out.append(Photo(p.relative_to(root).as_posix(), _sha(p), intr, p))
    return out


def _frame_photos(fs: FrameSet) -> list[Photo]:
    out = []
    for rec in fs.frames:
        if not rec.color_path.is_file():
            raise UserError(f"frame {rec.name}: colour image {rec.color_path} not found")
        extra = "" if rec.color_index is None else f"#{rec.color_index}"
        out.append(Photo(rec.name, _sha(rec.color_path, extra), frame_intrinsics(fs, rec), rec.color_path, (fs, rec)))
    return out


def load_photo(photo: Photo) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a photo as a viewer sees it (EXIF orientation applied; a frame
    undistorted), at its :attr:`Photo.intrinsics` size."""
    if photo.frame is not None:
        return load_frame(*photo.frame)[0]
    from PIL import Image, ImageOps

    try:
        with Image.open(photo.path) as img:
            rgb = np.asarray(ImageOps.exif_transpose(img).convert("RGB"))
    except (OSError, ValueError) as err:
        raise UserError(f"photo {photo.path}: cannot read it ({err})") from None
    if rgb.shape[:2] != (photo.intrinsics.height, photo.intrinsics.width):
        raise UserError(f"photo {photo.path}: {rgb.shape[1]}x{rgb.shape[0]} pixels, its camera says "
                        f"{photo.intrinsics.width}x{photo.intrinsics.height}")
    return np.ascontiguousarray(rgb)
