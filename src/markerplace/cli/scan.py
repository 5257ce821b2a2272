"""Command line of the scan package: ``markerplace fuse`` and ``scene export ... --as-scan``.

:func:`add_scan_parsers` is the only hook into :mod:`markerplace.cli.main`: it adds the ``fuse``
subcommand and the ``--as-scan``, ``--voxel`` and ``--keep-frames`` options of ``scene export``
(wrapping that command so it still writes glTF without ``--as-scan``).
"""

from __future__ import annotations

import argparse
import functools
import logging
from dataclasses import replace
from pathlib import Path

from markerplace.errors import UserError
from markerplace.output_paths import check_output_file
from markerplace.scan.frames import FORMATS, open_frameset
from markerplace.scan.fuse import FuseConfig, fuse_frameset, parse_trunc, refine_up, write_mesh_ply
from markerplace.scan.simulate import ScanConfig, simulate_scan
from markerplace.scene import load_scene
from markerplace.scene.builtin.catalogue import builtin_names

log = logging.getLogger("markerplace.cli.main")

FUSE_DEFAULTS = {"voxel": 0.02, "trunc": "4x", "depth_max": 4.0, "every": 1}


def _progress(args: argparse.Namespace) -> bool:
    return not getattr(args, "quiet", False)


def _check_ply(out: str, option: str) -> Path:
    path = Path(out)
    if path.suffix.lower() != ".ply":
        raise UserError(f"{option} {out!r} must end in .ply (the fused mesh is written as binary PLY)")

    return check_output_file(path, option)  # a folder, a file above it, no write: before the minutes of fusion


def fuse_config_from_args(args: argparse.Namespace):
    """:class:`~markerplace.scan.fuse.FuseConfig` from ``fuse`` arguments (validated)."""
    trunc_m, trunc_voxels = parse_trunc(args.trunc)
    config = FuseConfig(voxel=args.voxel, trunc_m=trunc_m, trunc_voxels=trunc_voxels, depth_max=args.depth_max,
                        every=args.every)
    config.validate()
    return config


def cmd_fuse(args: argparse.Namespace) -> int:
    """``markerplace fuse FRAMES_DIR --out MESH.ply``."""
    out = _check_ply(args.out, "--out")
    config = fuse_config_from_args(args)
    if args.max_dt <= 0:
        raise UserError(f"--max-dt {args.max_dt:g} must be positive (seconds)")
    fs = open_frameset(args.frames, args.format, args.intrinsics, args.max_dt, up=args.up)
    log.info("%s: %d frames (%s layout), %dx%d, depth scale %g per metre, up axis: %s", fs.root, len(fs.frames),
             fs.format, fs.intrinsics.width, fs.intrinsics.height, fs.depth_scale, fs.up_source)
    mesh = fuse_frameset(fs, config, progress=_progress(args))
    fs, mesh = refine_up(fs, mesh)
    write_mesh_ply(mesh, out)
    print(f"wrote {out} ({len(mesh.triangles)} faces)")
    return 0


def cmd_scene_export_scan(args: argparse.Namespace) -> int:
    """``markerplace scene export NAME OUT.ply --as-scan [--voxel V] [--keep-frames DIR]``."""
    name = str(args.name).strip().lower()
    if name not in builtin_names():
        raise UserError(f"--as-scan works on built-in scenes only ({', '.join(builtin_names())}), not {args.name!r}")
    out = _check_ply(args.out, "scene export OUT")
    config = ScanConfig()
    if args.voxel is not None:
        config = replace(config, fuse=replace(config.fuse, voxel=float(args.voxel)))
    config.fuse.validate()
    if args.keep_frames is not None:
        keep = Path(args.keep_frames)
        if keep.exists() and not keep.is_dir():
            raise UserError(f"--keep-frames {args.keep_frames!r} is a file; give a folder")
        if keep.is_dir() and any(keep.iterdir()):
            raise UserError(f"--keep-frames {args.keep_frames!r} is not empty; give a new or empty folder")
    scene = load_scene(name, seed=args.seed)
    result = simulate_scan(scene, config, seed=args.seed, keep_frames=args.keep_frames, progress=_progress(args))
    write_mesh_ply(result.mesh, out)
    if args.keep_frames is not None:
        log.info("kept %d frames in %s (markerplace layout; `markerplace fuse %s --voxel %g --trunc %gx` rebuilds the mesh)",
                 len(result.world_from_cam), args.keep_frames, args.keep_frames, config.fuse.voxel, config.fuse.trunc_multiplier)
    print(f"wrote {out} ({len(result.mesh.triangles)} faces)")
    return 0


