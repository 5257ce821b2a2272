"""The tag family against the outside world: the official images and codes, and the pose the
AprilTag library reports for an upright tag.

Nothing here compares markerplace with its own drawing: the expected cells come from the
official apriltag-imgs PNGs (tests/data/apriltag_imgs) and from the AprilTag C library's own
``apriltag_to_image`` (the build pupil-apriltags ships), and the expected rotation from the
library's documented frames (README, "Coordinate System"): camera x right, y down, z out of the
lens; tag x to a facing viewer's right, y down, z into the tag.
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest

from helpers.official_tags import OFFICIAL_IDS, official_png
from markerplace.geometry import Intrinsics, world_from_marker_pose
from markerplace.localization.tags import make_detector
from markerplace.markers import Marker
from markerplace.render.renderer import Renderer
from markerplace.scene.types import MeshPart, Scene
from markerplace.tagfamily import NUM_TAGS, QUIET_BITS, TAG_BITS, tag_image

UP = np.array([0.0, 0.0, 1.0])


def _black_square(tag_id: int) -> np.ndarray:
    """(8, 8) bool, True = white, of markerplace's drawing (one pixel per bit, quiet zone cut)."""
    img = tag_image(tag_id, pixels_per_bit=1)
    return img[QUIET_BITS:QUIET_BITS + TAG_BITS, QUIET_BITS:QUIET_BITS + TAG_BITS] > 127


@pytest.mark.parametrize("tag_id", OFFICIAL_IDS)
def test_bitmaps_equal_the_official_images_cell_by_cell(tag_id):
    official = official_png(tag_id) > 127
    assert official.shape == (10, 10)
    assert official[0].all() and official[-1].all() and official[:, 0].all() and official[:, -1].all()
    np.testing.assert_array_equal(_black_square(tag_id), official[1:-1, 1:-1])
    # the quiet zone is white all round
    img = tag_image(tag_id, pixels_per_bit=1)
    assert (img[:QUIET_BITS] == 255).all() and (img[-QUIET_BITS:] == 255).all()
    assert (img[:, :QUIET_BITS] == 255).all() and (img[:, -QUIET_BITS:] == 255).all()


class _ImageU8(ctypes.Structure):
    _fields_ = [("width", ctypes.c_int32), ("height", ctypes.c_int32), ("stride", ctypes.c_int32),
                ("buf", ctypes.POINTER(ctypes.c_uint8))]


@pytest.fixture(scope="module")
def apriltag_library():
    """The AprilTag C library that pupil-apriltags loads, and its tag36h11 family."""
    import pupil_apriltags

    libdir = Path(pupil_apriltags.__file__).parent
    path = next(p for p in sorted(libdir.rglob("libapriltag.so*")))
    lib = ctypes.CDLL(str(path))
    lib.tag36h11_create.restype = ctypes.c_void_p
    lib.tag36h11_destroy.argtypes = [ctypes.c_void_p]
    lib.apriltag_to_image.restype = ctypes.POINTER(_ImageU8)
    lib.apriltag_to_image.argtypes = [ctypes.c_void_p, ctypes.c_uint32]
    lib.image_u8_destroy.argtypes = [ctypes.POINTER(_ImageU8)]
    family = lib.tag36h11_create()
    yield lib, family
    lib.tag36h11_destroy(family)


def test_every_id_has_the_apriltag_library_data_bits(apriltag_library):
    """All 587 ids: the 6 x 6 data cells equal those the library's ``apriltag_to_image`` draws
    from its own code table (its 10 x 10 image: data cells at rows/columns 2..7; this build
    draws its white ring one cell inside, over the black border, so only the data cells and
    the layout, not the ring, are compared)."""
    lib, family = apriltag_library
    for tag_id in range(NUM_TAGS):
        ptr = lib.apriltag_to_image(family, tag_id)
        im = ptr.contents
        buf = np.ctypeslib.as_array(im.buf, shape=(im.height * im.stride,)).reshape(im.height, im.stride)
        expected = buf[2:8, 2:8] > 127
        got = _black_square(tag_id)[1:7, 1:7]
        lib.image_u8_destroy(ptr)
        assert np.array_equal(got, expected), f"tag {tag_id} differs from the AprilTag library's table"
    # and the border is black all round
    for tag_id in (0, 586):
        sq = _black_square(tag_id)
        assert not sq[0].any() and not sq[-1].any() and not sq[:, 0].any() and not sq[:, -1].any()


