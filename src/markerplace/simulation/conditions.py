"""Query conditions: test (query) images degraded the way a phone camera in the building would
take them, while the map images stay as the map was rendered (``evaluate --conditions``).

A condition is a registered class (:data:`CONDITIONS`, ``name``, ``summary``, a frozen
``Config`` of documented defaults). Per query image it draws its parameters from its own random
stream (:meth:`Condition.draw`), may change the renderer's light (:meth:`Condition.lighting`,
the ``lighting`` condition: the query is rendered again with another light set-up, a render
costs about 5 ms against about 50 ms for its SIFT on tiny) and filters the rendered RGB
(:meth:`Condition.filter`, the filters of :mod:`markerplace.imaging.degrade`). Depth, and so
the in-view masks and the 3D points of features, are those of the clean render.

The condition is applied in the worker between the render and the feature extraction
(:func:`render_query`), so the tag detector and SIFT/VLAD both see the degraded image, for the
marker-free queries and for the queries re-rendered with a placement's markers alike (same
seed, same draws). Each (test set, condition) is its own image set named :func:`set_name`
(``weighted`` for the clean set, as before conditions existed; ``weighted@blur`` otherwise),
with its own cache keys (:meth:`QueryCondition.key`); the clean sets keep their keys.

Seeds: image ``i`` of test set ``ts`` under condition ``c`` draws from
``numpy.random.default_rng([test seed, crc32(c), crc32(ts), i])`` (the test seed is
``--test-seed``, else ``--seed``): the same image gets the same degradation in every run,
whatever other conditions or sets run.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass, replace
from typing import Sequence

import numpy as np

from markerplace.imaging import degrade
from markerplace.registry import Registry
from markerplace.render.renderer import Lighting
from markerplace.runtime.cache import hash_of

__all__ = ["CLEAN", "CONDITIONS", "Condition", "ImageCondition", "QueryCondition", "condition_names", "degrade_render", "render_query",
           "set_name", "split_set"]

#: The condition that changes nothing (the map's rendering).
CLEAN = "clean"
#: Separator of a test set and its condition in an image set's name (``weighted@blur``).
SEP = "@"

#: The registered query conditions (``evaluate --conditions``).
CONDITIONS = Registry("query condition", "--conditions")


def set_name(test_set: str, condition: str) -> str:
    """Name of the image set of ``test_set`` under ``condition``: the test set's own name when
    clean, ``<test set>@<condition>`` otherwise."""
    return test_set if condition == CLEAN else f"{test_set}{SEP}{condition}"


def split_set(name: str) -> tuple[str, str]:
    """(test set, condition) of an image set's name (inverse of :func:`set_name`)."""
    ts, _, cond = str(name).partition(SEP)
    return ts, cond or CLEAN


def condition_names() -> tuple[str, ...]:
    """Registered condition names, in registration order."""
    return CONDITIONS.names()


def _uniform(rng: np.random.Generator, bounds: Sequence[float]) -> float:
    return float(rng.uniform(float(bounds[0]), float(bounds[1])))


class Condition:
    """A query condition (see the module docstring). ``conf``: its ``Config`` (default
    ``default_conf``)."""

    name = ""
    summary = ""

    def __init__(self, conf=None):
        self.conf = self.default_conf if conf is None else conf

    def draw(self, rng: np.random.Generator, world_from_cam: np.ndarray) -> dict:
        """This image's parameters (plain numbers) from its stream ``rng``."""
        return {}

    def lighting(self, params: dict) -> Lighting | None:
        """The light set-up to render with (None: the map's)."""
        return None

    def filter(self, rgb: np.ndarray, params: dict, rng: np.random.Generator, depth: np.ndarray | None = None,
               K: np.ndarray | None = None) -> np.ndarray:
        """The degraded (H, W, 3) uint8 image (``rng``: the same stream, after :meth:`draw`;
        ``depth``: (H, W) the render's planar depth, metres; ``K``: (3, 3) intrinsics)."""
        return rgb


@dataclass(frozen=True)
class NoSettings:
    """A condition without settings."""


@CONDITIONS.register
class Clean(Condition):
    """Rendered as the map is: no degradation (every result before conditions existed)."""

    name = CLEAN
    summary = "as the map is rendered"
    Config = NoSettings
    default_conf = NoSettings()


@dataclass(frozen=True)
class ExposureConfig:
    """Attributes:
        max_ev: exposure error drawn uniformly in [-max_ev, max_ev] stops per image (a phone's
            auto-exposure between rooms and against windows is off by up to about one stop).
    """

    max_ev: float = 1.0


@CONDITIONS.register
class Exposure(Condition):
    """Global exposure error: linear light times 2**ev, 8-bit values times 2**(ev/2.2), clipped
    (:func:`markerplace.imaging.degrade.exposure`)."""

    name = "exposure"
    summary = "+-1 EV gain with clipping"
    Config = ExposureConfig
    default_conf = ExposureConfig()

    def draw(self, rng, world_from_cam):
        return {"ev": _uniform(rng, (-self.conf.max_ev, self.conf.max_ev))}

    def filter(self, rgb, params, rng, depth=None, K=None):
        return degrade.exposure(rgb, params["ev"])


