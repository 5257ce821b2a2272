"""``evaluate --plan PLAN_DIR``: an evaluation that starts from a finished plan folder.

The plan folder (:func:`markerplace.plan.folder.read_plan_folder`) gives the scene, the plan's
settings and its placement. The evaluation then

* runs with the plan's settings (:func:`start_from_plan`): a scene argument, ``--seed``,
  ``--up``, ``--unit-scale`` or a plan option that differs from the plan's is refused with one
  line (``--workers`` and ``--cluster`` only say where the work runs and are the command
  line's); ``--k`` defaults to the plan's k and may not exceed it;
* evaluates the plan's placement as its method's marker set (OMP's prefixes for the smaller
  budgets; a method placed per k is evaluated at the plan's k only), snapped onto the
  candidates of the cached discretization (:func:`plan_placement`);
* reuses the plan's cached stages (:func:`adopt_plan_stages`): discretization, observations,
  look-alikes, success models, and the marker-free map and VLAD codebook of a calibrated
  method, hard-linked into the evaluation's work folder (copied across file systems). The
  stages find them fresh when their keys match and compute nothing again; otherwise they are
  recomputed in the evaluation's folder as usual. The plan folder is only read.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from pathlib import Path

from markerplace.errors import UserError
from markerplace.plan.config import PlanConfig
from markerplace.plan.folder import PlanFolder, read_plan_folder
from markerplace.plan.place.methods import PLACEMENT_METHODS
from markerplace.plan.where import Where, load_where, parse_where
from markerplace.runtime import cache
from markerplace.scene.spec import SceneSpec
from markerplace.scene.worldframe import world_offset
from markerplace.settings import walk

log = logging.getLogger(__name__)

__all__ = ["PlanStart", "start_from_plan", "adopt_plan_stages", "plan_placement", "PLAN_STAGES", "CALIBRATION_CACHE"]

PLAN_STAGES = ("discretization.npz", "observations", "similarity.npz")
"""The plan folder's stage artifacts an evaluation reuses (into its ``plan/``)."""

CALIBRATION_CACHE = ("map_base/features", "map_base/in_view.npy", "vlad_codebook.npz", "offgrid_base/features",
                     "offgrid_base/in_view.npy")
"""The plan's ``calibration/`` artifacts an evaluation reuses (into its ``cache/``): the
marker-free map (the testbed's, same key), its codebook and the off-grid calibration images."""


@dataclass(frozen=True, eq=False)
class PlanStart:
    """What ``evaluate --plan`` runs with.

    Attributes:
        folder: the plan folder read back.
        scene_spec: the plan's scene.
        plan_config: the plan's settings (user frame), the command line's runtime, ``placement.k``
            = the largest evaluated budget.
        config: the evaluation's settings: budgets at most the plan's k, the plan's method among
            the methods, the seed the plan's scene seed.
        where: the plan's ``--where`` file (:mod:`markerplace.plan.where`), or None.
    """

    folder: PlanFolder
    scene_spec: SceneSpec
    plan_config: PlanConfig
    config: object
    where: Where | None = None


def _differs(given, planned) -> bool:
    return given != planned and not (isinstance(given, (int, float)) and isinstance(planned, (int, float))
                                     and float(given) == float(planned))


def _check_scene(folder: PlanFolder, scene: str | None, up, unit_scale, seed) -> None:
    where = f"the plan in {folder.path}"
    spec = folder.spec
    if scene is not None:  # its own or another: the plan gives the scene, one source only
        same = scene == spec.spec or Path(scene).resolve() == Path(spec.spec).resolve()
        raise UserError(f"scene {scene!r} {'is already' if same else 'is not'} the scene of {where} ({spec.spec!r}): "
                        "give a scene or --plan, not both (--plan brings its scene)")
    for flag, given, planned in (("--up", up, spec.up), ("--unit-scale", unit_scale, spec.unit_scale),
                                 ("--seed", seed, spec.seed)):
        if given is not None and _differs(given, planned):
            raise UserError(f"{flag} {given} differs from {where} ({planned}): leave it out with --plan")


