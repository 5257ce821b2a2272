"""Renderer speed: frames per second at the paper's 600x450 on a built-in scene.

Prints ``name: value`` lines. Goal: >= 30 frames/s (RGB + depth + normal read back) for the
office scene on 2 cores with llvmpipe.

    .venv/bin/python benchmarks/render.py [--frames 200] [--scene office] [--synthetic]

``--synthetic`` renders a generated textured box room instead of a built-in scene (for when the
scene library is unavailable).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from markerplace.geometry import Intrinsics, world_from_cam_poses
from markerplace.render.renderer import Renderer
from markerplace.scene.types import MeshPart, Room, Scene

GOAL_FPS = 30.0


def synthetic_scene(n_boxes: int = 300, seed: int = 0) -> Scene:
    """A 12 x 9 x 3 m textured room with ``n_boxes`` subdivided textured boxes (~15k triangles)."""
    rng = np.random.default_rng(seed)
    tex = rng.integers(0, 256, size=(512, 512, 3), dtype=np.uint8)
    parts = []

    def grid_quad(name, origin, du, dv, nu, nv):
        origin, du, dv = (np.asarray(a, float) for a in (origin, du, dv))
        i, j = np.meshgrid(np.arange(nu + 1), np.arange(nv + 1), indexing="ij")
        verts = origin + i[..., None] / nu * du + j[..., None] / nv * dv
        uv = np.stack([i / nu * np.linalg.norm(du), j / nv * np.linalg.norm(dv)], -1)
        idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
        a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
        faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
        parts.append(MeshPart(name, verts.reshape(-1, 3).astype(np.float32), faces.astype(np.int32),
                              uv=uv.reshape(-1, 2).astype(np.float32), texture=tex))

    L, Wd, H = 12.0, 9.0, 3.0
    grid_quad("floor", [0, 0, 0], [L, 0, 0], [0, Wd, 0], 24, 18)
    grid_quad("ceiling", [0, 0, H], [0, Wd, 0], [L, 0, 0], 24, 18)
    grid_quad("wall_s", [0, 0, 0], [L, 0, 0], [0, 0, H], 24, 6)
    grid_quad("wall_n", [0, Wd, 0], [0, 0, H], [L, 0, 0], 6, 24)
    grid_quad("wall_w", [0, 0, 0], [0, 0, H], [0, Wd, 0], 6, 18)
    grid_quad("wall_e", [L, 0, 0], [0, Wd, 0], [0, 0, H], 18, 6)
    for k in range(n_boxes):
        c = rng.uniform([0.5, 0.5, 0.0], [L - 0.5, Wd - 0.5, 1.0])
        s = rng.uniform(0.1, 0.5, 3)
        x0, y0, z0 = c - s / 2
        x1, y1, z1 = c + s / 2
        for name, o, du, dv in (
            ("a", [x0, y0, z0], [s[0], 0, 0], [0, 0, s[2]]),
            ("b", [x1, y0, z0], [0, s[1], 0], [0, 0, s[2]]),
            ("c", [x1, y1, z0], [-s[0], 0, 0], [0, 0, s[2]]),
            ("d", [x0, y1, z0], [0, -s[1], 0], [0, 0, s[2]]),
            ("e", [x0, y0, z1], [s[0], 0, 0], [0, s[1], 0]),
        ):
            grid_quad(f"box{k}{name}", o, du, dv, 2, 2)
    return Scene("synthetic", tuple(parts), rooms=(Room("main", (0.0, 0.0, L, Wd)),), floor_z=0.0, source="synthetic")


def poses_inside(scene: Scene, n: int, seed: int = 0) -> np.ndarray:
    """(n, 4, 4) level poses at eye height spread over the rooms (or the bounding box)."""
    rng = np.random.default_rng(seed)
    b = scene.bounds
    floor = scene.floor_z if scene.floor_z is not None else b[0, 2]
    rooms = [r.bounds for r in scene.rooms] or [(b[0, 0], b[0, 1], b[1, 0], b[1, 1])]
    pos = np.zeros((n, 3))
    for i in range(n):
        x0, y0, x1, y1 = rooms[i % len(rooms)]
        pos[i] = [rng.uniform(x0 + 0.3, x1 - 0.3), rng.uniform(y0 + 0.3, y1 - 0.3), floor + 1.5]
    yaws = rng.uniform(-np.pi, np.pi, n)
    return world_from_cam_poses(pos, yaws)


def _fps(renderer: Renderer, poses: np.ndarray, **flags: bool) -> float:
    renderer.render(poses[0], **flags)  # warm-up (shader compile, VAO creation)
    t0 = time.perf_counter()
    for _ in renderer.render_batch(poses, **flags):
        pass
    return len(poses) / (time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=200, help="frames per measurement (default 200)")
    ap.add_argument("--scene", default="office", help="built-in scene name (default office)")
    ap.add_argument("--synthetic", action="store_true", help="use a generated textured room instead of --scene")
    args = ap.parse_args(argv)

    if args.synthetic:
        scene = synthetic_scene()
    else:
        from markerplace.scene import load_scene

        scene = load_scene(args.scene)
    poses = poses_inside(scene, args.frames)
    t0 = time.perf_counter()
    with Renderer(scene, Intrinsics()) as r:
        setup_s = time.perf_counter() - t0
        fps_all = _fps(r, poses)
        fps_rgb = _fps(r, poses, rgb=True, depth=False, normal=False)
        fps_rgbd = _fps(r, poses, rgb=True, depth=True, normal=False)
        gl = r.ctx.info.get("GL_RENDERER", "?")
    print(f"scene: {scene.name}")
    print(f"gl_renderer: {gl}")
    print(f"cpus: {os.cpu_count()}")
    print(f"scene_triangles: {scene.num_faces}")
    print(f"frames: {args.frames}")
    print("resolution: 600x450")
    print(f"renderer_setup_s: {setup_s:.3f}")
    print(f"render_fps_rgb_depth_normal: {fps_all:.1f}")
    print(f"render_fps_rgb_depth: {fps_rgbd:.1f}")
    print(f"render_fps_rgb_only: {fps_rgb:.1f}")
    print(f"goal_fps: {GOAL_FPS:.0f}")
    print(f"ratio_to_goal: {fps_all / GOAL_FPS:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
