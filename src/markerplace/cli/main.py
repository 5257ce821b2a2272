"""Command line: parses arguments and chains library stages; no logic of its own.

Every user-fixable problem surfaces as :class:`~markerplace.errors.UserError`: printed as one
line ``markerplace: error: ...`` with exit code 2; so does every argument error
(:class:`OneLineParser`), and what the machine makes fail (standard output on a full device or
in an encoding that lacks a character, a deleted working directory, ``ulimit -n``, out of memory:
:mod:`markerplace.cli.edge`). Ctrl-C and SIGTERM stop the command within seconds with exit code 130
/ 143 and one line saying how to resume (:mod:`markerplace.runtime.interrupt`).
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from markerplace import __version__
from markerplace.cli.bounds import check_args
from markerplace.cli.check_command import add_check_parser
from markerplace.cli.edge import StdoutError, StdoutGuard, check_working_directory, resource_error
from markerplace.cli.evaluate_command import add_evaluate_parser
from markerplace.cli.export_command import add_export_parser
from markerplace.cli.options import add_force_arg, add_plan_args, add_scene_args, plan_config_from_args
from markerplace.cli.plan_frames_command import add_frames_args, cmd_plan_frames
from markerplace.cli.scan import add_scan_parsers
from markerplace.cli.study_command import add_study_parser
from markerplace.errors import UserError
from markerplace.geometry import Intrinsics, world_from_cam_pose
from markerplace.log import setup_logging
from markerplace.markers import load_markers
from markerplace.output_paths import check_output_file
from markerplace.pipelines.plan import PlanInputs, run_plan
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.render.renderer import Renderer
from markerplace.render.views import default_pose, write_render_outputs
from markerplace.report.sheets import PAPER_CHOICES
from markerplace.runtime import cache_home
from markerplace.runtime.interrupt import InterruptGuard
from markerplace.runtime.run_folder import close_all
from markerplace.scene import load_scene
from markerplace.scene.builtin.catalogue import list_scenes
from markerplace.scene.export import export_glb
from markerplace.scene.preflight import allow_large_models
from markerplace.scene.spec import SceneSpec
from markerplace.scene.worldframe import markers_to_internal, points_to_internal, world_offset
from markerplace.validation import COORDINATE, YAW_DEG, check_pose_in_scene, check_render_sees_something, parse_floats

log = logging.getLogger("markerplace.cli.main")


def _parse_pose(text: str):
    return parse_floats(text, "--pose", ("X", "Y", "Z", "YAW_DEG"), (COORDINATE, COORDINATE, COORDINATE, YAW_DEG))


def cmd_scene_list(args: argparse.Namespace) -> int:
    rows = list_scenes()
    width = max(10, *(len(r["name"]) for r in rows))
    print(f"{'name':<{width}} {'floor area (m^2)':>16} {'rooms':>6}  description")
    for r in rows:
        print(f"{r['name']:<{width}} {r['area_m2']:>16.1f} {r['rooms']:>6}  {r['description']}")
    return 0


def cmd_scene_export(args: argparse.Namespace) -> int:
    check_output_file(args.out, "scene export OUT")
    if Path(args.out).suffix.lower() != ".glb":
        raise UserError(f"scene export OUT {args.out!r} must end in .glb (binary glTF with the textures inside; "
                        "--as-scan writes .ply)")
    scene = load_scene(args.name, seed=args.seed)
    export_glb(scene, args.out)
    log.info("wrote %s (%d faces)", args.out, scene.num_faces)
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    pose = _parse_pose(args.pose) if args.pose else None
    check_output_file(args.out, "--out", ("_rgb.png", "_depth.npy", "_normal.png"))
    user_markers = load_markers(args.markers, "--markers") if args.markers else []
    scene = load_scene(args.scene, up=args.up, unit_scale=args.unit_scale, seed=args.seed)
    offset = world_offset(scene)  # inputs are in the user's (file) frame
    markers = markers_to_internal(user_markers, offset)
    if pose is not None:
        position = points_to_internal(pose[:3], offset)
        check_pose_in_scene(scene, position, offset)
        world_from_cam = world_from_cam_pose(position, np.radians(pose[3]))
    else:
        world_from_cam = default_pose(scene)
    intr = Intrinsics.from_fov(args.width, args.height, args.hfov)
    with Renderer(scene, intr, markers=markers) as renderer:
        result = renderer.render(world_from_cam)
    check_render_sees_something(result, args.pose)
    paths = write_render_outputs(args.out, result)
    for p in paths:
        print(p)
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    """Handler of ``markerplace plan``: :func:`markerplace.pipelines.plan.run_plan` (or, with
    ``--frames``, :func:`markerplace.cli.plan_frames_command.cmd_plan_frames`), then what it wrote."""
    if args.frames is not None or args.scene is None:
        return cmd_plan_frames(args)
    frames_only = [f for f, v in (("--mesh", args.mesh), ("--frame-step", args.frame_step),
                                  ("--intrinsics", args.intrinsics)) if v is not None]
    if frames_only:
        raise UserError(f"{frames_only[0]} is an option of plan --frames DIR; a scene was given")
    inputs = PlanInputs(existing=args.existing, exclude=args.exclude, where=args.where, paper=args.paper,
                        with_map=args.with_map, force=args.force, adopt=args.adopt, progress=not args.quiet)
    scene = SceneSpec(args.scene, args.up, args.unit_scale, args.seed)
    result = run_plan(plan_config_from_args(args), scene, args.out, inputs)
    print(f"wrote {args.out}/placement.json, placement.csv, tags/*.svg, tags.pdf, tagmaps/, scores.npz, scores.png, "
          f"gain_first.png, placement.png, {'where.png, ' if args.where else ''}config.json")
    print(f"wrote {result.report}")
    for line in result.changes:
        print(line)
    return 0


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line ``markerplace: error: ...`` (exit code 2),
    naming the subcommand's ``--help``, instead of argparse's usage block. Subparsers made by
    ``add_subparsers`` are of the same class."""

    def error(self, message: str):
        text = " ".join(str(message).split())
        sys.stderr.write(f"markerplace: error: {text} (see `{self.prog} --help`)\n")
        sys.exit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="markerplace",
        description="Plan where to put AprilTag markers so camera localization works better (OMP), and prove it in simulation.",
    )
    parser.add_argument("--version", action="version", version=f"markerplace {__version__}")
    parser.add_argument("--quiet", action="store_true", help="only warnings and errors, no progress bars")
    parser.add_argument("--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p_scene = sub.add_parser("scene", help="built-in scenes: list them or export one as glTF")
    scene_sub = p_scene.add_subparsers(dest="scene_command", metavar="SUBCOMMAND")
    p_list = scene_sub.add_parser("list", help="print name, floor area and rooms of each built-in scene")
    p_list.set_defaults(func=cmd_scene_list)
    p_export = scene_sub.add_parser("export", help="write a built-in scene as a standard binary glTF (.glb, y-up)")
    p_export.add_argument("name", help="built-in scene name")
    p_export.add_argument("out", help="output path, e.g. office.glb")
    p_export.add_argument("--seed", type=int, default=0, help="seed of the procedural generator (default 0)")
    add_force_arg(p_export)
    p_export.set_defaults(func=cmd_scene_export)

    p_render = sub.add_parser("render", help="render RGB, depth and normals of a scene at one camera pose")
    add_scene_args(p_render)
    p_render.add_argument("--pose", default=None, help="camera X,Y,Z,YAW_DEG (world, metres; yaw CCW from +x); default: a pose inside the scene")
    p_render.add_argument("--markers", default=None, help="JSON file of markers to draw (e.g. a placement.json)")
    p_render.add_argument("--out", required=True, help="output prefix: writes PREFIX_rgb.png, PREFIX_depth.npy, PREFIX_normal.png")
    p_render.add_argument("--width", type=int, default=600, help="image width in pixels (default 600)")
    p_render.add_argument("--height", type=int, default=450, help="image height in pixels (default 450)")
    p_render.add_argument("--hfov", type=float, default=90.0, help="horizontal field of view in degrees (default 90)")
    add_force_arg(p_render)
    p_render.set_defaults(func=cmd_render)


    p_plan = sub.add_parser("plan", help=f"place k markers ({', '.join(PLACEMENT_METHODS)}) and write the plan")
    add_scene_args(p_plan, optional="give --frames DIR instead")
    add_frames_args(p_plan)
    p_plan.add_argument("--out", required=True, help="run directory (stages are cached here and reused)")
    p_plan.add_argument("--config", default=None, metavar="FILE",
                        help="settings from a TOML file (tables as in config.json: [discretize], "
                             "[discretize.candidates], [placement], ...) or a plan's config.json (reproduces that "
                             "plan); options given here override it (see docs/cli.md)")
    p_plan.add_argument("--existing", default=None, help="JSON file of markers already on the walls; they count as placed")
    p_plan.add_argument("--exclude", default=None, metavar="FILE",
                        help="JSON file of spots (x, y, z, radius) and boxes where no tag may go, in the model's "
                             "coordinates (e.g. the rejected.json of report.html's review buttons); applied when "
                             "placing, so a re-run reuses every cached stage (see docs/cli.md)")
    p_plan.add_argument("--where", default=None, metavar="FILE",
                        help="GeoJSON file of where the cameras will be: zones, routes (width, heading) and poses "
                             "of use in the model's coordinates (docs/where.md); the objective, the predicted recall "
                             "and the bounds weigh each camera pose by it; applied after discretize, so a re-run "
                             "reuses every cached stage")

    p_plan.add_argument("--paper", default="a4", type=str.lower, choices=PAPER_CHOICES,
                        help="paper of tags.pdf: tags larger than it are tiled with overlap strips and alignment marks; "
                             "none = one page per tag at its own size (default a4)")
    p_plan.add_argument("--with-map", action="store_true",
                        help="also extract the evaluation's marker-free map (OpenCV-default SIFT and tags) from "
                             "observe's renders, so that a later `evaluate --plan` renders no map image (observe "
                             "takes longer); always on with expected-recall, --target-recall or "
                             "--recall-curve, whose calibration needs the map")
    add_plan_args(p_plan)
    p_plan.set_defaults(func=cmd_plan)


    add_evaluate_parser(sub)


    add_scan_parsers(sub, p_export)  # `fuse` and `scene export ... --as-scan`



    add_study_parser(sub)  # `study SCENE --out DIR`
    add_export_parser(sub)  # `export PLAN_DIR --gltf OUT.glb`
    add_check_parser(sub)  # `check PLAN_DIR --installed FILE.json`

    return parser


SIGNED_VALUE_OPTIONS = ("--up", "--start", "--pose")
"""Options whose value may start with '-' (``--up -x``, ``--start -2.5,1``): argparse would read it
as an option ("expected one argument"), so :func:`join_signed_values` glues it on with '='."""


def join_signed_values(argv: list[str]) -> list[str]:
    """``[..., "--up", "-x", ...]`` -> ``[..., "--up=-x", ...]`` for :data:`SIGNED_VALUE_OPTIONS`
    followed by a value that starts with '-' (and is not ``--``-anything); the rest unchanged."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in SIGNED_VALUE_OPTIONS and i + 1 < len(argv) and argv[i + 1].startswith("-") \
                and not argv[i + 1].startswith("--") and len(argv[i + 1]) > 1:
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


RESUMABLE_COMMANDS = ("plan", "evaluate", "study", "check")
"""Commands that cache their stages in their output folder: an interrupted one resumes."""


def main(argv: list[str] | None = None) -> int:
    with InterruptGuard() as guard, StdoutGuard() as stdout:
        try:
            try:
                check_working_directory()
                code = _run(list(sys.argv[1:] if argv is None else argv), guard)
            finally:
                sys.stdout.flush()  # a full disk shows here, not in Python's flush at exit
            return code
        except StdoutError as err:
            stdout.silence()
            if not err.quiet:
                print(f"markerplace: error: {err}", file=sys.stderr)
            return err.exit_code
        except UserError as err:
            print(f"markerplace: error: {err}", file=sys.stderr)
            return err.exit_code
        except KeyboardInterrupt as err:  # Ctrl-C or SIGTERM (runtime.interrupt.Terminated)
            return guard.stopped(err)
        except (MemoryError, OSError, ImportError) as err:  # ulimit -n, ulimit -v, no memory: one line (cli.edge)
            short = resource_error(err, guard.resumable)
            if short is None:
                raise
            print(f"markerplace: error: {short}", file=sys.stderr)
            return short.exit_code


def _run(argv: list[str], guard: InterruptGuard) -> int:
    """Parse ``argv`` and run its command (:func:`main` catches what it raises)."""
    parser = build_parser()
    args = parser.parse_args(join_signed_values(argv))
    setup_logging(quiet=args.quiet, verbose=args.verbose)
    for note in cache_home.NOTE:  # the cache folder is not the one asked for (a service account)
        (log.warning if cache_home.NOTE_IS_WARNING else log.info)("cache: %s", note)
    guard.resumable = args.command in RESUMABLE_COMMANDS
    func = getattr(args, "func", None)
    if func is None:
        # `markerplace` or `markerplace scene` without a subcommand: show the relevant help.
        if args.command == "scene":
            parser.parse_args(["scene", "--help"])
        parser.print_help()
        return 2
    check_args(args)  # every numeric option of every subcommand: finite and in range
    allow_large_models(getattr(args, "force", False))  # --force: a model file larger than the free memory too
    try:
        code = int(func(args) or 0)
        if guard.signum is not None:  # a signal whose exception was swallowed on the way
            return guard.stopped(KeyboardInterrupt())
        return code
    finally:
        close_all()  # unlock the run folders; one the run wrote nothing into is left as found