def start_from_plan(plan_dir: str | Path, plan_values: dict, config, *, ks_given: bool, scene: str | None = None,
                    up: str | None = None, unit_scale: float | None = None, seed: int | None = None,
                    where: str | None = None) -> PlanStart:
    """Read ``plan_dir`` and settle the evaluation's settings (see the module docstring).

    Args:
        plan_dir: a finished ``plan`` folder.
        plan_values: the plan options given on the command line (config path -> value,
            :func:`markerplace.settings.values_from_args` of a parser without defaults).
        config: the :class:`~markerplace.testbed.config.EvaluateConfig` of the command line.
        ks_given: ``--k`` was given (else the plan's k is the one budget).
        scene, up, unit_scale, seed: the scene arguments given (None: left out).
        where: the ``--where`` file given (None: left out); the plan's own where file (recorded
            in its config.json) is used, and a given one must be the same.

    Raises:
        UserError: one line, for a folder that is no finished plan or an option that
            conflicts with the plan.
    """
    folder = read_plan_folder(plan_dir, "--plan")
    _check_scene(folder, scene, up, unit_scale, seed)
    planned = folder.config
    leaves = {leaf.path: leaf for leaf in walk(planned)}
    for path, value in plan_values.items():
        leaf = leaves.get(path)
        if path.startswith("runtime.") or leaf is None or not _differs(value, leaf.value):
            continue
        raise UserError(f"{leaf.setting.flag or path} {value} conflicts with the plan's {leaf.value} "
                        f"({folder.path / 'config.json'}): leave it out, evaluate --plan uses the plan's settings")
    planned_where = None if folder.where is None else parse_where(folder.where, f"--plan {folder.path}: config.json's where")
    if where is not None and (planned_where is None or load_where(where).doc != planned_where.doc):
        raise UserError(f"--where {where} is not the where file of the plan in {folder.path} "
                        f"({'it has none' if planned_where is None else 'it has another'}): leave it out, "
                        "evaluate --plan uses the plan's")
    if folder.existing:
        raise UserError(f"--plan {folder.path} was planned around --existing markers, which evaluate does not "
                        "draw: evaluate its placement.json with --placements instead")
    method, k = planned.placement.method, int(planned.placement.k)
    cls = PLACEMENT_METHODS.get(method)
    if cls is None or cls.randomized:
        raise UserError(f"--plan {folder.path} was placed with {method!r}, a random baseline that evaluate "
                        "draws itself: evaluate its placement.json with --placements instead")
    study = config.study
    ks = tuple(study.ks) if ks_given else (k,)
    if max(ks) > k:
        raise UserError(f"--k {max(ks)} is more than the {k} tags the plan in {folder.path} placed: give budgets "
                        f"up to {k}, or leave --k out")
    if not cls.nested and set(ks) != {k}:
        raise UserError(f"--k: {method} places each budget on its own, and the plan placed {k} tags: give --k {k} "
                        "or leave --k out")
    methods = tuple(study.methods) + ((method,) if method not in study.methods else ())
    runtime = replace(PlanConfig().runtime, **{p.split(".", 1)[1]: v for p, v in plan_values.items()
                                              if p.startswith("runtime.")})
    plan_config = replace(planned, runtime=runtime, placement=replace(planned.placement, k=max(ks)))
    config = replace(config, seed=folder.spec.seed, study=replace(study, ks=ks, methods=methods))
    log.info("evaluate --plan %s: scene %s, %s placement of %d tags, budgets %s", folder.path, folder.scene, method,
             len(folder.markers), ",".join(map(str, ks)))
    return PlanStart(folder, folder.spec, plan_config, config, planned_where)


def adopt_plan_stages(folder: PlanFolder, plan_dir: Path, cache_dir: Path) -> list[str]:
    """Hard-link the plan folder's fresh stage artifacts (:data:`PLAN_STAGES` into
    ``plan_dir``, :data:`CALIBRATION_CACHE` and ``success_model_*.json`` too) into the
    evaluation's work folder (:func:`markerplace.runtime.cache.adopt`); returns the names
    adopted. Whether a stage reuses one is its key's decision."""
    calibration = {folder.path / "calibration" / name: Path(cache_dir) / name for name in CALIBRATION_CACHE}
    adopted = [f"calibration/{src.relative_to(folder.path / 'calibration')}" for src, dst in calibration.items()
               if cache.adopt(src, dst)]
    names = [*PLAN_STAGES, *(p.name for p in sorted(folder.path.glob("success_model_*.json")))]
    adopted += [name for name in names if cache.adopt(folder.path / name, Path(plan_dir) / name, calibration)]
    log.info("evaluate --plan: reusing the plan's %s", ", ".join(adopted) or "nothing (no fresh stage)")
    return adopted


def plan_placement(folder: PlanFolder, data, scene) -> dict[str, list]:
    """{the plan's method: its markers} in the scene's internal frame, on the exact poses of
    the candidates of ``data`` (the prepared plan), for
    :func:`~markerplace.simulation.marker_sets.build_placements`."""
    markers, _ = folder.planned_on_candidates(data.disc.candidate_world_from_marker, world_offset(scene))
    return {folder.config.placement.method: markers}
