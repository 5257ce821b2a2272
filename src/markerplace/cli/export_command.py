"""``markerplace export PLAN_DIR --gltf OUT.glb``: the plan's model with its tags as textured
quads, in the model's original axes and units (:mod:`markerplace.report.tagged_export`).
Registered by :func:`markerplace.cli.main.build_parser`."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

from markerplace.cli.options import add_force_arg
from markerplace.errors import UserError
from markerplace.output_paths import check_output_file
from markerplace.plan.folder import read_plan_folder
from markerplace.report.tagged_export import export_plan_glb

log = logging.getLogger("markerplace.cli.main")


def cmd_export(args: argparse.Namespace) -> int:
    if Path(args.gltf).suffix.lower() != ".glb":
        raise UserError(f"--gltf {args.gltf!r} must end in .glb (binary glTF with the textures inside)")
    folder = read_plan_folder(args.plan_dir)
    check_output_file(args.gltf, "--gltf")
    summary = export_plan_glb(folder, args.gltf)
    print(f"wrote {args.gltf} ({len(summary['tags'])} tags, {summary['faces']} faces; vertex data in {summary['frame']})")
    return 0


def add_export_parser(sub) -> argparse.ArgumentParser:
    """Add ``export`` to the CLI's subparsers."""
    p = sub.add_parser(
        "export", help="write a plan's model with its tags (textured quads) as binary glTF for any viewer or Blender",
        description="Write the model of a plan folder with every placed and existing tag as a textured quad (tag "
                    "image with its white quiet zone) on its wall. The vertex data is in the model's original axes "
                    "and units (the loader's --up rotation, --unit-scale and recentring undone; built-in scenes: "
                    "the z-up world, metres); a root node maps it to glTF's y-up metres so viewers show it upright.")
    p.add_argument("plan_dir", metavar="PLAN_DIR", help="the --out folder of a `markerplace plan` run")
    p.add_argument("--gltf", required=True, metavar="OUT.glb", help="output file (.glb)")
    add_force_arg(p)
    p.set_defaults(func=cmd_export)
    return p
