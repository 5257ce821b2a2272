"""Simulated RGB-D scan of a built-in scene: a walk through every room, a depth-sensor noise model,
TSDF fusion. The result looks like a real scan: holes, noise, vertex colours, no texture.

Walk
----
Each room (``scene.rooms``, xy bounds and ``floor_z``) gets a lattice of positions ``spacing``
apart (default 0.8 m), ``wall_margin`` inside its wall centre lines, visited in serpentine order;
a position that is not over the room's floor (furniture below) or closer than ``clearance`` to
anything at knee, waist or eye height is nudged by a third of the spacing, or skipped. Doorways
are found geometrically (horizontal rays across the wall shared by two rooms at 1 m above the
floor) and crossed: positions 0.6 m before, in and 0.6 m after each opening. At every position
the camera is 1.2-1.6 m above the room's floor and sweeps ``yaws`` headings at each of the
``pitches_deg`` (-45, 0, +30 deg: floor, walls, ceiling), with a few degrees of hand-held jitter
in yaw, pitch and roll. Everything random comes from ``seed``.

Sensor
------
A Kinect-like camera (320x240, fx = fy = 262.5 px: 63 x 49 deg, half the Kinect v1 resolution)
rendered by :class:`markerplace.render.renderer.Renderer` (planar depth, world normals). Noise
model, per frame, from these sources:

* axial noise (Nguyen, Izadi, Lovell, "Modeling Kinect Sensor Noise for Improved 3D
  Reconstruction and Tracking", 3DIMPVT 2012, eq. 6): sigma_z(z, theta) = 0.0012 + 0.0019
  (z - 0.4)^2 + 0.0001 / sqrt(z) * theta^2 / (pi/2 - theta)^2 metres, z in metres, theta the
  angle between the surface normal and the viewing ray (clipped at 80 deg);
* lateral noise (same paper, eq. 5): sigma_L = 0.8 + 0.035 theta / (pi/2 - theta) pixels at the
  Kinect's 585 px focal length, scaled to ours; each pixel takes the depth of a neighbour offset
  by the rounded Gaussian jitter;
* depth quantization of a disparity sensor (Khoshelham & Elberink, Sensors 2012): inverse depth
  in steps of 2.85e-3 per metre (2.9 mm at 1 m, 2.6 cm at 3 m), then whole millimetres;
* dropouts: grazing angles (probability rising linearly from 0 at 65 deg to 1 at 78 deg),
  depth discontinuities (a jump over 5 % of the depth to a neighbour, dilated by one pixel),
  random speckle (small discs), nothing nearer than 0.4 m or beyond 5 m, and no reading on glass
  (parts with ``MeshPart.transparent`` that are the first surface along the ray, found with a
  second renderer that draws only the transparent parts, opaque; the main renderer's depth is
  what lies behind glass, which ``glass_dropout=False`` keeps).

The colour image is the renderer's, registered to the depth. Frames can be kept on disk in the
markerplace layout (:mod:`markerplace.scan.frames`), so ``markerplace fuse`` reproduces the mesh.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..geometry import Intrinsics, rotation_from_yaw
from ..scene.types import Room, Scene
from .fuse import FuseConfig, TSDFFusion

log = logging.getLogger(__name__)

DEPTH_SCALE = 1000.0
"""Simulated depth images are stored in millimetres."""


@dataclass(frozen=True)
class WalkConfig:
    """Where the simulated scanner goes.

    Attributes:
        spacing: lattice spacing of positions in each room, metres (default 0.8).
        wall_margin: lattice inset from the room's wall centre lines, metres (default 0.4).
        height_min, height_max: camera height above the room's floor, metres (default 1.2-1.6;
            drawn per position).
        yaws: headings per pitch at each position (default 8, 45 deg apart; random start).
        pitches_deg: camera pitches, degrees, positive up (default -45, 0, +30).
        jitter_deg: standard deviation of hand-held yaw/pitch/roll jitter, degrees (default 2).
        clearance: minimum distance to any surface at 0.5 m, 1.0 m and camera height, metres
            (default 0.3).
        doorways: also cross the openings between rooms (default True).
    """

    spacing: float = 0.8
    wall_margin: float = 0.4
    height_min: float = 1.2
    height_max: float = 1.6
    yaws: int = 8
    pitches_deg: tuple[float, ...] = (-45.0, 0.0, 30.0)
    jitter_deg: float = 2.0
    clearance: float = 0.3
    doorways: bool = True


@dataclass(frozen=True)
class DepthNoiseConfig:
    """Depth sensor model (see the module docstring for the sources).

    Attributes:
        min_range, max_range: readings outside [min, max] metres are dropped (default 0.4, 5.0).
        axial_a, axial_b, axial_z0, axial_angle: Nguyen et al. 2012 axial noise coefficients
            sigma = a + b (z - z0)^2 + angle / sqrt(z) * theta^2 / (pi/2 - theta)^2 (metres).
        lateral_px, lateral_angle, lateral_focal: Nguyen et al. lateral noise sigma_L =
            lateral_px + lateral_angle * theta / (pi/2 - theta) pixels at focal length
            ``lateral_focal`` px (scaled by fx / lateral_focal); 0 turns jitter off.
        disparity_step: inverse-depth quantization step, 1/metres (default 2.85e-3; 0 = off).
        grazing_start_deg, grazing_end_deg: dropout probability rises linearly from 0 to 1
            between these incidence angles (default 65, 78).
        edge_rel: a depth jump to a 4-neighbour above this fraction of the depth is a
            discontinuity (default 0.05); both sides and ``edge_dilate_px`` pixels around drop.
        speckle_rate, speckle_radius_px: seeds per pixel and radius of random dropout discs
            (default 1e-3, 2 px: about 1.3 % of the pixels).
        glass_dropout: no reading where a transparent part is the first surface (default
            True); False keeps the renderer's depth of what lies behind the glass.
    """

    min_range: float = 0.4
    max_range: float = 5.0
    axial_a: float = 0.0012
    axial_b: float = 0.0019
    axial_z0: float = 0.4
    axial_angle: float = 0.0001
    lateral_px: float = 0.8
    lateral_angle: float = 0.035
    lateral_focal: float = 585.0
    disparity_step: float = 2.85e-3
    grazing_start_deg: float = 65.0
    grazing_end_deg: float = 78.0
    edge_rel: float = 0.05
    edge_dilate_px: int = 1
    speckle_rate: float = 1e-3
    speckle_radius_px: int = 2
    glass_dropout: bool = True


@dataclass(frozen=True)
class ScanConfig:
    """A simulated scan: camera, walk, noise and fusion.

    Attributes:
        width, height, fx, fy: rendered image size and focal lengths, pixels (default 320x240,
            262.5: a Kinect v1 at half resolution); the principal point is the image centre.
        walk: where the scanner goes.
        noise: the depth sensor model.
        fuse: TSDF settings (default 0.04 m voxels, truncation 2.5 voxels = 10 cm, depth up to
            4 m: about 0.6 million faces for the 112 m^2 office). A truncation wider than the
            0.1 m walls lets the two sides of a wall pull each other's surface off (4x gave
            10 % of the vertices more than 4 cm off; 2.5x gives 1.3 %).
    """

    width: int = 320
    height: int = 240
    fx: float = 262.5
    fy: float = 262.5
    walk: WalkConfig = WalkConfig()
    noise: DepthNoiseConfig = DepthNoiseConfig()
    fuse: FuseConfig = FuseConfig(voxel=0.04, trunc_voxels=2.5)

    @property
    def intrinsics(self) -> Intrinsics:
        """Camera model; pixel centres at integer coordinates, principal point at the centre."""
        return Intrinsics(self.width, self.height, self.fx, self.fy, (self.width - 1) / 2.0, (self.height - 1) / 2.0)


@dataclass(frozen=True)
class ScanResult:
    """Outcome of :func:`simulate_scan`.

    Attributes:
        mesh: legacy ``open3d.geometry.TriangleMesh`` (world frame, vertex colours, normals).
        world_from_cam: (N, 4, 4) poses of the frames, in walk order.
        positions: (P, 3) walk positions, metres.
        doorways: (D, 3) doorway centres found, metres.
        valid_fraction: mean fraction of pixels with a depth reading after the noise model.
        seconds: wall-clock time of the whole scan.
    """

    mesh: object
    world_from_cam: np.ndarray
    positions: np.ndarray
    doorways: np.ndarray
    valid_fraction: float
    seconds: float
    stats: dict = field(default_factory=dict)


def _rng(seed: int, *stream: int) -> np.random.Generator:
    """A generator for (seed, stream...): independent streams, any integer seed (negative too)."""
    return np.random.default_rng([int(seed) % (1 << 63), *[int(s) for s in stream]])


# ---------------------------------------------------------------------------------------- walk
def world_from_cam_ypr(position: np.ndarray, yaw: float, pitch: float, roll: float = 0.0) -> np.ndarray:
    """(4, 4) ``world_from_cam`` at ``position`` looking along yaw (radians, CCW from +x), pitched
    up by ``pitch`` (radians, positive up) and rolled by ``roll`` about the optical axis."""
    cp, sp = math.cos(pitch), math.sin(pitch)
    # level camera, then a rotation about the camera x axis: z -> cos p * forward + sin p * up (up = -y)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    cr, sr = math.cos(roll), math.sin(roll)
    Rz = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = rotation_from_yaw(yaw) @ Rx @ Rz
    T[:3, 3] = position
    return T


def _feasible(caster, p: np.ndarray, floor_z: float, clearance: float) -> bool:
    """Camera position ``p`` is over the floor at ``floor_z`` and ``clearance`` from everything."""
    t, _ = caster.first_hits(p[None], np.array([[0.0, 0.0, -1.0]]))
    if not abs(t[0] - (p[2] - floor_z)) < 0.05:
        return False
    angles = np.linspace(0.0, 2 * np.pi, 16, endpoint=False)
    dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)], axis=1)
    heights = (floor_z + 0.5, floor_z + 1.0, p[2])
    origins = np.concatenate([np.tile([p[0], p[1], h], (len(dirs), 1)) for h in heights])
    t, _ = caster.first_hits(origins, np.tile(dirs, (len(heights), 1)), max_t=clearance)
    return bool(np.all(np.isinf(t)))


def _room_lattice(room: Room, cfg: WalkConfig) -> np.ndarray:
    """(K, 2) serpentine lattice of xy positions inside ``room``."""
    x0, y0, x1, y1 = room.bounds
    axes = []
    for lo, hi in ((x0, x1), (y0, y1)):
        lo, hi = lo + cfg.wall_margin, hi - cfg.wall_margin
        if hi <= lo:
            axes.append(np.array([(lo + hi) / 2.0]))
        else:
            n = int(math.floor((hi - lo) / cfg.spacing + 1e-9)) + 1
            span = (n - 1) * cfg.spacing
            axes.append((lo + hi) / 2.0 - span / 2.0 + cfg.spacing * np.arange(n))
    xs, ys = axes
    rows = [np.stack([xs if j % 2 == 0 else xs[::-1], np.full(len(xs), y)], axis=1) for j, y in enumerate(ys)]
    return np.concatenate(rows)


def find_doorways(scene: Scene, caster, step: float = 0.05, min_width: float = 0.5) -> list[dict]:
    """Openings in the walls shared by two rooms of ``scene.rooms``.

    Samples the shared wall line every ``step`` metres, 1 m above the higher floor, with a
    horizontal ray from 0.35 m on one side to 0.35 m on the other; runs of free rays at least
    ``min_width`` wide are doorways.

    Returns:
        one dict per doorway: ``a``, ``b`` (room indices), ``centre`` (3,) on the wall line at
        the lower floor's height, ``normal`` (3,) unit, pointing from room a into room b.
    """
    rooms = scene.rooms
    out = []
    for i in range(len(rooms)):
        for j in range(i + 1, len(rooms)):
            a, b = rooms[i], rooms[j]
            if abs(a.floor_z - b.floor_z) > 0.3:
                continue
            ax0, ay0, ax1, ay1 = a.bounds
            bx0, by0, bx1, by1 = b.bounds
            lines = []
            for ea, eb, sign in ((ax1, bx0, 1.0), (ax0, bx1, -1.0)):
                if abs(ea - eb) < 1e-3:
                    lo, hi = max(ay0, by0), min(ay1, by1)
                    if hi - lo >= min_width:
                        lines.append(("x", ea, lo, hi, sign))
            for ea, eb, sign in ((ay1, by0, 1.0), (ay0, by1, -1.0)):
                if abs(ea - eb) < 1e-3:
                    lo, hi = max(ax0, bx0), min(ax1, bx1)
                    if hi - lo >= min_width:
                        lines.append(("y", ea, lo, hi, sign))
            z = max(a.floor_z, b.floor_z) + 1.0
            for axis, c, lo, hi, sign in lines:
                s = np.arange(lo + step / 2, hi, step)
                n = np.array([sign, 0.0, 0.0]) if axis == "x" else np.array([0.0, sign, 0.0])
                pts = np.stack([np.full_like(s, c), s, np.full_like(s, z)], 1) if axis == "x" else \
                    np.stack([s, np.full_like(s, c), np.full_like(s, z)], 1)
                t, _ = caster.first_hits(pts - 0.35 * n, np.tile(n, (len(s), 1)), max_t=0.7)
                free = np.isinf(t)
                k = 0
                while k < len(free):
                    if not free[k]:
                        k += 1
                        continue
                    e = k
                    while e < len(free) and free[e]:
                        e += 1
                    if (e - k) * step >= min_width:
                        mid = 0.5 * (s[k] + s[e - 1])
                        centre = np.array([c, mid, min(a.floor_z, b.floor_z)]) if axis == "x" else \
                            np.array([mid, c, min(a.floor_z, b.floor_z)])
                        out.append({"a": i, "b": j, "centre": centre, "normal": n})
                    k = e
    return out


def plan_walk(scene: Scene, cfg: WalkConfig = WalkConfig(), seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Camera poses of the scanning walk.

    Args:
        scene: a scene with ``rooms`` (the built-ins).
        cfg: walk settings.
        seed: seeds heights, yaw offsets and jitter.

    Returns:
        world_from_cam (N, 4, 4), positions (P, 3) and doorway centres (D, 3), metres.

    Raises:
        UserError: the scene has no rooms, or no feasible position at all.
    """
    from ..scene.raycast import RayCaster

    if not scene.rooms:
        raise UserError(f"scene {scene.name!r} has no rooms: a simulated scan needs a built-in scene")
    if cfg.yaws < 1 or not cfg.pitches_deg or cfg.spacing <= 0:
        raise ValueError("walk needs yaws >= 1, at least one pitch and a positive spacing")
    caster = RayCaster(*scene.geometry())
    rng = _rng(seed, 1)
    doorways = find_doorways(scene, caster) if cfg.doorways else []
    stops: list[tuple[np.ndarray, float]] = []  # (xy, floor_z)
    nudges = cfg.spacing / 3.0 * np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1]], dtype=float)
    skipped = 0
    for ri, room in enumerate(scene.rooms):
        kept = 0
        for xy in _room_lattice(room, cfg):
            h = rng.uniform(cfg.height_min, cfg.height_max)
            for d in nudges:
                p = np.array([xy[0] + d[0], xy[1] + d[1], room.floor_z + h])
                if _feasible(caster, p, room.floor_z, cfg.clearance):
                    stops.append((p, room.floor_z))
                    kept += 1
                    break
            else:
                skipped += 1
        log.debug("walk: room %s: %d positions", room.name, kept)
        for dw in doorways:
            if dw["a"] != ri:
                continue
            for off in (-0.6, 0.0, 0.6):
                h = rng.uniform(cfg.height_min, cfg.height_max)
                p = dw["centre"] + off * dw["normal"] + np.array([0.0, 0.0, h])
                fz = scene.rooms[dw["a"] if off < 0 else dw["b"]].floor_z if off else dw["centre"][2]
                p[2] = fz + h
                if _feasible(caster, p, fz, min(cfg.clearance, 0.25)):
                    stops.append((p, fz))
    if not stops:
        raise UserError(f"scene {scene.name!r}: no free position for the scanning walk")
    jit = math.radians(cfg.jitter_deg)
    poses = []
    for p, _ in stops:
        yaw0 = rng.uniform(0.0, 2 * math.pi / cfg.yaws)
        for pitch in cfg.pitches_deg:
            for k in range(cfg.yaws):
                yaw = yaw0 + 2 * math.pi * k / cfg.yaws + rng.normal(0.0, jit)
                poses.append(world_from_cam_ypr(p, yaw, math.radians(pitch) + rng.normal(0.0, jit), rng.normal(0.0, jit)))
    log.info("walk: %d positions in %d rooms (%d lattice points skipped: furniture or too close), %d doorways, %d frames",
             len(stops), len(scene.rooms), skipped, len(doorways), len(poses))
    return np.array(poses), np.array([p for p, _ in stops]), np.array([d["centre"] for d in doorways]).reshape(-1, 3)


