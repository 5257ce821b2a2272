"""``markerplace plan --frames DIR``: the options of a plan at an RGB-D sequence's own poses and
its handler (:func:`markerplace.pipelines.plan_frames.run_plan_frames`)."""

from __future__ import annotations

import argparse
import logging

from markerplace.cli.options import plan_config_from_args
from markerplace.errors import UserError
from markerplace.pipelines.plan_frames import FramesInputs, check_frames_method, run_plan_frames
from markerplace.plan.frames.poses import frame_indices
from markerplace.scan.frames import FORMATS, open_frameset

log = logging.getLogger("markerplace.cli.main")

__all__ = ["add_frames_args", "cmd_plan_frames"]


def add_frames_args(p: argparse.ArgumentParser) -> None:
    """``--frames``, ``--format``, ``--intrinsics``, ``--mesh``, ``--frame-step``."""
    g = p.add_argument_group("planning from RGB-D frames (plan --frames DIR, no scene)")
    g.add_argument("--frames", default=None, metavar="DIR",
                   help="plan at the camera poses of this RGB-D sequence, from its own images (markerplace, TUM, "
                        "7-Scenes, nerfstudio or Stray Scanner layout, docs/rgbd_layout.md); tags go on the surface fused from the frames; give no scene")
    g.add_argument("--format", default="auto", choices=["auto", *FORMATS],
                   help="layout of --frames (default auto: detected from the folder's files, docs/rgbd_layout.md)")
    g.add_argument("--intrinsics", default=None, metavar="FILE.json",
                   help="TUM layout: camera intrinsics JSON (width, height, fx, fy, cx, cy, optional depth_scale)")
    g.add_argument("--mesh", default=None, metavar="FILE",
                   help="put tags on this mesh (in the frames' world frame, z up, metres) instead of the surface "
                        "fused from the frames")
    g.add_argument("--frame-step", type=int, default=None, metavar="N",
                   help="use every N-th frame as a camera pose (default: the smallest step giving at most 400 poses)")


def cmd_plan_frames(args: argparse.Namespace) -> int:
    """``plan --frames DIR``: refuses a scene with it (or neither), the options that need a
    scene, then plans and prints what it wrote."""
    if args.frames is None:
        raise UserError("plan needs a scene (a built-in name or a mesh file) or --frames DIR")
    if args.scene is not None:
        raise UserError(f"give either a scene ({args.scene}) or --frames DIR, not both (--mesh FILE puts the tags "
                        "on a mesh of the frames)")
    for flag, value in (("--existing", args.existing), ("--where", args.where), ("--with-map", args.with_map)):
        if value:
            raise UserError(f"{flag} is not supported with --frames yet")
    if args.unit_scale is not None:
        log.warning("--unit-scale: for a scene argument; ignored with --frames (the frames and --mesh are read in "
                    "the frames' world frame, metres)")
    if args.frame_step is not None and args.frame_step < 1:
        raise UserError(f"--frame-step {args.frame_step} must be a positive integer")
    config = plan_config_from_args(args)
    check_frames_method(config)  # before reading any frame
    fs = open_frameset(args.frames, args.format, args.intrinsics, up=args.up)
    idx = frame_indices(len(fs.frames), args.frame_step)
    log.info("plan --frames: %d of %d frames (%s layout, every %d) as camera poses", len(idx), len(fs.frames),
             fs.format, int(idx[1] - idx[0]) if len(idx) > 1 else 1)
    inputs = FramesInputs(fs, idx, mesh=args.mesh, exclude=args.exclude, paper=args.paper, adopt=args.adopt,
                          progress=not args.quiet)
    result = run_plan_frames(config, inputs, args.out)
    print(f"wrote {args.out}/placement.json, placement.csv, tags/*.svg, tags.pdf, tagmaps/, scores.npz, scores.png, "
          f"camera_path.png, placement.png, fused.ply, config.json")
    print(f"wrote {result.report}")
    return 0
