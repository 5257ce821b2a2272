"""Discretization (paper, Methods: "Discretization"): feasible camera poses and candidate markers.

The paper cuts one eye-level plane through the model and maps its free space with an occupancy
grid. Real buildings have several storeys, steps and sunken rooms, and scans have holes, glass
and clutter, so the stage is built from three parts:

1. :mod:`markerplace.plan.discretize.storeys` and :mod:`markerplace.plan.discretize.floorplan`: vertical rays find the
   storeys and, per storey, the floor a person stands on (steps and sunken rooms included,
   furniture tops not, inside the building).
2. :mod:`markerplace.plan.discretize.freespace`: eye-level cross-sections give the obstacles; the free region
   is the floor minus obstacles, opened so that scan holes narrower than a person do not leak;
   camera locations are lattice points in it (``grid_spacing`` apart, ``clearance`` from
   anything, ``height`` above their local floor), each with ``num_yaws`` level poses.
3. :mod:`markerplace.plan.discretize.wall_candidates`: range scans at eye level from the camera locations give
   the wall spots; they are spaced uniformly along the free-space perimeter and kept where a
   flat tag fits on structure that stays (not on glass, windows, doors, curtains, mirrors,
   screens, pictures or furniture, unless ``allow`` names them; by the parts' names and by
   geometry), each recording what it is on.

``level`` plans one storey (0 = lowest) or, when None, every storey at once (one budget, one
greedy over the poses and candidates of all storeys).

Frames: world z up, metres (see :mod:`markerplace.geometry`). The occupancy grids have row 0 at
``grid_origin[1]`` and column 0 at ``grid_origin[0]`` (the lower-left corner), cells of
``grid_resolution`` metres; cell (r, c) has centre ``origin + ((c + .5) res, (r + .5) res)``.

The result, :class:`~markerplace.plan.discretize.artifact.Discretization`, and its file
``discretization.npz`` live in :mod:`markerplace.plan.discretize.artifact`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from markerplace import geometry
from markerplace.errors import UserError
from markerplace.markers import DEFAULT_TAG_SIZE
from markerplace.plan.discretize.artifact import Discretization
from markerplace.plan.discretize.artifact import load as load_discretization
from markerplace.plan.discretize.artifact import save as save_discretization
from markerplace.plan.discretize.candidate_rules import RULES, CandidateConfig, SurfaceLabels, rule_words
from markerplace.plan.discretize.floorplan import eye_level_support, storey_floor
from markerplace.plan.discretize.freespace import Sections, StoreySpace, camera_locations, free_space, obstacle_mask, open_fractions
from markerplace.plan.discretize.grid import Grid
from markerplace.plan.discretize.storeys import FloorConfig, cast_columns, find_storeys
from markerplace.plan.discretize.wall_candidates import wall_candidates
from markerplace.runtime import cache
from markerplace.runtime.cache import config_dict
from markerplace.runtime.stages import cached
from markerplace.scene.raycast import RayCaster
from markerplace.settings import OCCUPANCY_CELL, setting
from markerplace.validation import parse_level as _parse_level
from markerplace.validation import parse_xy as _parse_xy

log = logging.getLogger(__name__)

__all__ = ["DiscretizeConfig", "candidate_arithmetic", "discretize", "run_discretize"]


@dataclass(frozen=True)
class DiscretizeConfig:
    """Settings of the discretization stage (``plan --config``: the ``[discretize]`` table).

    The tag that must fit flat on a wall is the placement's (``placement.tag_size``): it is
    passed to :func:`discretize`, not kept here.

    Attributes:
        height: eye level (cameras and tag centres) above the local floor, metres (paper: 1.5).
        level: storey to plan, 0 = lowest; None plans every storey at once.
        start: (x, y) world metres: keep only the free region holding this point (on each
            storey where it is free); None keeps every region of at least ``min_region_area``.
        grid_spacing: distance between camera locations, metres (paper: 0.5-0.7).
        clearance: minimum distance from a camera location to non-free space, metres.
        num_yaws: camera poses per location, yaw = 2 pi j / num_yaws (paper: 8).
        resolution: occupancy and floor-map cell size, metres (coarsened for huge models).
        slice_offsets: heights (metres, relative to the eye-level plane of the storey) of the
            cross-sections whose union blocks free space.
        passage_radius: gaps narrower than twice this (metres) do not connect free space.
        min_region_area: without ``start``, free regions smaller than this (m^2) are dropped.
        max_open_fraction: without ``start``, a free region from which more than this fraction
            of horizontal eye-level rays hit nothing within ``open_reach`` is outdoors (a strip
            under the eaves, a porch, a balcony: a CAD model's surroundings) and dropped; a room
            with glassless windows lets far fewer out. 1.0 keeps every region.
        open_reach: length of those rays, metres.
        floor: how storeys and floors are found (:class:`~markerplace.plan.discretize.storeys.FloorConfig`).
        candidates: where candidate markers may go (spacing, flatness, the scan, ``allow``:
            :class:`~markerplace.plan.discretize.candidate_rules.CandidateConfig`).
    """

    height: float = setting(1.5, flag="--height", bounds=(0.1, 10.0), units="m",
                            help="eye level (cameras and tag centres) above the local floor, metres",
                            hint="the eye-level plane height above the floor in metres, e.g. 1.5")
    level: int | None = setting(None, flag="--level", type=_parse_level, metavar="N|all", bounds=(0, 1000),
                                integer=True, hint="a storey index, 0 = lowest", shown_default="all",
                                help="storey to plan, 0 = lowest, or 'all' for every storey with one marker budget")
    start: tuple[float, float] | None = setting(None, flag="--start", metavar="X,Y", convert=_parse_xy,
                                                shown_default="every region of at least 2 m^2",
                                                help="plan only the free region holding this point (user frame, "
                                                     "metres)")
    grid_spacing: float = setting(0.5, flag="--grid-spacing", bounds=(OCCUPANCY_CELL, 50.0), units="m",
                                  help="camera grid spacing, metres (the paper used 0.5-0.7)",
                                  hint=f"the camera grid spacing in metres, e.g. 0.5 (not finer than the "
                                       f"{OCCUPANCY_CELL:g} m occupancy grid)")
    clearance: float = setting(0.3, flag="--clearance", bounds=(0.0, 5.0), units="m",
                               help="minimum distance of camera locations from obstacles, metres",
                               hint="the distance of cameras from obstacles in metres, e.g. 0.3")
    num_yaws: int = setting(8, flag="--yaws", bounds=(1, 360), help="camera yaws per location",
                            hint="camera yaws per location, e.g. 8")
    resolution: float = 0.05
    slice_offsets: tuple[float, ...] = (-0.3, 0.0, 0.25)
    passage_radius: float = 0.2
    min_region_area: float = 2.0
    max_open_fraction: float = setting(0.35, flag="--keep-outdoors", const=1.0, bounds=(0.0, 1.0), shown_default="off",
                                       help="also plan free regions open to the outside (a porch, a strip under "
                                            "the eaves, a balcony; or a room whose glass walls the scan lost): by "
                                            "default a region from which more than 35 % of eye-level views hit "
                                            "nothing within 50 m is left out, and logged",
                                       hint="a fraction in [0, 1], e.g. 0.35 (1 keeps every region)")
    open_reach: float = 50.0
    floor: FloorConfig = field(default_factory=FloorConfig)
    candidates: CandidateConfig = field(default_factory=CandidateConfig)

    def cache_view(self, tag_size: float) -> dict:
        """What the discretization's cache key hashes: the settings as one flat dict, laid out as
        before the candidate settings were nested (so the keys of existing run folders stay
        valid), with ``tag_size`` (the placement's, metres); a candidate setting that was not a
        field of the flat layout is added only when it differs from its default."""
        flat = {f.name: config_dict(getattr(self, f.name)) for f in fields(self) if f.name != "candidates"}
        default = CandidateConfig()
        for f in fields(CandidateConfig):
            value = getattr(self.candidates, f.name)
            if f.name in _FLAT_CANDIDATE_FIELDS or value != getattr(default, f.name):
                flat[f.name] = config_dict(value)
        flat["tag_size"] = tag_size
        return flat


_FLAT_CANDIDATE_FIELDS = ("marker_spacing", "normal_diff_deg", "tag_border", "flatness_tol", "max_normal_z",
                          "scan_rays", "max_scan_range", "allow")
"""The candidate settings DiscretizeConfig held itself before they were nested."""


def _grid_for(vertices: np.ndarray, cfg: DiscretizeConfig) -> Grid:
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    grid = Grid.covering(lo, hi, cfg.resolution)
    cells = grid.H * grid.W
    if cells > cfg.floor.max_cells:
        res = cfg.resolution * float(np.sqrt(cells / cfg.floor.max_cells))
        log.warning("discretize: the model is %.0f x %.0f m; floor maps use %.2f m cells instead of %.2f m (memory)",
                    hi[0] - lo[0], hi[1] - lo[1], res, cfg.resolution)
        grid = Grid.covering(lo, hi, res)
    return grid


def discretize(scene, config: DiscretizeConfig = DiscretizeConfig(),
               tag_size: float = DEFAULT_TAG_SIZE) -> Discretization:
    """Feasible camera poses and candidate marker poses of ``scene`` (see the module docstring).

    Args:
        scene: a :class:`~markerplace.scene.types.Scene` (world z up, metres).
        config: settings.
        tag_size: black-square edge of the tags that must fit flat on a wall, metres (the
            placement's ``tag_size``).

    Returns:
        The :class:`Discretization`.

    Raises:
        UserError: no floor, level out of range, start point in an obstacle or outside the
            model, no walls at eye level, no feasible camera pose, no candidate marker.
    """
    cfg = config
    V, F = scene.geometry()
    rc = RayCaster(V, F)
    grid = _grid_for(V, cfg)
    surfaces = cast_columns(rc, grid, cfg.floor)
    sections = Sections(V, F)

    def has_walls(floor_z: float, area: float) -> bool:
        """Walls cross the eye level above a floor: cut length at least its area's perimeter."""
        seg, _ = sections.at(floor_z + cfg.height)
        return float(np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1).sum()) >= 4 * np.sqrt(area)

    storeys, ceilings = find_storeys(surfaces, cfg.floor, has_walls)
    if not storeys:
        raise UserError("no floor found: no near-horizontal surface with headroom above it; check --up "
                        "(and --unit-scale) of the mesh")
    heights = ", ".join(f"{z:.2f}" for z in storeys)
    if cfg.level is None:
        planned = list(range(len(storeys)))
    elif 0 <= cfg.level < len(storeys):
        planned = [int(cfg.level)]
    else:
        raise UserError(f"--level {cfg.level} is out of range: found {len(storeys)} storey(s) "
                        f"(floor heights {heights} m); use --level 0..{len(storeys) - 1} or --level all")
    log.info("discretize: %d storey(s) at floor heights %s m (normals %s); planning %s",
             len(storeys), heights, surfaces.orientation,
             "all" if cfg.level is None else f"storey {cfg.level}")

    start = None if cfg.start is None else np.asarray(cfg.start, dtype=float).reshape(2)
    per_storey = []
    for s in planned:
        floor_z = storeys[s]
        eye = floor_z + cfg.height
        if s + 1 < len(storeys) and eye >= storeys[s + 1]:
            raise UserError(f"eye level z={eye:.2f} m is above the next storey's floor ({storeys[s + 1]:.2f} m); "
                            "lower --height")
        floor = storey_floor(surfaces, floor_z, ceilings[s], cfg.floor)
        obstacle, n_seg = obstacle_mask(grid, sections, [eye] + [eye + dz for dz in cfg.slice_offsets if dz != 0])
        if n_seg[0] == 0:
            if len(planned) == 1:
                raise UserError(f"no walls cut the plane at z={eye:.2f} m; check --height/--level/--up")
            log.warning("discretize: storey %d: no walls cut its eye-level plane z=%.2f m; skipped", s, eye)
            continue
        support = eye_level_support(rc, grid, floor, eye, surfaces.orientation, cfg.floor)
        per_storey.append((s, floor, support, obstacle))
    if start is not None:
        _check_start(start, grid, per_storey, cfg)

    summary = {"storeys": [float(z) for z in storeys], "normals": surfaces.orientation, "per_storey": []}
    spaces = []
    for s, floor, support, obstacle in per_storey:
        here = None
        if start is not None and grid.lookup(support & ~obstacle, start[None], False)[0]:
            here = start
        space = free_space(grid, support, obstacle, passage_radius=cfg.passage_radius,
                           min_region_area=cfg.min_region_area, start=here)
        if here is None:
            space = _drop_outdoors(rc, grid, space, s, floor.floor_z + cfg.height, cfg)
        xy, z = camera_locations(grid, floor, space.free, grid_spacing=cfg.grid_spacing,
                                 clearance=cfg.clearance, height=cfg.height, rc=rc)
        spaces.append((s, floor, support & ~obstacle, space, xy, z))
    if sum(len(t[4]) for t in spaces) == 0:
        eyes = ", ".join(f"{storeys[t[0]] + cfg.height:.2f}" for t in per_storey) or "?"
        raise UserError(f"no feasible camera poses: no free cell with clearance >= {cfg.clearance:g} m and floor "
                        f"below at z={eyes} m; check --start/--height/--clearance/--grid-spacing")

    cand = wall_candidates(rc, SurfaceLabels.from_scene(scene), grid,
                           [(floor, space.free, np.column_stack([xy, z])) for _, floor, _, space, xy, z in spaces],
                           cfg.candidates, height=cfg.height, tag_size=tag_size)
    if len(cand.position) == 0:
        raise UserError(f"no candidate marker poses: no flat near-vertical wall at eye level holds a "
                        f"{tag_size:g} m tag ({_removed_words(cand.removed, tag_size)}); check "
                        "--height/--tag-size, or --allow what the spots are on")

    locations = np.concatenate([t[4] for t in spaces])
    location_z = np.concatenate([t[5] for t in spaces])
    location_storey = np.concatenate([np.full(len(t[4]), t[0], np.int64) for t in spaces])
    L, n = len(locations), cfg.num_yaws
    location_index = np.repeat(np.arange(L), n)
    yaw = np.tile(2 * np.pi * np.arange(n) / n, L)
    pos = np.column_stack([locations[location_index], location_z[location_index]])
    world_from_cam = geometry.world_from_cam_poses(pos, yaw)
    slots = [t[0] for t in spaces]
    cand_storey = np.asarray(slots, np.int64)[cand.storey] if len(cand.storey) else np.zeros(0, np.int64)
    cT = np.stack([geometry.world_from_marker_pose(p, q) for p, q in zip(cand.position, cand.normal)])

    for (s, _floor, open_floor, space, xy, _z) in spaces:
        info = _storey_report(s, storeys[s], grid, open_floor, space, xy, int((cand_storey == s).sum()), cfg)
        summary["per_storey"].append(info)
    r = cand.removed
    summary["candidates_removed"] = {rule: r[rule] for rule in RULES}
    summary["wall_spots"] = r["spots"]
    summary["wall_spots_pass"] = r["pass"]
    summary["candidates_crowded"] = r["crowded"]
    summary["candidates_added"] = r["added"]
    summary["allow"] = list(cfg.candidates.allow)
    log.info("discretize: %s", candidate_arithmetic(summary, cfg.candidates.marker_spacing, tag_size, len(cT)))

    if start is None:
        first = spaces[0]
        from scipy.ndimage import distance_transform_edt

        clear = distance_transform_edt(first[3].free)
        r, c = np.unravel_index(int(np.argmax(clear)), clear.shape)
        start = grid.centres(np.array([r]), np.array([c]))[0]
    return Discretization(
        locations=locations, location_z=location_z, location_storey=location_storey, world_from_cam=world_from_cam,
        location_index=location_index.astype(np.int64), yaw=yaw, candidate_world_from_marker=cT,
        candidate_normal=cand.normal, candidate_position=cand.position, candidate_storey=cand_storey,
        candidate_surface=cand.surface, candidate_part=cand.part,
        perimeter_arclength=cand.arclength, perimeter_length=float(cand.perimeter_length),
        occupancy=np.stack([t[3].occupancy for t in spaces]), planned_storeys=np.asarray(slots, np.int64),
        grid_origin=np.array([grid.x0, grid.y0]), grid_resolution=float(grid.res),
        storeys=np.asarray(storeys, dtype=float), start=np.asarray(start, dtype=float), summary=summary)


def _removed_words(removed: dict, tag_size: float) -> str:
    """``"4 on glass + 3 on doors + ..."`` for the rules that removed spots (``"none removed"``)."""
    parts = [f"{removed[rule]} {rule_words(rule, tag_size)}" for rule in RULES if removed.get(rule)]
    return " + ".join(parts) or "none removed"


def candidate_arithmetic(summary: dict, spacing: float, tag_size: float, candidates: int) -> str:
    """One line whose numbers add up: the wall spots ``spacing`` metres apart, those each rule
    removed and those that pass; then the candidates as those that pass, less the ones crowded
    out, plus the spots found beside removed ones (from a discretization's ``summary``)."""
    removed = summary.get("candidates_removed", {})
    spots, passed = summary.get("wall_spots", 0), summary.get("wall_spots_pass", 0)
    crowded, added = summary.get("candidates_crowded", 0), summary.get("candidates_added", 0)
    rules = [f"{removed[rule]} {rule_words(rule, tag_size)}" for rule in RULES if removed.get(rule)]
    line = f"{spots} wall spots {spacing:g} m apart = " + " + ".join(rules + [f"{passed} that pass"])
    line += f"; candidates = those {passed}"
    if crowded:
        line += f" - {crowded} crowded out"
    return line + f" + {added} found beside removed spots by moving along the wall = {candidates}"


def _drop_outdoors(rc: RayCaster, grid: Grid, space: StoreySpace, s: int, eye: float,
                   cfg: DiscretizeConfig) -> StoreySpace:
    """``space`` without its regions open to the outside (``max_open_fraction``), logged."""
    lab, frac, area = open_fractions(rc, grid, space.free, eye, reach=cfg.open_reach)
    drop = np.flatnonzero(frac > cfg.max_open_fraction)
    drop = drop[drop > 0]
    for i in range(1, len(frac)):
        log.debug("discretize: storey %d: free region %d, %.1f m^2: %.0f %% of eye-level rays leave the model",
                  s, i, area[i], 100 * frac[i])
    if len(drop) == 0:
        return space
    for i in drop:
        rr, cc = np.nonzero(lab == i)
        centre = grid.centres(np.array([rr.mean()]), np.array([cc.mean()]))[0]
        log.info("discretize: storey %d: a free region of %.1f m^2 around (%.1f, %.1f) is outdoors (%.0f %% of its "
                 "eye-level views hit nothing within %.0f m: under eaves, a porch, a balcony); no cameras there "
                 "(--keep-outdoors, or --start X,Y inside it, keeps it)", s, area[i], centre[0], centre[1], 100 * frac[i], cfg.open_reach)
    out = np.isin(lab, drop)
    free = space.free & ~out
    occupancy = space.occupancy.copy()
    occupancy[out] = -1
    return StoreySpace(free, occupancy, space.unreached, float(free.sum() * grid.res ** 2))


def _check_start(start: np.ndarray, grid: Grid, per_storey: list, cfg: DiscretizeConfig) -> None:
    """UserError when ``start`` is off every planned storey's floor or inside an obstacle."""
    from scipy.ndimage import distance_transform_edt

    txt = f"{start[0]:g},{start[1]:g}"
    r, c, inside = grid.cell(start[None])
    on_floor = [t for t in per_storey if inside[0] and t[2][r[0], c[0]]]
    if not on_floor:
        near = [t for t in per_storey if inside[0] and t[2].any()
                and distance_transform_edt(~t[2])[r[0], c[0]] * grid.res <= 1.0]
        if near:  # floor all around: furniture or a wall stands there
            z = near[0][1].floor_z + cfg.height
            raise UserError(f"--start {txt} is inside an obstacle (wall or furniture) at z={z:.2f} m; "
                            "pick a point in open floor space")
        raise UserError(f"--start {txt} is outside the model (no floor below it on the planned storey(s)); "
                        "pick a point in open floor space")

    for _, _floor, support, obstacle in on_floor:
        free0 = support & ~obstacle
        if free0[r[0], c[0]] and distance_transform_edt(free0)[r[0], c[0]] * grid.res >= min(cfg.passage_radius, 0.15):
            return
    z = on_floor[0][1].floor_z + cfg.height
    raise UserError(f"--start {txt} is inside an obstacle (wall or furniture) at z={z:.2f} m; "
                    "pick a point in open floor space")


def _storey_report(s: int, floor_z: float, grid: Grid, open_floor: np.ndarray, space, xy: np.ndarray, n_cand: int,
                   cfg: DiscretizeConfig) -> dict:
    """Log what was found on one storey and return it as a dict (for ``summary``)."""
    from scipy.ndimage import distance_transform_edt

    cell_area = grid.res ** 2
    floor_area = float(open_floor.sum() * cell_area)
    covered_area = 0.0
    if len(xy):
        at = np.zeros(grid.shape, bool)
        r, c, _ = grid.cell(xy)
        at[r, c] = True
        near = distance_transform_edt(~at) * grid.res <= cfg.clearance + cfg.grid_spacing
        covered_area = float((open_floor & near).sum() * cell_area)
    log.info("discretize: storey %d (floor %.2f m, eye level %.2f m): open floor %.1f m^2, free region %.1f m^2, "
             "%d camera locations (covering %.1f m^2), %d candidates", s, floor_z, floor_z + cfg.height, floor_area,
             space.free_area, len(xy), covered_area, n_cand)
    for area, centre in space.unreached[:10]:
        log.info("discretize: storey %d: a floor region of %.1f m^2 around (%.1f, %.1f) has no camera location "
                 "(reached only through a gap narrower than %.1f m%s)", s, area, centre[0], centre[1],
                 2 * cfg.passage_radius, ", or not connected to --start" if cfg.start is not None else "")
    if len(space.unreached) > 10:
        log.info("discretize: storey %d: %d more such regions", s, len(space.unreached) - 10)
    if floor_area > 0 and covered_area < 0.5 * floor_area:
        log.warning("discretize: storey %d: camera locations cover only %.0f %% of its %.1f m^2 of open floor; "
                    "check the log above for unreached regions, --start, --clearance and --grid-spacing",
                    s, 100 * covered_area / floor_area, floor_area)
    return {"storey": s, "floor_z": floor_z, "open_floor_m2": floor_area, "free_m2": space.free_area,
            "covered_m2": covered_area, "locations": int(len(xy)), "candidates": n_cand,
            "unreached": [{"area_m2": a, "centre": [float(v) for v in c]} for a, c in space.unreached]}


def discretize_key(scene, config: DiscretizeConfig, tag_size: float) -> str:
    """The discretize stage's cache key: the scene (geometry; the parts' names and glass, which
    decide the wall spots that may carry a tag), ``config`` and ``tag_size``."""
    labels = [(p.name, tuple(p.names), bool(p.transparent)) for p in scene.parts]
    return cache.hash_of("discretize-v4", cache.scene_hash(scene), labels, config.cache_view(tag_size))


def run_discretize(scene, config: DiscretizeConfig, tag_size: float, run_dir: Path,
                   timings: dict) -> tuple[Discretization, str]:
    """The discretize stage of a run folder: ``run_dir/discretization.npz``, reused while the
    scene (geometry, part names, glass), ``config`` and ``tag_size`` (the placement's
    black-square edge, metres: the tag that must fit flat on a wall) are unchanged.

    Returns:
        (the discretization, the stage's cache key, which the later stages' keys include).
    """
    key = discretize_key(scene, config, tag_size)
    disc = cached("discretize", run_dir / "discretization.npz", key, lambda: discretize(scene, config, tag_size),
                  save_discretization, load_discretization, timings)
    log.info("discretize: %d camera locations x %d yaws = %d poses, %d candidate marker poses",
             len(disc.locations), config.num_yaws, len(disc.world_from_cam), len(disc.candidate_world_from_marker))
    return disc, key
