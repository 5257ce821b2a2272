"""The scanning walk of a simulated RGB-D scan through a built-in scene.

Each room (``scene.rooms``, xy bounds and ``floor_z``) gets a lattice of positions ``spacing``
apart (default 0.8 m), ``wall_margin`` inside its wall centre lines, visited in serpentine order;
a position that is not over the room's floor (furniture below) or closer than ``clearance`` to
anything at knee, waist or eye height is nudged by a third of the spacing, or skipped. Doorways
are found geometrically (horizontal rays across the wall shared by two rooms at 1 m above the
floor) and crossed: positions 0.6 m before, in and 0.6 m after each opening. At every position
the camera is 1.2-1.6 m above the room's floor and sweeps ``yaws`` headings at each of the
``pitches_deg`` (-45, 0, +30 deg: floor, walls, ceiling), with a few degrees of hand-held jitter
in yaw, pitch and roll. Everything random comes from ``seed``.

Poses are (4, 4) ``world_from_cam`` (OpenCV camera: x right, y down, z forward; world z up,
metres). Used by :func:`markerplace.scan.simulate.simulate_scan`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import rotation_from_yaw
from markerplace.scene.raycast import RayCaster
from markerplace.scene.types import Room, Scene

log = logging.getLogger(__name__)


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



def seeded_rng(seed: int, *stream: int) -> np.random.Generator:
    """A generator for (seed, stream...): independent streams, any integer seed (negative too)."""
    return np.random.default_rng([int(seed) % (1 << 63), *[int(s) for s in stream]])


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
    if not scene.rooms:
        raise UserError(f"scene {scene.name!r} has no rooms: a simulated scan needs a built-in scene")
    if cfg.yaws < 1 or not cfg.pitches_deg or cfg.spacing <= 0:
        raise ValueError("walk needs yaws >= 1, at least one pitch and a positive spacing")
    caster = RayCaster(*scene.geometry())
    rng = seeded_rng(seed, 1)
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



__all__ = ["WalkConfig", "seeded_rng", "world_from_cam_ypr", "find_doorways", "plan_walk"]