# -------------------------------------------------------------------------------------- noise
def _camera_rays(intrinsics: Intrinsics) -> np.ndarray:
    """(H, W, 3) unit viewing rays in the camera frame."""
    v, u = np.mgrid[0 : intrinsics.height, 0 : intrinsics.width].astype(np.float64)
    r = np.stack([(u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, np.ones_like(u)], axis=2)
    return r / np.linalg.norm(r, axis=2, keepdims=True)


def _disc(radius: int) -> np.ndarray:
    y, x = np.mgrid[-radius : radius + 1, -radius : radius + 1]
    return (x * x + y * y <= radius * radius + 0.5).astype(np.uint8)


def noisy_depth(depth: np.ndarray, normal: np.ndarray, intrinsics: Intrinsics, world_from_cam: np.ndarray,
                rng: np.random.Generator, cfg: DepthNoiseConfig = DepthNoiseConfig(),
                glass: np.ndarray | None = None, rays: np.ndarray | None = None) -> np.ndarray:
    """Apply the sensor model to a rendered planar depth image.

    Args:
        depth: (H, W) float planar depth, metres, 0 = nothing hit.
        normal: (H, W, 3) world-frame unit normals (any sign; 0 where nothing was hit).
        intrinsics: the camera model of the images.
        world_from_cam: (4, 4) pose of the frame.
        rng: random generator (the only source of randomness).
        cfg: noise settings.
        glass: (H, W) bool, pixels whose first surface is glass (no reading), or None.
        rays: (H, W, 3) camera-frame unit rays of ``intrinsics`` (computed when None).

    Returns:
        (H, W) float32 planar depth, metres, 0 = no reading.
    """
    import cv2

    H, W = depth.shape
    z = np.asarray(depth, dtype=np.float64)
    valid = z > 0
    if glass is not None:
        valid &= ~glass
    if rays is None:
        rays = _camera_rays(intrinsics)
    d_world = rays @ np.asarray(world_from_cam, dtype=np.float64)[:3, :3].T
    cos_t = np.abs(np.einsum("hwc,hwc->hw", d_world, np.asarray(normal, dtype=np.float64)))
    theta = np.arccos(np.clip(cos_t, 0.0, 1.0))
    theta_c = np.minimum(theta, math.radians(80.0))
    # dropouts: grazing incidence, discontinuities, speckle, range
    g0, g1 = math.radians(cfg.grazing_start_deg), math.radians(cfg.grazing_end_deg)
    p_graze = np.clip((theta - g0) / max(g1 - g0, 1e-9), 0.0, 1.0)
    drop = rng.random((H, W)) < p_graze
    edge = np.zeros((H, W), dtype=bool)
    both = valid[:, 1:] & valid[:, :-1]
    jump = both & (np.abs(z[:, 1:] - z[:, :-1]) > cfg.edge_rel * np.minimum(z[:, 1:], z[:, :-1]))
    edge[:, 1:] |= jump
    edge[:, :-1] |= jump
    both = valid[1:, :] & valid[:-1, :]
    jump = both & (np.abs(z[1:, :] - z[:-1, :]) > cfg.edge_rel * np.minimum(z[1:, :], z[:-1, :]))
    edge[1:, :] |= jump
    edge[:-1, :] |= jump
    if cfg.edge_dilate_px > 0 and edge.any():
        edge = cv2.dilate(edge.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=int(cfg.edge_dilate_px)) > 0
    drop |= edge
    if cfg.speckle_rate > 0:
        seeds = (rng.random((H, W)) < cfg.speckle_rate).astype(np.uint8)
        drop |= cv2.dilate(seeds, _disc(int(cfg.speckle_radius_px))) > 0
    valid &= ~drop & (z >= cfg.min_range) & (z <= cfg.max_range)
    # lateral noise: each pixel reads a jittered neighbour
    if cfg.lateral_px > 0:
        sigma = (cfg.lateral_px + cfg.lateral_angle * theta_c / (math.pi / 2 - theta_c)) * (intrinsics.fx / cfg.lateral_focal)
        du = np.clip(np.rint(rng.standard_normal((H, W)) * sigma), -2, 2).astype(np.int64)
        dv = np.clip(np.rint(rng.standard_normal((H, W)) * sigma), -2, 2).astype(np.int64)
        vv, uu = np.mgrid[0:H, 0:W]
        sv, su = np.clip(vv + dv, 0, H - 1), np.clip(uu + du, 0, W - 1)
        z, valid, theta_c = z[sv, su], valid[sv, su], theta_c[sv, su]
    # axial noise (Nguyen et al. 2012)
    zc = np.where(valid, z, 1.0)
    sigma_z = (cfg.axial_a + cfg.axial_b * (zc - cfg.axial_z0) ** 2
               + cfg.axial_angle / np.sqrt(zc) * theta_c**2 / (math.pi / 2 - theta_c) ** 2)
    zn = zc + rng.standard_normal((H, W)) * sigma_z
    if cfg.disparity_step > 0:
        q = np.rint(1.0 / (np.maximum(zn, 1e-3) * cfg.disparity_step))
        zn = 1.0 / (np.maximum(q, 1.0) * cfg.disparity_step)
    valid &= (zn >= cfg.min_range) & (zn <= cfg.max_range)
    return np.where(valid, zn, 0.0).astype(np.float32)


def to_depth_png(depth_m: np.ndarray, scale: float = DEPTH_SCALE) -> np.ndarray:
    """(H, W) metres -> uint16 in ``scale`` units per metre (0 stays 0; beyond 65535 units -> 0)."""
    d = np.rint(np.asarray(depth_m, dtype=np.float64) * scale)
    return np.where((d > 0) & (d <= 65535), d, 0).astype(np.uint16)


def _glass_scene(scene: Scene) -> Scene | None:
    """The transparent parts alone, made opaque so they write depth (None when there are none)."""
    parts = tuple(dataclasses.replace(p, transparent=False) for p in scene.parts if p.transparent and len(p.faces))
    if not parts:
        return None
    return Scene(name=f"{scene.name}/glass", parts=parts, rooms=scene.rooms, floor_z=scene.floor_z, source=scene.source)


# --------------------------------------------------------------------------------------- scan
class FrameSimulator:
    """Renders noisy RGB-D frames of one scene (one GL context; two when the scene has glass).

    Use as a context manager or call :meth:`close`.

    Args:
        scene: the scene (world z up, metres).
        config: camera and noise settings (``config.walk`` and ``config.fuse`` are not used).
    """

    def __init__(self, scene: Scene, config: ScanConfig = ScanConfig()):
        from ..render.renderer import Renderer

        self.config = config
        self.intrinsics = config.intrinsics
        self._rays = _camera_rays(self.intrinsics)
        glass_scene = _glass_scene(scene) if config.noise.glass_dropout else None
        if glass_scene is not None:
            log.info("scan: %d transparent parts give no depth where they are the first surface", len(glass_scene.parts))
        self._renderer = Renderer(scene, self.intrinsics)
        self._glass = None
        try:
            self._glass = Renderer(glass_scene, self.intrinsics) if glass_scene is not None else None
        except Exception:
            self._renderer.close()
            raise

    def frame(self, world_from_cam: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """One frame at a (4, 4) ``world_from_cam``.

        Returns:
            rgb (H, W, 3) uint8 and depth (H, W) uint16 millimetres (0 = no reading), planar.
        """
        # two GL contexts live in this process when there is glass: make each current before use
        # (a Renderer draws into whichever context is current)
        with self._renderer.ctx:
            res = self._renderer.render(world_from_cam)
        glass = None
        if self._glass is not None:
            # the renderer's depth is what lies behind glass; glass is the first surface where
            # the glass-only depth is nearer than that (or nothing lies behind it)
            with self._glass.ctx:
                dg = self._glass.render(world_from_cam, rgb=False, normal=False).depth
            glass = (dg > 0) & ((res.depth == 0) | (dg < res.depth + 1e-3))
        d = noisy_depth(res.depth, res.normal, self.intrinsics, world_from_cam, rng, self.config.noise, glass, self._rays)
        return res.rgb, to_depth_png(d, DEPTH_SCALE)

    def close(self) -> None:
        """Release the GL contexts."""
        self._renderer.close()
        if self._glass is not None:
            self._glass.close()

    def __enter__(self) -> "FrameSimulator":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def simulate_scan(scene: Scene, config: ScanConfig = ScanConfig(), seed: int = 0,
                  keep_frames: str | Path | None = None, progress: bool = True) -> ScanResult:
    """Walk through ``scene``, render noisy RGB-D frames and fuse them into a mesh.

    Args:
        scene: a scene with rooms (built-in).
        config: camera, walk, noise and fusion settings.
        seed: seeds the walk and every frame's noise (frame i uses its own stream), so the
            result does not depend on anything else.
        keep_frames: folder to write the frames to in the markerplace layout, or None.
        progress: show a progress bar.

    Returns:
        :class:`ScanResult`.
    """
    from tqdm import tqdm

    from .frames import FrameWriter

    t0 = time.perf_counter()
    config.fuse.validate()
    intr = config.intrinsics
    poses, positions, doorways = plan_walk(scene, config.walk, seed)
    fusion = TSDFFusion(intr, config.fuse)
    writer = FrameWriter(keep_frames, intr, DEPTH_SCALE) if keep_frames is not None else None
    valid_sum = 0.0
    try:
        with FrameSimulator(scene, config) as sim:
            for i, T in enumerate(tqdm(poses, desc="scan", unit="frame", disable=not progress, leave=False)):
                rgb, d16 = sim.frame(T, _rng(seed, 2, i))
                valid_sum += float(np.count_nonzero(d16)) / d16.size
                fusion.integrate(rgb, d16, DEPTH_SCALE, T)
                if writer is not None:
                    writer.write(f"{i:06d}", rgb, d16, T)
    finally:
        if writer is not None:
            writer.close()
    mesh = fusion.extract_mesh()
    seconds = time.perf_counter() - t0
    stats = {"frames": len(poses), "positions": len(positions), "doorways": len(doorways),
             "faces": len(mesh.triangles), "vertices": len(mesh.vertices), "seconds": round(seconds, 2)}
    log.info("scan: %d frames fused at %.3f m voxels in %.1f s: %d vertices, %d faces; %.0f %% of pixels had depth",
             len(poses), config.fuse.voxel, seconds, len(mesh.vertices), len(mesh.triangles),
             100.0 * valid_sum / max(len(poses), 1))
    if len(mesh.triangles) == 0:
        raise UserError(f"scene {scene.name!r}: the simulated scan produced no surface")
    return ScanResult(mesh, poses, positions, doorways, valid_sum / max(len(poses), 1), seconds, stats)


def distance_to_scene(points: np.ndarray, scene: Scene) -> np.ndarray:
    """(N,) unsigned distance (metres) from each of (N, 3) points to the scene's triangles.

    Open3D's ``RaycastingScene.compute_distance`` on the mesh recentred in float64 first (the
    same float32 precaution as :class:`markerplace.scene.raycast.RayCaster`).
    """
    import open3d as o3d

    V, F = scene.geometry()
    centre = 0.5 * (V.min(axis=0) + V.max(axis=0))
    rs = o3d.t.geometry.RaycastingScene()
    rs.add_triangles(o3d.core.Tensor((V - centre).astype(np.float32)), o3d.core.Tensor(F.astype(np.uint32)))
    q = o3d.core.Tensor((np.asarray(points, dtype=np.float64).reshape(-1, 3) - centre).astype(np.float32))
    return rs.compute_distance(q).numpy().astype(np.float64)


__all__ = ["WalkConfig", "DepthNoiseConfig", "ScanConfig", "ScanResult", "FrameSimulator", "plan_walk", "find_doorways",
           "noisy_depth", "simulate_scan", "distance_to_scene", "world_from_cam_ypr", "to_depth_png"]
