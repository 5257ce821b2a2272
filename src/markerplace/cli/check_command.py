"""``markerplace check PLAN_DIR --installed installed.json`` or ``--photos DIR``: where the tags
really went vs the plan (:func:`markerplace.pipelines.check.run_check`). Registered by :func:`markerplace.cli.main.build_parser`."""

from __future__ import annotations

import argparse

from markerplace.cli.options import add_adopt_arg, add_force_arg
from markerplace.pipelines.check import run_check
from markerplace.plan.installed_vs_plan import MATCH_RADIUS_M, TOLERANCE_DEG, TOLERANCE_M
from markerplace.runtime.executor import RuntimeConfig
from markerplace.settings import add_setting_args, apply, values_from_args


def cmd_check(args: argparse.Namespace) -> int:
    runtime = apply(RuntimeConfig(), values_from_args(args, RuntimeConfig(), "check"))
    _, text = run_check(args.plan_dir, args.installed, args.out, radius=args.match_radius, runtime=runtime,
                        progress=not args.quiet, adopt=args.adopt, photos=args.photos, intrinsics=args.intrinsics)
    print(text)
    return 0


def add_check_parser(sub) -> argparse.ArgumentParser:
    """Add ``check`` to the CLI's subparsers."""
    p = sub.add_parser(
        "check", help="compare the tags as installed (measured) with a plan: shifts, score lost, where it hurts",
        description="After the tags went up, give photos of them (--photos DIR) or their measured poses (--installed: "
                    "placement.json's format, or a list of {tag_id, position, normal[, size]} in the plan's "
                    "coordinates, metres). Per planned "
                    f"tag: what was found at its spot (as planned within {100 * TOLERANCE_M:.0f} cm and "
                    f"{TOLERANCE_DEG:.0f} deg, shifted, wrong id, swapped, missing; extra tags too), the shift in "
                    "metres and degrees and the localizability score lost; then the camera locations that lost "
                    "most. The plan's cached stages are reused; only depth at the poses that see an installed tag "
                    "is rendered.")
    p.add_argument("plan_dir", metavar="PLAN_DIR", help="the --out folder of a `markerplace plan` run")
    how = p.add_mutually_exclusive_group(required=True)
    how.add_argument("--photos", default=None, metavar="DIR",
                     help="photos of the tags on the walls (JPEG/PNG of any size, the focal length from EXIF; or an "
                          "RGB-D frame folder): the tags and cameras are solved together, placed on the model by the "
                          "tags hung as planned; per tag its uncertainty and how many photos saw it; what to "
                          "photograph next. Detections are cached in the output folder")
    how.add_argument("--installed", default=None, metavar="FILE.json",
                     help="tags measured by hand (see above): the fallback without photos")
    p.add_argument("--intrinsics", default=None, metavar="FILE.json",
                   help="with --photos: the camera (width, height, fx, fy, cx, cy in pixels; photos of another size "
                        "with the same aspect get it scaled), needed when the photos' EXIF has no focal length")
    p.add_argument("--out", default=None, help="output folder (default PLAN_DIR/check)")
    p.add_argument("--match-radius", type=float, default=MATCH_RADIUS_M,
                   help=f"an installed tag farther than this from a planned spot is not that spot's tag, metres "
                        f"(default {MATCH_RADIUS_M:g})")
    add_setting_args(p, RuntimeConfig(), "check")  # --workers, as plan's

    add_force_arg(p)
    add_adopt_arg(p)  # PLAN_DIR from an older markerplace, or an --out folder it did not make
    p.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help="no progress bars, warnings only")
    p.set_defaults(func=cmd_check)
    return p