def _scene_export_dispatch(args: argparse.Namespace, fallback) -> int:
    if not getattr(args, "as_scan", False):
        if args.voxel is not None or args.keep_frames is not None:
            raise UserError("--voxel and --keep-frames apply to --as-scan only")
        return fallback(args)
    return cmd_scene_export_scan(args)


def add_fuse_parser(sub) -> argparse.ArgumentParser:
    """Add ``fuse`` to the CLI's subparsers."""
    p = sub.add_parser(
        "fuse",
        help="fuse posed RGB-D frames into a vertex-coloured mesh (TSDF + marching cubes)",
        description="Fuse posed RGB-D frames (markerplace layout, TUM RGB-D, 7-Scenes, nerfstudio transforms.json "
                    "or Stray Scanner; see docs/rgbd_layout.md) into a vertex-coloured triangle mesh with a TSDF "
                    "volume and marching cubes; writes binary PLY in the poses' world frame turned so that +z is up.",
    )
    p.add_argument("frames", metavar="FRAMES_DIR", help="folder of RGB-D frames with poses")
    p.add_argument("--out", required=True, help="output mesh, .ply")
    p.add_argument("--format", default="auto", choices=["auto", *FORMATS],
                   help="input layout (default auto: markerplace if poses.txt/intrinsics.json exist, tum if rgb.txt/depth.txt "
                        "do, 7scenes if frame-*.pose.txt do, nerfstudio if transforms.json does, stray if odometry.csv does)")
    p.add_argument("--up", default=None, metavar="AXIS",
                   help="up direction in the input's world: x, y, z, -x, -y, -z or three numbers such as 0,0.9,0.4 "
                        "(default: the layout's, else estimated from the cameras and refined by the mesh's floors)")
    p.add_argument("--intrinsics", default=None, metavar="FILE.json",
                   help="camera of a TUM sequence: {width, height, fx, fy, cx, cy[, depth_scale=5000]} (default: TUM freiburg1)")
    p.add_argument("--voxel", type=float, default=FUSE_DEFAULTS["voxel"], help="voxel edge, metres (default 0.02)")
    p.add_argument("--trunc", default=FUSE_DEFAULTS["trunc"],
                   help="TSDF truncation: metres (e.g. 0.08) or a multiple of the voxel (e.g. 4x; default 4x)")
    p.add_argument("--depth-max", type=float, default=FUSE_DEFAULTS["depth_max"], help="ignore depth beyond this, metres (default 4.0)")
    p.add_argument("--every", type=int, default=FUSE_DEFAULTS["every"], help="use every N-th frame (default 1: all)")
    p.add_argument("--max-dt", type=float, default=0.02, help="TUM: max timestamp difference of colour, depth and pose, seconds (default 0.02)")
    p.set_defaults(func=cmd_fuse)
    return p


def add_scan_export_args(p_export: argparse.ArgumentParser) -> None:
    """Add ``--as-scan``, ``--voxel`` and ``--keep-frames`` to ``scene export`` and route them."""
    g = p_export.add_argument_group("simulated scan (--as-scan)")
    g.add_argument("--as-scan", action="store_true",
                   help="write what an RGB-D scan of the built-in scene would give: walk through every room, render "
                        "Kinect-like noisy depth (holes, noise), fuse into a vertex-coloured mesh; OUT must be .ply; "
                        "--seed also seeds the walk and the noise")
    g.add_argument("--voxel", type=float, default=None,
                   help="--as-scan: TSDF voxel edge, metres (default 0.04: about 0.75 million faces for the office)")
    g.add_argument("--keep-frames", default=None, metavar="DIR",
                   help="--as-scan: also write the rendered RGB-D frames to DIR in the markerplace layout (input for `markerplace fuse`)")
    fallback = p_export.get_default("func")
    p_export.set_defaults(func=functools.partial(_scene_export_dispatch, fallback=fallback))


def add_scan_parsers(sub, p_export: argparse.ArgumentParser) -> None:
    """The hook called by :func:`markerplace.cli.main.build_parser`: ``fuse`` and ``scene export --as-scan``."""
    add_fuse_parser(sub)
    add_scan_export_args(p_export)