def _look_at(eye, target) -> np.ndarray:
    """(4, 4) world_from_cam of an OpenCV camera (x right, y down, z forward) at ``eye`` looking
    at ``target``, level (no roll)."""
    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, UP)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, eye
    return T


def _documented_world_from_tag(centre, normal) -> np.ndarray:
    """(4, 4) the AprilTag library's tag frame of an upright tag (top edge up) on a wall whose
    outward normal is ``normal``: x to a facing viewer's right, y down, z into the tag."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    z = -n  # into the tag
    y = -UP  # down
    x = np.cross(y, z)  # right-handed: x = y cross z
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, y, z, centre
    return T


def _wall(x: float) -> Scene:
    verts = np.array([[x, 5, -2], [x, -5, -2], [x, -5, 5], [x, 5, 5]], np.float32)
    return Scene("wall", (MeshPart("wall", verts, np.array([[0, 1, 2], [0, 2, 3]], np.int32),
                                   base_color=(0.5, 0.5, 0.5, 1)),))


# Not head-on: a single tag's pose is ill-conditioned seen square on (corner noise of 0.2 px
# moves it by about 0.7 degrees); the head-on corners are checked in tests/render/test_tags.py.
POSES = [
    # camera eye, point looked at (tag centre at (3, 0, 1.5) on the wall x = 3, facing -x)
    ([1.0, 0.5, 1.2], [3.0, 0.0, 1.5]),   # 2 m in front, 0.5 m to its side, 0.3 m below (the case)
    ([1.0, -0.6, 1.8], [3.0, 0.0, 1.5]),  # 2 m in front, 0.6 m to the other side, 0.3 m above
    ([1.2, -1.4, 1.2], [3.0, 0.1, 1.6]),  # oblique, about 40 degrees
]


@pytest.mark.parametrize("eye,target", POSES)
def test_pupil_pose_of_an_upright_tag_is_the_documented_rotation(eye, target):
    """A tag hung top edge up, rendered and detected by pupil-apriltags with its own pose
    estimate: ``pose_R`` (cam_from_tag) is the rotation the library's documented frames give
    for that geometry, within 1 degree, and ``pose_t`` the tag centre in the camera, within 2 cm."""
    centre, normal, size = np.array([3.0, 0.0, 1.5]), np.array([-1.0, 0.0, 0.0]), 0.4
    marker = Marker(3, size, world_from_marker_pose(centre, normal))
    world_from_cam = _look_at(np.array(eye, float), np.array(target, float))
    intr = Intrinsics.from_fov(1600, 1200, 90.0)  # the tag spans 150-200 px: a tight pose estimate
    with Renderer(_wall(3.0), intr, markers=[marker]) as r:
        rgb = r.render(world_from_cam, depth=False, normal=False).rgb
    gray = np.ascontiguousarray(rgb.mean(axis=2).round().astype(np.uint8))
    K = intr.K
    det = make_detector(quad_decimate=1.0)
    # the library's pixel centres sit at +0.5 (OpenCV's at integers): shift the principal point
    found = det.detect(gray, estimate_tag_pose=True, camera_params=(K[0, 0], K[1, 1], K[0, 2] + 0.5, K[1, 2] + 0.5),
                       tag_size=size)
    assert [d.tag_id for d in found] == [3] and found[0].hamming == 0
    cam_from_tag = np.linalg.inv(world_from_cam) @ _documented_world_from_tag(centre, normal)
    R_err = cam_from_tag[:3, :3].T @ np.asarray(found[0].pose_R)
    angle = np.degrees(np.arccos(np.clip((np.trace(R_err) - 1) / 2, -1, 1)))
    assert angle < 1.0, f"detector rotation is {angle:.1f} deg from the documented one"
    assert np.linalg.norm(np.asarray(found[0].pose_t).ravel() - cam_from_tag[:3, 3]) < 0.02
