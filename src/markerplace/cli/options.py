"""Options and settings shared by ``plan`` and ``evaluate``: the scene arguments, the
discretization, scoring, placement and runtime options, and the
:class:`~markerplace.plan.config.PlanConfig` built from them.

``--start`` X,Y is given in the user's (file) frame, metres; :func:`markerplace.pipelines.size_guard.check_first_guess`
moves it into the scene's internal frame after the run-size guard. Lengths are metres.
Used by :mod:`markerplace.cli.main` (``plan``), :mod:`markerplace.cli.evaluate` and
:mod:`markerplace.cli.study`.
"""

from __future__ import annotations

import argparse
import logging
from typing import Sequence

log = logging.getLogger(__name__)

__all__ = ["add_scene_args", "add_plan_args", "add_adopt_arg", "parse_allow", "parse_level", "parse_xy",
           "plan_config_from_args", "plan_config_for_budgets"]


def add_scene_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="built-in scene name (see `markerplace scene list`) or a mesh file (.glb, .gltf, .obj, .ply)")
    p.add_argument("--up", default=None, help="up axis of the mesh file: z, y, -y, x, -x, -z (default: y for glTF, its specification; z for OBJ/PLY)")
    p.add_argument("--unit-scale", type=float, default=None, help="multiply mesh coordinates by this to get metres (e.g. 0.01 for cm, 0.001 for mm)")
    p.add_argument("--seed", type=int, default=0, help="seed of the procedural generator for built-in scenes (default 0)")


def parse_xy(text: str | None):
    if text is None:
        return None
    from markerplace.validation import COORDINATE, parse_floats

    return tuple(parse_floats(text, "--start", ("X", "Y"), (COORDINATE, COORDINATE)))


def parse_level(text: str):
    """``--level``: ``all`` (None) or a storey index >= 0."""
    if str(text).strip().lower() == "all":
        return None
    try:
        level = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a storey: give N >= 0 or 'all'") from None
    if level < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a storey: give N >= 0 (0 = lowest) or 'all'")
    return level


def parse_allow(text: str | None) -> tuple[str, ...]:
    """``--allow``: comma list of :data:`~markerplace.plan.discretize.wall_candidates.ALLOWABLE` keys
    (``doors,furniture``); ``none`` or empty: nothing. Raises UserError for an unknown one."""
    from markerplace.errors import UserError
    from markerplace.plan.discretize.wall_candidates import ALLOWABLE

    if text is None:
        return ()
    items = [t.strip().lower() for t in str(text).split(",") if t.strip()]
    if items == ["none"]:
        return ()
    unknown = [t for t in items if t not in ALLOWABLE]
    if unknown:
        raise UserError(f"--allow {text!r}: unknown {', '.join(map(repr, unknown))}; choose from "
                        f"{', '.join(ALLOWABLE)} (comma-separated)")
    return tuple(dict.fromkeys(items))


def plan_config_from_args(args: argparse.Namespace):
    """Build a :class:`~markerplace.plan.config.PlanConfig` from ``plan``/``evaluate`` arguments."""
    from dataclasses import replace

    from markerplace.plan.discretize.stage import DiscretizeConfig
    from markerplace.plan.config import PlanConfig
    from markerplace.plan.place.config import PlacementConfig
    from markerplace.runtime.executor import RuntimeConfig

    disc = replace(DiscretizeConfig(), height=args.height, level=args.level, start=parse_xy(args.start),
                   grid_spacing=args.grid_spacing, clearance=args.clearance, num_yaws=args.yaws,
                   marker_spacing=args.marker_spacing,
                   max_open_fraction=1.0 if args.keep_outdoors else DiscretizeConfig().max_open_fraction,
                   allow=parse_allow(getattr(args, "allow", None)))
    # tag_size: derived from placement's by PlanConfig
    placement = PlacementConfig(k=getattr(args, "k", 20), method=getattr(args, "method", "omp"), v=args.v,
                                marker_model=args.marker_model, tag_size=args.tag_size,
                                similarity=not args.no_similarity, seed=args.placement_seed,
                                calibration_poses=args.calibration_poses)
    runtime = RuntimeConfig(workers=args.workers, cluster=args.cluster)
    return PlanConfig(discretize=disc, placement=placement, runtime=runtime)


