"""``markerplace evaluate --frames DIR``: the options of the real-photograph testbed and the
handler that runs :func:`markerplace.pipelines.evaluate_frames.run_frames_evaluation`.

:func:`add_frames_eval_args` adds the options to ``evaluate``'s parser; ``cmd_evaluate`` hands
over to :func:`cmd_evaluate_frames` when ``--frames`` is given.
"""

from __future__ import annotations

import argparse

from markerplace.errors import UserError
from markerplace.pipelines.evaluate_frames import run_frames_evaluation
from markerplace.runtime import run_folder
from markerplace.scan.frames import FORMATS, open_frameset
from markerplace.testbed.frames.config import MAP_KINDS, FramesEvalConfig
from markerplace.testbed.frames.split import FrameSplitConfig

__all__ = ["add_frames_eval_args", "cmd_evaluate_frames"]


def add_frames_eval_args(p: argparse.ArgumentParser) -> None:
    """The ``--frames`` options of ``evaluate``."""
    g = p.add_argument_group("real photographs (--frames)")
    g.add_argument("--frames", default=None, metavar="DIR",
                   help="evaluate on a real RGB-D sequence instead of a scene: plan at the map frames' poses, "
                        "composite each placement's tags into the photographs, localize the query frames "
                        "(layouts: docs/rgbd_layout.md)")
    g.add_argument("--format", dest="frames_format", default="auto", choices=["auto", *FORMATS],
                   help="--frames: layout of the frame folder (default auto)")
    g.add_argument("--intrinsics", dest="frames_intrinsics", default=None, metavar="FILE.json",
                   help="--frames: camera of a TUM sequence (docs/rgbd_layout.md)")
    g.add_argument("--mesh", default=None, metavar="FILE",
                   help="--frames: mesh (z up, metres, the frames' world) for the candidate spots and the renders "
                        "instead of the surface fused from the map frames")
    g.add_argument("--map", dest="frames_map", default=",".join(MAP_KINDS), metavar="KINDS",
                   help="--frames: map images: frames (the real map frames), render (the fused surface rendered at "
                        "their poses) or frames,render (default)")
    g.add_argument("--no-gap", dest="frames_gap", action="store_false",
                   help="--frames: skip the queries rendered from the fused surface (the gap table)")
    split = FrameSplitConfig()
    g.add_argument("--block", type=int, default=split.block,
                   help=f"--frames: frames per block of the map/query split (default {split.block})")
    g.add_argument("--gap-frames", type=int, default=split.gap,
                   help=f"--frames: frames left out at each end of a query block (default {split.gap})")
    g.add_argument("--map-step", type=int, default=split.map_step,
                   help=f"--frames: every n-th frame of a map block is a map image (default {split.map_step})")
    g.add_argument("--query-step", type=int, default=split.query_step,
                   help=f"--frames: every n-th frame of a query block is a query (default {split.query_step})")


def frames_eval_config_from_args(args: argparse.Namespace) -> FramesEvalConfig:
    """:class:`~markerplace.testbed.frames.config.FramesEvalConfig` from the parsed options (validated)."""
    maps = tuple(m.strip().lower() for m in str(args.frames_map).split(",") if m.strip())
    config = FramesEvalConfig(split=FrameSplitConfig(args.block, args.gap_frames, args.map_step, args.query_step),
                              maps=maps, gap=bool(args.frames_gap) and "render" in maps)
    config.validate()
    return config


def cmd_evaluate_frames(args: argparse.Namespace, plan_config, config, progress: bool) -> int:
    """``evaluate --frames DIR``: every input checked, the run folder opened, the run."""
    if args.scene is not None or args.plan is not None:
        raise UserError("--frames evaluates a frame sequence: give no scene and no --plan with it")
    frames_config = frames_eval_config_from_args(args)
    fs = open_frameset(args.frames, args.frames_format, args.frames_intrinsics, up=args.up)
    run_folder.open_run_folder(args.out, "evaluate", adopt=args.adopt)
    result = run_frames_evaluation(fs, plan_config, config, frames_config, args.out, mesh=args.mesh, progress=progress)
    print(result.markdown.split("## Every threshold")[0].strip())
    print(f"\nwrote {args.out}/recall.csv, tables.md, query_errors.npz, split.json, config.json, report.html")
    return 0
