"""A finished plan run folder read back: its scene, configuration and markers.

``plan`` leaves ``config.json`` (the resolved :class:`~markerplace.plan.config.PlanConfig`, the
scene argument, ``scene_options`` = ``up``/``unit_scale``/``seed`` and the ``--existing``
markers) and ``placement.json`` (the placed markers) in its folder; ``export`` and ``check``
rebuild the run from them. Positions in both files are in the user's frame (z up, metres, the
file's coordinates; :mod:`markerplace.scene.worldframe`).
"""

from __future__ import annotations

import logging
from dataclasses import MISSING, dataclass, fields, is_dataclass, replace
from pathlib import Path

import numpy as np

from markerplace.config_file import upgrade_legacy
from markerplace.errors import UserError
from markerplace.jsonfile import read_json
from markerplace.markers import Marker, check_markers_on_walls, marker_from_json
from markerplace.plan.config import PlanConfig
from markerplace.plan.discretize.artifact import load as load_discretization
from markerplace.plan.discretize.stage import discretize_key
from markerplace.runtime import cache, run_folder
from markerplace.runtime.run_lock import lock_for_reading
from markerplace.scene.spec import SceneSpec
from markerplace.scene.worldframe import markers_to_internal, points_to_internal, world_offset

log = logging.getLogger(__name__)

__all__ = ["FRAMES_SCENE_PREFIX", "PlanFolder", "read_plan_folder", "config_from_dict"]

FRAMES_SCENE_PREFIX = "frames:"
"""``config.json``'s ``scene`` of a plan made from RGB-D frames (``plan --frames``) starts so."""


def _tuples(v):
    return tuple(_tuples(x) for x in v) if isinstance(v, list) else v


def config_from_dict(cls, d: dict):
    """Rebuild the frozen dataclass ``cls`` (nested configs included) from its
    :func:`~markerplace.runtime.cache.config_dict`; keys it does not know are ignored, missing
    ones keep their defaults, JSON lists become tuples."""
    kwargs = {}
    for f in fields(cls):
        if f.name not in d:
            continue
        default = f.default if f.default is not MISSING else (
            f.default_factory() if f.default_factory is not MISSING else None)
        value = d[f.name]
        if is_dataclass(default) and isinstance(value, dict):
            value = config_from_dict(type(default), value)
        kwargs[f.name] = _tuples(value)
    return cls(**kwargs)


@dataclass(frozen=True, eq=False)
class PlanFolder:
    """A plan run folder.

    Attributes:
        path: the folder.
        scene: the scene argument of the run (built-in name or mesh path).
        scene_options: ``up``, ``unit_scale``, ``seed`` of the scene argument ({} for folders
            made before they were recorded).
        config: the run's :class:`~markerplace.plan.config.PlanConfig` (``start`` in the user frame).
        markers: placed markers in placement order, user frame (poses rounded to 1e-6 as
            placement.json stores them).
        records: placement.json's marker records.
        existing: the run's ``--existing`` markers, user frame.
        where: the run's ``--where`` file as it read it (a GeoJSON document,
            :mod:`markerplace.plan.where`), or None.
    """

    path: Path
    scene: str
    scene_options: dict
    config: object
    markers: list
    records: list
    existing: list
    where: dict | None = None

    @property
    def spec(self) -> SceneSpec:
        """How to load the run's scene."""
        o = self.scene_options
        return SceneSpec(self.scene, o.get("up"), o.get("unit_scale"), int(o.get("seed") or 0))

    def config_in_scene_frame(self, offset):
        """The config with ``discretize.start`` moved into the scene's internal frame (as
        ``plan`` ran it; ``offset`` from :func:`markerplace.scene.worldframe.world_offset`)."""
        start = self.config.discretize.start
        if start is None or not any(offset):
            return self.config
        moved = tuple(float(v) for v in points_to_internal(start, offset))
        return replace(self.config, discretize=replace(self.config.discretize, start=moved))


    def planned_on_candidates(self, candidate_world_from_marker: np.ndarray, offset) -> tuple[list, list[int]]:
        """The placed markers in the scene's internal frame on the poses of their candidates (the
        discretization's exact poses, not placement.json's rounded ones), and each one's
        candidate index.

        Args:
            candidate_world_from_marker: (C, 4, 4) the candidates of the folder's cached
                discretization (internal frame).
            offset: the scene's :func:`~markerplace.scene.worldframe.world_offset`.

        Raises:
            UserError: a marker is not on the candidate placement.json names (the folder's
                stages were computed for other settings).
        """
        cands = np.asarray(candidate_world_from_marker, float)
        internal = markers_to_internal(self.markers, offset)
        indices = [int(r.get("candidate_index", -1)) for r in self.records]
        for m, c in zip(internal, indices):
            if not 0 <= c < len(cands) or np.abs(cands[c] - m.world_from_marker).max() > 1e-4:
                raise UserError(f"{self.path}: placement.json does not match the scene and settings of its "
                                f"config.json (tag {m.tag_id} is not on its candidate spot): one of them was edited "
                                "or comes from another run; re-run `markerplace plan` into the folder")
        return [Marker(m.tag_id, m.size, cands[c].copy(), m.family) for m, c in zip(internal, indices)], indices


    def check_scene(self, scene) -> None:
        """Refuse (one line) a folder whose placed tags do not belong to its config.json's scene
        and settings (``scene``, loaded from :attr:`spec`): config.json or placement.json edited,
        or from two runs. With the folder's cached discretization fresh for them, each tag must
        sit on one of its candidate spots; without (deleted, or made by another version or for
        another model file) each must hang on a wall of the scene
        (:func:`markerplace.markers.check_markers_on_walls`). ``export``, ``check`` and ``evaluate
        --plan`` call it before anything is written; the latter two then also check each tag's
        ``candidate_index`` on the stages they reuse (:meth:`planned_on_candidates`)."""
        offset = world_offset(scene)
        config = self.config_in_scene_frame(offset)
        key = discretize_key(scene, config.discretize, config.placement.tag_size)
        disc = cache.load_fresh(self.path / "discretization.npz", key, load_discretization)
        markers = markers_to_internal(self.markers, offset)
        if disc is None:
            try:
                check_markers_on_walls(scene, markers, "placement.json")
            except UserError as err:
                raise UserError(f"{self.path}: placement.json does not match the scene of its config.json ({err}): "
                                "one of them was edited or comes from another run; re-run `markerplace plan` into "
                                "the folder") from None
            return
        cands = np.asarray(disc.candidate_world_from_marker, float)  # all of them: candidate_index counts the seen
        for m in markers:
            if not len(cands) or np.abs(cands - m.world_from_marker).max(axis=(1, 2)).min() > 1e-4:
                raise UserError(f"{self.path}: placement.json does not match the scene and settings of its "
                                f"config.json (tag {m.tag_id} is on none of their candidate spots): one of them was "
                                "edited or comes from another run; re-run `markerplace plan` into the folder")