@dataclass(frozen=True)
class WhiteBalanceConfig:
    """Attributes:
        max_shift: log red/green gain drawn uniformly in [-max_shift, max_shift] (blue gets the
            opposite); 0.25 is roughly a +-1200 K white-balance error around 5000 K.
    """

    max_shift: float = 0.25


@CONDITIONS.register
class WhiteBalance(Condition):
    """Colour-temperature error: per-channel linear gains exp(s), 1, exp(-s)
    (:func:`markerplace.imaging.degrade.white_balance`)."""

    name = "white_balance"
    summary = "per-channel gains, a colour temperature shift"
    Config = WhiteBalanceConfig
    default_conf = WhiteBalanceConfig()

    def draw(self, rng, world_from_cam):
        return {"shift": _uniform(rng, (-self.conf.max_shift, self.conf.max_shift))}

    def filter(self, rgb, params, rng, depth=None, K=None):
        return degrade.white_balance(rgb, params["shift"])


@dataclass(frozen=True)
class LightingConfig:
    """Ranges (drawn uniformly per image) of the query's light set-up
    (:class:`~markerplace.render.renderer.Lighting`; the map's: ambient 0.6, headlight 0.4).

    Attributes:
        ambient: ambient intensity.
        headlight: light from the camera's direction (a phone has none; the map's 0.4 is a
            shading convention).
        sun: directional light (windows, ceiling lights on one side).
        sun_elevation_deg: its elevation above the horizon, degrees; azimuth uniform.
        dim: share of the light lost beyond a vertical plane (a zone with its lights off).
        cut_distance: metres from the camera to that plane, along a uniform horizontal direction.
    """

    ambient: tuple = (0.3, 0.6)
    headlight: tuple = (0.0, 0.2)
    sun: tuple = (0.2, 0.5)
    sun_elevation_deg: tuple = (20.0, 70.0)
    dim: tuple = (0.3, 0.7)
    cut_distance: tuple = (0.5, 3.0)


@CONDITIONS.register
class LightingChange(Condition):
    """Another light set-up, rendered (not a filter): the relit shader of
    :mod:`markerplace.render.shaders` with parameters drawn from :class:`LightingConfig`."""

    name = "lighting"
    summary = "re-rendered with other lights: dimmer ambient, a directional light, a zone dimmed"
    Config = LightingConfig
    default_conf = LightingConfig()

    def draw(self, rng, world_from_cam):
        c = self.conf
        az, el = rng.uniform(0.0, 2 * np.pi), np.radians(_uniform(rng, c.sun_elevation_deg))
        cut_az, dist = rng.uniform(0.0, 2 * np.pi), _uniform(rng, c.cut_distance)
        normal = np.array([np.cos(cut_az), np.sin(cut_az)])
        point = np.asarray(world_from_cam, float)[:2, 3] + dist * normal
        return {"ambient": _uniform(rng, c.ambient), "headlight": _uniform(rng, c.headlight),
                "sun": _uniform(rng, c.sun),
                "sun_dir": [float(np.cos(el) * np.cos(az)), float(np.cos(el) * np.sin(az)), float(np.sin(el))],
                "dim": _uniform(rng, c.dim), "cut_point": point.tolist(), "cut_normal": normal.tolist()}

    def lighting(self, params):
        return Lighting(params["ambient"], params["headlight"], params["sun"], tuple(params["sun_dir"]),
                        tuple(params["cut_point"]), tuple(params["cut_normal"]), params["dim"])


@dataclass(frozen=True)
class NoiseConfig:
    """Attributes:
        shot: range of the shot-noise gain, DN per photo-electron (variance = shot * signal),
            drawn uniformly per image (a phone indoors, ISO a few hundred to about 1600).
        read: read-noise standard deviation, DN.
    """

    shot: tuple = (0.2, 0.8)
    read: float = 2.0


@CONDITIONS.register
class Noise(Condition):
    """Sensor noise: variance shot * x + read**2 at 8-bit signal x
    (:func:`markerplace.imaging.degrade.sensor_noise`)."""

    name = "noise"
    summary = "shot + read noise"
    Config = NoiseConfig
    default_conf = NoiseConfig()

    def draw(self, rng, world_from_cam):
        return {"shot": _uniform(rng, self.conf.shot), "read": float(self.conf.read)}

    def filter(self, rgb, params, rng, depth=None, K=None):
        return degrade.sensor_noise(rgb, rng, params["shot"], params["read"])


@dataclass(frozen=True)
class BlurConfig:
    """Attributes:
        length: range of the motion-blur length, pixels (hand shake and walking at 1/30 s on a
            600 px wide image), drawn uniformly; the direction is uniform.
        defocus: range of the Gaussian defocus sigma, pixels.
    """

    length: tuple = (2.0, 8.0)
    defocus: tuple = (0.0, 0.7)


