"""``markerplace check PLAN_DIR --installed installed.json``: the tags as a person measured them
on the walls, compared with the plan (:mod:`markerplace.plan.installed_vs_plan`), and what it found written
(:mod:`markerplace.report.check_outputs`). The plan folder's cached stages are reused
(:func:`markerplace.pipelines.plan.prepare`); ``check.html`` shows it in 3D
(:mod:`markerplace.report.check_page`)."""

from __future__ import annotations

import logging
import os
from pathlib import Path

from markerplace.errors import UserError
from markerplace.markers import check_markers_on_walls, load_markers
from markerplace.pipelines.plan import prepare
from markerplace.plan import installed_vs_plan as check
from markerplace.plan.folder import read_plan_folder
from markerplace.report.check_outputs import write_check_outputs
from markerplace.report.check_page import write_check_page
from markerplace.report.tagmaps.write import tag_map_patterns
from markerplace.runtime import run_folder
from markerplace.runtime.claims import refuse_foreign
from markerplace.runtime.executor import RuntimeConfig, make_executor
from markerplace.scene.worldframe import markers_to_internal, world_offset

log = logging.getLogger(__name__)

__all__ = ["load_installed", "run_check", "CHECK_OUTPUTS"]

CHECK_OUTPUTS = ("check.json", "check.csv", "check_map.png", "check.html", *tag_map_patterns())
"""What ``check`` writes into its ``--out`` folder (see :data:`markerplace.pipelines.plan.PLAN_OUTPUTS`)."""


def load_installed(path: str | Path, default_size: float) -> list:
    """Installed markers (user frame) from placement.json's format or a plain list of
    ``{tag_id, position, normal[, size]}``; a missing size is the plan's tag size. The checks of
    :func:`markerplace.markers.load_markers` (JSON guards, integer tag36h11 ids listed once,
    finite rigid poses)."""

    return load_markers(path, "--installed", default_size=default_size)


def _warn_off_wall(scene, markers) -> None:

    for m in markers:
        try:
            check_markers_on_walls(scene, [m], "installed")
        except UserError as err:
            log.warning("%s (scored where it was measured)", err)


def run_check(plan_dir: str | Path, installed_path: str | Path, out_dir: str | Path | None = None, *,
              radius: float | None = None, runtime: RuntimeConfig = RuntimeConfig(), progress: bool = True,
              adopt: bool = False) -> tuple[Path, str]:
    """Compare the measured tags with the plan in ``plan_dir``; write the outputs to ``out_dir``
    (default ``plan_dir/check``). Both are run folders (locked; ``adopt``: one markerplace did
    not make is used, its files left alone; :mod:`markerplace.runtime.run_folder`). Returns the
    folder and the text summary printed by the CLI. ``runtime``: where the depth renders run
    (``--workers``)."""
    folder = read_plan_folder(plan_dir)
    installed_user = load_installed(installed_path, folder.config.placement.tag_size)
    out = Path(out_dir) if out_dir is not None else folder.path / "check"
    if os.path.realpath(out) == os.path.realpath(folder.path):
        raise UserError(f"--out {out} is the plan folder itself: check writes its own tagmaps/ (the tags as "
                        "installed) and would replace the plan's; give another folder (default PLAN_DIR/check)")
    run_folder.open_run_folder(folder.path, "check", adopt=adopt, option="PLAN_DIR")  # its caches may be rewritten
    run_folder.open_run_folder(out, "check", adopt=adopt)
    refuse_foreign(out, CHECK_OUTPUTS)  # before any work
    spec = folder.spec
    scene = spec.load()
    folder.check_scene(scene)  # placement.json on config.json's scene, before anything renders
    offset = world_offset(scene)
    config = folder.config_in_scene_frame(offset)
    installed = markers_to_internal(installed_user, offset)
    _warn_off_wall(scene, installed)
    existing = markers_to_internal(folder.existing, offset)
    ex = make_executor(runtime)
    try:
        data = prepare(spec, config, folder.path, existing=existing, progress=progress, executor=ex)
        planned, cands = folder.planned_on_candidates(data.disc.candidate_world_from_marker, offset)
        covs = check.installed_coverages(spec, data.disc.world_from_cam, installed, config, ex)
    finally:
        ex.close()
    result = check.compare(data, planned, cands, installed, covs,
                           radius=check.MATCH_RADIUS_M if radius is None else radius)
    text = write_check_outputs(out, result, offset, folder, installed_user)
    write_check_page(out, scene, result, planned, installed)
    return out, text
