"""Tag images and rendered markers: ids and corners agree with pupil-apriltags detection."""

from __future__ import annotations

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.geometry import Intrinsics, project, world_from_cam_pose, world_from_marker_pose
from markerplace.localization.tags import make_detector
from markerplace.markers import Marker
from markerplace.render import gl_resources
from markerplace.render.renderer import Renderer
from markerplace.scene.types import MeshPart, Scene
from markerplace.tagfamily import QUIET_BITS, TAG_BITS, outer_size, tag_image

K = Intrinsics().K


def grey_wall(x: float = 3.0) -> Scene:
    verts = np.array([[x, 5, -2], [x, -5, -2], [x, -5, 5], [x, 5, 5]], np.float32)
    return Scene("wall", (MeshPart("wall", verts, np.array([[0, 1, 2], [0, 2, 3]], np.int32), base_color=(0.5, 0.5, 0.5, 1)),))


@pytest.fixture(scope="module")
def detector():
    return make_detector()


def test_tag_image_layout():
    ppb = 5
    img = tag_image(17, pixels_per_bit=ppb)
    n = (TAG_BITS + 2 * QUIET_BITS) * ppb
    assert img.shape == (n, n) and img.dtype == np.uint8
    q = QUIET_BITS * ppb
    assert (img[:q] == 255).all() and (img[-q:] == 255).all() and (img[:, :q] == 255).all() and (img[:, -q:] == 255).all()
    inner = img[q:-q, q:-q]
    assert (inner[:ppb] == 0).all() and (inner[-ppb:] == 0).all() and (inner[:, :ppb] == 0).all() and (inner[:, -ppb:] == 0).all()
    assert set(np.unique(img)) == {0, 255}
    assert not np.array_equal(tag_image(17, ppb), tag_image(18, ppb))
    assert outer_size(0.4) == pytest.approx(0.4 * (TAG_BITS + 2 * QUIET_BITS) / TAG_BITS)


def test_tag_image_rejects_bad_id():
    with pytest.raises(UserError):
        tag_image(587)
    with pytest.raises(UserError):
        tag_image(-1)


@pytest.mark.parametrize("tag_id", [0, 13, 586])
def test_tag_images_decode_as_same_pupil_id(detector, tag_id):
    img = np.pad(tag_image(tag_id, pixels_per_bit=10), 20, constant_values=255)
    dets = detector.detect(img)
    assert [d.tag_id for d in dets] == [tag_id]


CASES = [
    # tag id, size, marker centre, wall normal, camera position, camera yaw (deg)
    (3, 0.4, [3.0, 0.0, 1.5], [-1, 0, 0], [1.0, 0.0, 1.5], 0.0),  # 2 m, head-on
    (101, 0.3, [3.0, 0.3, 1.7], [-1, 0, 0], [1.0, 0.0, 1.5], 4.0),  # 2 m, slightly off-centre
    (42, 0.4, [3.0, 0.2, 1.5], [-1, 0, 0], [1.6, -1.3, 1.4], 40.0),  # ~1.9 m, ~43 deg oblique
]


@pytest.mark.parametrize("tag_id,size,centre,normal,cam,yaw_deg", CASES)
def test_rendered_marker_detected_with_right_id_and_corners(detector, tag_id, size, centre, normal, cam, yaw_deg):
    marker = Marker(tag_id, size, world_from_marker_pose(np.array(centre, float), np.array(normal, float)))
    pose = world_from_cam_pose(np.array(cam, float), np.radians(yaw_deg))
    with Renderer(grey_wall(), markers=[marker]) as r:
        rgb = r.render(pose, depth=False, normal=False).rgb
    gray = np.ascontiguousarray(rgb.mean(axis=2).round().astype(np.uint8))
    dets = detector.detect(gray)
    assert [d.tag_id for d in dets] == [tag_id]
    expected, _ = project(K, pose, marker.corners_world())
    got = np.asarray(dets[0].corners)
    # The detector's corners pair with marker_corners_local by index (no permutation), each
    # within 1 px, and an order-free nearest match agrees.
    err = np.linalg.norm(got - expected, axis=1)
    assert err.max() < 1.0, err
    d = np.linalg.norm(got[:, None] - expected[None], axis=2)
    assert list(d.argmin(axis=1)) == [0, 1, 2, 3]


def test_missing_egl_raises_user_error_with_hint(monkeypatch):
    import moderngl

    def fail(*a, **k):
        raise Exception("libEGL.so.1: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_standalone_context", fail)
    with pytest.raises(UserError) as err:
        Renderer(grey_wall())
    assert "libegl1" in str(err.value) and "make setup" in str(err.value)
    assert "\n" not in str(err.value)
    assert gl_resources.EGL_HINT in str(err.value)


def test_detector_is_destroyed_before_its_tag_families():
    """pupil-apriltags frees the families first and the detector's destructor then writes into
    them (heap corruption); make_detector's detectors release the detector first."""
    det = make_detector()
    real = det.libc
    calls = []

    class Recorder:
        def __getattr__(self, name):
            fn = getattr(real, name)

            def call(*args):
                calls.append(name)
                return fn(*args)

            call.restype = None
            return call

    det.libc = Recorder()
    det.__del__()
    assert calls == ["apriltag_detector_destroy", "tag36h11_destroy"]
    det.__del__()  # a second call (the garbage collector's) does nothing
    assert len(calls) == 2