def _read_json(path: Path, what: str) -> dict:
    try:
        data = read_json(path)
    except UserError as err:
        raise UserError(f"{err}: {what}") from None
    if not isinstance(data, dict):
        raise UserError(f"{path} is not a JSON object: {what}")
    return data


def read_plan_folder(path: str | Path, option: str = "PLAN_DIR") -> PlanFolder:
    """Read a plan folder, holding a shared lock on it until the command ends
    (:func:`markerplace.runtime.run_lock.lock_for_reading`; released by
    :func:`markerplace.runtime.run_folder.close_all`). Raises :class:`UserError` (one line) for a
    missing folder, one a run is writing, a folder that is not a finished plan run, or damaged
    files (a number that is not finite included: :func:`markerplace.jsonfile.read_json`)."""
    path = Path(path)
    if not path.is_dir():
        raise UserError(f"{option} {str(path)!r} is not a folder: give the --out folder of a `markerplace plan` run")
    if run_folder.find(path) is None and (path / run_folder.MARKER).is_file():  # not this process's own run
        lock_for_reading(path / run_folder.LOCK, f"{option} {path}")  # shared: no plan rewrites it meanwhile
    missing = [n for n in ("config.json", "placement.json") if not (path / n).is_file()]
    if missing:
        raise UserError(f"{option} {str(path)!r} is not a plan folder: {' and '.join(missing)} missing "
                        "(run `markerplace plan ... --out` into it first)")
    rerun = "re-run `markerplace plan` into the folder"
    config_json = _read_json(path / "config.json", rerun)
    placement = _read_json(path / "placement.json", rerun)
    if "scene" not in config_json or not isinstance(placement.get("markers"), list):
        raise UserError(f"{path} was not written by `markerplace plan` (config.json has no scene or placement.json "
                        f"no markers): {rerun}")
    if str(config_json["scene"]).startswith(FRAMES_SCENE_PREFIX):
        raise UserError(f"{option} {str(path)!r} was planned from RGB-D frames (plan --frames); export, check and "
                        "evaluate --plan read plans made on a scene only (for now)")
    try:
        config = config_from_dict(PlanConfig, upgrade_legacy(config_json))  # older folders: flat discretize
        markers = [marker_from_json(r) for r in placement["markers"]]
        existing = [marker_from_json(r) for r in config_json.get("existing_markers", [])]
    except (UserError, TypeError, ValueError, KeyError) as err:
        raise UserError(f"{path}: config.json or placement.json is damaged ({err}): {rerun}") from None
    options = config_json.get("scene_options")
    if options is None:
        log.warning("%s was made by an older markerplace: its config.json does not record --up, --unit-scale or "
                    "--seed; assuming the defaults", path)
        options = {}
    where = config_json.get("where")
    if where is not None and not isinstance(where, dict):
        raise UserError(f"{path}: config.json's where is damaged (not a JSON object): {rerun}")
    return PlanFolder(path, str(config_json["scene"]), dict(options), config, markers, list(placement["markers"]),
                      existing, where)