@CONDITIONS.register
class Blur(Condition):
    """Linear motion blur of random direction, then slight defocus
    (:func:`markerplace.imaging.degrade.motion_blur`)."""

    name = "blur"
    summary = "2-8 px motion blur, slight defocus"
    Config = BlurConfig
    default_conf = BlurConfig()

    def draw(self, rng, world_from_cam):
        return {"length": _uniform(rng, self.conf.length), "angle": float(rng.uniform(0.0, np.pi)),
                "defocus": _uniform(rng, self.conf.defocus)}

    def filter(self, rgb, params, rng, depth=None, K=None):
        return degrade.motion_blur(rgb, params["length"], params["angle"], params["defocus"])


@dataclass(frozen=True)
class OccludersConfig:
    """People in front of the camera (:func:`markerplace.imaging.degrade.occlude`).

    Attributes:
        people: range of the number of people per image (inclusive, uniform).
        distance: range of each one's distance from the camera, metres (uniform).
        width, height: a person's size, metres (an upright ellipse).
        eye: camera height above the floor, metres (the queries are level cameras).
        colour: range of each clothing colour channel, 8-bit (dark to mid: 20..120).
    """

    people: tuple = (1, 2)
    distance: tuple = (1.0, 4.0)
    width: float = 0.5
    height: float = 1.75
    eye: float = 1.5
    colour: tuple = (20.0, 120.0)


@CONDITIONS.register
class Occluders(Condition):
    """People-sized occluders pasted in front of the scene where the depth is beyond them."""

    name = "occluders"
    summary = "1-2 people 1-4 m in front of the camera"
    Config = OccludersConfig
    default_conf = OccludersConfig()

    def draw(self, rng, world_from_cam):
        c = self.conf
        n = int(rng.integers(int(c.people[0]), int(c.people[1]) + 1))
        return {"people": [{"distance": _uniform(rng, c.distance), "u": float(rng.uniform()),
                            "colour": rng.uniform(c.colour[0], c.colour[1], 3).tolist(),
                            "folds": rng.uniform(0.0, 1.0, (4, 8)).tolist()} for _ in range(n)]}

    def filter(self, rgb, params, rng, depth=None, K=None):
        c = self.conf
        return degrade.occlude(rgb, depth, K, params["people"], c.width, c.height, c.eye)


@dataclass(frozen=True)
class ImageCondition:
    """What a worker needs to degrade one query image: the condition's name, its settings and
    the image's seed (a sequence for ``numpy.random.default_rng``)."""

    name: str
    conf: object
    seed: tuple


@dataclass(frozen=True)
class QueryCondition:
    """One condition applied to one test set.

    Attributes:
        name: a registered condition (not ``clean``: a clean set has no QueryCondition).
        test_set: the test set's name (part of every image's seed).
        seed: the test seed (``EvaluateConfig.pose_seed``).
        conf: the condition's settings (default: its ``default_conf``).
    """

    name: str
    test_set: str
    seed: int
    conf: object = None

    @property
    def settings(self):
        return CONDITIONS.lookup(self.name).default_conf if self.conf is None else self.conf

    def key(self) -> str:
        """Part of the cache key of the set's images and predictions."""
        return hash_of("condition-v1", self.name, type(self.settings).__name__, self.settings, self.test_set,
                       int(self.seed))

    def image(self, index: int) -> ImageCondition:
        """The condition of image ``index`` of the set."""
        seed = (int(self.seed), zlib.crc32(self.name.encode()), zlib.crc32(self.test_set.encode()), int(index))
        return ImageCondition(self.name, self.settings, seed)


def degrade_render(world_from_cam: np.ndarray, cond: ImageCondition, render, K: np.ndarray | None = None) -> tuple:
    """(render result, drawn parameters) of the view at (4, 4) ``world_from_cam`` under
    ``cond``: ``render(lighting)`` makes the :class:`~markerplace.render.renderer.RenderResult`
    (with depth) with that light set-up (None: the map's), whose RGB is then filtered (``K``:
    the (3, 3) intrinsics, for conditions sized in metres)."""
    part = CONDITIONS.lookup(cond.name)(cond.conf)
    rng = np.random.default_rng(list(cond.seed))
    params = part.draw(rng, world_from_cam)
    light = part.lighting(params)
    res = render(light)
    return replace(res, rgb=part.filter(res.rgb, params, rng, res.depth, K)), params


def render_query(engine, world_from_cam: np.ndarray, markers, cond: ImageCondition | None):
    """Render ``world_from_cam`` with ``markers`` on a worker's
    :class:`~markerplace.imaging.engine.ImagingEngine`, under ``cond`` (None: clean).
    Returns the :class:`~markerplace.render.renderer.RenderResult` with the degraded RGB."""
    if cond is None:
        return engine.render(world_from_cam, markers)

    def render(light):
        engine.renderer.set_lighting(light)
        try:
            return engine.render(world_from_cam, markers)
        finally:
            engine.renderer.set_lighting(None)

    return degrade_render(world_from_cam, cond, render, engine.K)[0]