def plan_config_for_budgets(args: argparse.Namespace, ks: Sequence[int]):
    """The :class:`~markerplace.plan.config.PlanConfig` of ``evaluate``/``study`` arguments.

    Their ``--k`` is a comma list of budgets held in the same ``args.k`` that ``plan`` uses for
    its one budget, so it is read here as ``ks`` (the parsed budgets, each >= 1): the plan places
    ``max(ks)`` markers and the smaller budgets are evaluated on their own placements or prefixes.
    ``args`` is not changed.
    """
    from markerplace.markers import check_tag_budget

    check_tag_budget(max(ks), [])  # placements get ids 0..k-1
    return plan_config_from_args(argparse.Namespace(**{**vars(args), "k": max(ks)}))


def add_plan_args(p: argparse.ArgumentParser) -> None:
    """Options shared by `plan` and `evaluate` (discretization, scoring)."""
    from markerplace.plan.score.marker_models import MARKER_MODELS
    from markerplace.plan.place.config import CALIBRATION_POSES
    from markerplace.plan.place.methods import PLACEMENT_METHODS

    g = p.add_argument_group("discretization")
    g.add_argument("--height", type=float, default=1.5, help="eye level (cameras and tag centres) above the local floor, metres (default 1.5)")
    g.add_argument("--level", type=parse_level, default=None, metavar="N|all",
                   help="storey to plan, 0 = lowest, or 'all' for every storey with one marker budget (default all)")
    g.add_argument("--start", default=None, help="X,Y: plan only the free region holding this point (default: every region of at least 2 m^2)")
    g.add_argument("--grid-spacing", type=float, default=0.5, help="camera grid spacing, metres (default 0.5)")
    g.add_argument("--clearance", type=float, default=0.3, help="minimum distance of camera locations from obstacles, metres (default 0.3)")
    g.add_argument("--keep-outdoors", action="store_true",
                   help="also plan free regions open to the outside (a porch, a strip under the eaves, a balcony; "
                        "or a room whose glass walls the scan lost): by default a region from which more than 35 %% "
                        "of eye-level views hit nothing is left out, and logged")
    from markerplace.plan.discretize.wall_candidates import ALLOWABLE

    g.add_argument("--allow", default=None, metavar="CATEGORIES",
                   help="let tags go on these too, comma-separated: " + ", ".join(ALLOWABLE) + " (default: none, "
                        "tags only on walls and columns; named from the model's part names, IFC classes, "
                        "transparency and geometry; see docs/cli.md)")
    g.add_argument("--yaws", type=int, default=8, help="camera yaws per location (default 8)")
    g.add_argument("--marker-spacing", type=float, default=1.0, help="minimum spacing of candidate marker poses on a wall, metres (default 1.0)")
    g = p.add_argument_group("scoring and placement")
    g.add_argument("--tag-size", type=float, default=0.4, help="black-square edge of the printed tags, metres (default 0.4)")
    g.add_argument("-v", type=float, default=90.0, help="OMP percentile parameter v in [0, 100] (default 90)")
    g.add_argument("--marker-model", default="paper", choices=MARKER_MODELS.names(),
                   help=f"marker information model: {MARKER_MODELS.help()} (default paper)")
    g.add_argument("--no-similarity", action="store_true", help="turn the look-alike (similarity) analysis off")
    g.add_argument("--calibration-poses", default="map", choices=CALIBRATION_POSES,
                   help="images expected-recall fits its success model on: map (the map images, each without its "
                        "own location) or offgrid (1000 test-like renders between the map poses, never test "
                        "images) (default map)")
    randomized = "/".join(n for n, c in PLACEMENT_METHODS.items() if c.randomized)
    g.add_argument("--placement-seed", type=int, default=0, help=f"seed of the {randomized} placements (default 0)")
    g.add_argument("--workers", type=int, default=0, help="processes for rendering + SIFT (default: CPU count, at most 4; 1 = in this process)")
    g.add_argument("--cluster", default=None, metavar="local:N|tcp://HOST:PORT",
                   help="run rendering + SIFT on a Dask cluster: local:N starts N local workers, an address uses a "
                        "running scheduler (results do not depend on where they run)")
    g.add_argument("--force", action="store_true",
                   help="run even when the size guard estimates more poses, memory or time than the limits "
                        "(200,000 poses, 80%% of this machine's memory, 12 h)")
    add_adopt_arg(p)
    p.add_argument("--quiet", action="store_true", default=argparse.SUPPRESS, help="no progress bars, warnings only")


def add_adopt_arg(p: argparse.ArgumentParser) -> None:
    """``--adopt``: write a run into a non-empty folder markerplace did not make
    (:mod:`markerplace.runtime.run_folder`)."""
    p.add_argument("--adopt", action="store_true",
                   help="use a non-empty --out folder that markerplace did not make: its run files are added, the "
                        "files already there are never replaced or deleted (default: such a folder is refused)")
