"""The camera degradations of markerplace.imaging.degrade, measured against their documented
formulas: exposure and white balance as gains on power-law-decoded light, the noise variance
``shot * x + read**2`` (+ 1/12 of rounding), and the motion-blur streak of a point, whose
spread along the direction is that of a uniform segment of the documented length."""

import numpy as np
import pytest

from markerplace.imaging import degrade


def _flat(value, shape=(64, 64, 3)):
    return np.full(shape, value, np.uint8)


@pytest.mark.parametrize("ev", [-1.0, -0.4, 0.5, 1.0])
def test_exposure_scales_8bit_values_by_two_to_ev_over_gamma(ev):
    rng = np.random.default_rng(0)
    img = rng.integers(20, 110, (48, 64, 3)).astype(np.uint8)  # no clipping at +1 EV (110 * 1.37 < 255)
    out = degrade.exposure(img, ev)
    ratio = out.astype(float).mean() / img.astype(float).mean()
    assert ratio == pytest.approx(2.0 ** (ev / degrade.GAMMA), rel=0.01)


def test_exposure_clips_like_a_sensor():
    out = degrade.exposure(_flat(240), 1.0)
    assert (out == 255).all()
    assert (degrade.exposure(_flat(0), 1.0) == 0).all()
    assert np.array_equal(degrade.exposure(_flat(137), 0.0), _flat(137))


def test_white_balance_gains_red_and_blue_oppositely():
    out = degrade.white_balance(_flat(128), 0.2).astype(float)
    r, g, b = out[..., 0].mean(), out[..., 1].mean(), out[..., 2].mean()
    assert g == 128
    assert r / g == pytest.approx(np.exp(0.2 / degrade.GAMMA), abs=0.01)
    assert b / g == pytest.approx(np.exp(-0.2 / degrade.GAMMA), abs=0.01)


@pytest.mark.parametrize("signal, shot, read", [(30, 0.5, 2.0), (100, 0.5, 2.0), (200, 0.2, 3.0), (100, 0.0, 2.0)])
def test_noise_variance_matches_the_docstring_formula(signal, shot, read):
    img = _flat(signal, (256, 256, 3))
    out = degrade.sensor_noise(img, np.random.default_rng(1), shot, read).astype(float)
    expected = shot * signal + read ** 2 + 1.0 / 12.0  # + uniform rounding error
    assert out.var() == pytest.approx(expected, rel=0.03)
    assert out.mean() == pytest.approx(signal, abs=0.05)
    again = degrade.sensor_noise(img, np.random.default_rng(1), shot, read)
    assert np.array_equal(again, out.astype(np.uint8))


def _moments(weights: np.ndarray, angle: float) -> tuple[float, float, float]:
    """(total, std along ``angle``, std across) of a 2D weight image."""
    w = np.asarray(weights, float)
    ys, xs = np.mgrid[:w.shape[0], :w.shape[1]]
    total = w.sum()
    cx, cy = (w * xs).sum() / total, (w * ys).sum() / total
    u = (xs - cx) * np.cos(angle) + (ys - cy) * np.sin(angle)
    v = -(xs - cx) * np.sin(angle) + (ys - cy) * np.cos(angle)
    return total, float(np.sqrt((w * u ** 2).sum() / total)), float(np.sqrt((w * v ** 2).sum() / total))


@pytest.mark.parametrize("length, angle_deg", [(2.0, 0.0), (5.0, 30.0), (8.0, 90.0), (6.5, 137.0)])
def test_motion_kernel_is_a_segment_of_the_documented_length(length, angle_deg):
    a = np.radians(angle_deg)
    k = degrade.motion_kernel(length, a)
    total, along, across = _moments(k, a)
    assert total == pytest.approx(1.0) and k.shape[0] % 2 == 1
    # a uniform segment of length L has std L / sqrt(12); bilinear splatting adds at most 1/4 px^2
    assert along ** 2 == pytest.approx(length ** 2 / 12, abs=0.26)
    assert across < 0.5


@pytest.mark.parametrize("length, angle_deg", [(4.0, 20.0), (8.0, 75.0)])
def test_motion_blur_of_a_point_image_streaks_by_the_length(length, angle_deg):
    img = np.zeros((41, 41, 3), np.uint8)
    img[20, 20] = 255
    out = degrade.motion_blur(img, length, np.radians(angle_deg))[..., 0]
    total, along, across = _moments(out, np.radians(angle_deg))
    assert total == pytest.approx(255, rel=0.05)
    assert np.sqrt(12) * along == pytest.approx(length, abs=0.5)
    assert across < 0.6
    # the streak's ends: energy only within length / 2 (+ 1 px of splatting) of the point
    ys, xs = np.nonzero(out)
    assert np.hypot(xs - 20, ys - 20).max() <= length / 2 + 1.5
