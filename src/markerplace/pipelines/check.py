"""``markerplace check PLAN_DIR --installed installed.json`` or ``--photos DIR``: the tags as a
person measured them on the walls, or as photos of them show them
(:mod:`markerplace.plan.photo_check`), compared with the plan
(:mod:`markerplace.plan.installed_vs_plan`), and what it found written
(:mod:`markerplace.report.check_outputs`). The plan folder's cached stages are reused
(:func:`markerplace.pipelines.plan.prepare`); ``check.html`` shows it in 3D
(:mod:`markerplace.report.check_page`)."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.localization.photo_tags import detect_photos, draw_detection
from markerplace.markers import check_markers_on_walls, load_markers
from markerplace.pipelines.plan import prepare
from markerplace.plan import installed_vs_plan as check
from markerplace.plan import photo_check
from markerplace.plan.folder import read_plan_folder
from markerplace.report.check_outputs import write_check_outputs
from markerplace.report.check_page import write_check_page
from markerplace.report.tagmaps.write import tag_map_patterns
from markerplace.runtime import run_folder
from markerplace.runtime.claims import refuse_foreign
from markerplace.runtime.executor import RuntimeConfig, make_executor
from markerplace.scan.photos import list_photos
from markerplace.scene.raycast import RayCaster
from markerplace.scene.worldframe import markers_to_internal, markers_to_user, world_offset

log = logging.getLogger(__name__)

__all__ = ["load_installed", "run_check", "CHECK_OUTPUTS"]

CHECK_OUTPUTS = ("check.json", "check.csv", "check_map.png", "check.html", *tag_map_patterns(), "photo_cache/*.json",
                 "photos/tag_*.png")
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


def run_check(plan_dir: str | Path, installed_path: str | Path | None = None, out_dir: str | Path | None = None, *,
              radius: float | None = None, runtime: RuntimeConfig = RuntimeConfig(), progress: bool = True,
              adopt: bool = False, photos: str | Path | None = None,
              intrinsics: str | Path | None = None) -> tuple[Path, str]:
    """Compare the measured tags (``installed_path``) or the tags the ``photos`` show (a folder;
    ``intrinsics``: their camera when EXIF has none) with the plan in ``plan_dir``; write the
    outputs to ``out_dir`` (default ``plan_dir/check``). Both are run folders (locked; ``adopt``:
    one markerplace did not make is used, its files left alone;
    :mod:`markerplace.runtime.run_folder`). Returns the folder and the text summary printed by
    the CLI. ``runtime``: where the depth renders run (``--workers``)."""
    if (installed_path is None) == (photos is None):
        raise UserError("check needs either --installed FILE.json (tags measured by hand) or --photos DIR (photos of "
                        "the tags), not both")
    folder = read_plan_folder(plan_dir)
    size = folder.config.placement.tag_size
    installed_user = load_installed(installed_path, size) if photos is None else None
    out = Path(out_dir) if out_dir is not None else folder.path / "check"
    shots = list_photos(photos, intrinsics, exclude=out) if photos is not None else None
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
    existing = markers_to_internal(folder.existing, offset)
    survey = None
    if shots is not None:
        planned_internal = markers_to_internal(folder.markers, offset)
        survey = _survey(shots, out, scene, planned_internal, existing, size, progress)
        ex_ids = {int(m.tag_id) for m in existing}
        installed = [m for m in survey.measured_markers(lambda t: _size_of(t, planned_internal, size))
                     if int(m.tag_id) not in ex_ids]
        installed_user = markers_to_user(installed, offset)
    else:
        installed = markers_to_internal(installed_user, offset)
    _warn_off_wall(scene, installed)
    ex = make_executor(runtime)
    try:
        data = prepare(spec, config, folder.path, existing=existing, progress=progress, executor=ex)
        planned, cands = folder.planned_on_candidates(data.disc.candidate_world_from_marker, offset)
        covs = check.installed_coverages(spec, data.disc.world_from_cam, installed, config, ex)
    finally:
        ex.close()
    unmeasured = () if survey is None else _unmeasured(survey, planned)
    result = check.compare(data, planned, cands, installed, covs,
                           radius=check.MATCH_RADIUS_M if radius is None else radius, unmeasured=unmeasured)
    if survey is not None:
        _annotate(result, survey, shots, out)
    text = write_check_outputs(out, result, offset, folder, installed_user,
                               photos=None if survey is None else _photo_summary(survey, shots, planned))
    write_check_page(out, scene, result, planned, installed,
                     camera_path=None if survey is None else
                     np.array([T[:3, 3] for _, T in sorted(survey.cameras.items())]).reshape(-1, 3))
    return out, text


def _size_of(tag_id: int, planned, default: float) -> float:
    return next((float(m.size) for m in planned if int(m.tag_id) == tag_id), float(default))


def _survey(shots, out: Path, scene, planned, existing, size: float, progress: bool):
    """Detect (cached) and solve: the :class:`~markerplace.plan.photo_check.PhotoSurvey`."""
    run_folder.make_dirs(out / "photo_cache")
    dets, fresh = detect_photos(shots, out / "photo_cache", progress)
    log.info("%d photos: %d detected now, %d from the cache (%s)", len(shots), fresh, len(shots) - fresh,
             out / "photo_cache")
    return photo_check.survey(dets, [p.intrinsics for p in shots], planned, existing, size, tol_m=check.TOLERANCE_M,
                              tol_deg=check.TOLERANCE_DEG, caster=RayCaster(*scene.geometry()))


def _unmeasured(survey, planned) -> list[int]:
    """Planned ids whose spot the photos cannot call (not measured, not looked at enough)."""
    out = []
    for m in planned:
        t = int(m.tag_id)
        pt = survey.tags.get(t)
        if (pt is not None and not pt.measured) or (pt is None and survey.looked_at.get(t, 0) < photo_check.MIN_PHOTOS):
            out.append(t)
    return out


def _annotate(result, survey, shots, out: Path) -> None:
    """Per row the photo check's numbers and one photo of its tag with the detection drawn."""
    run_folder.make_dirs(out / "photos")
    for r in result.rows:
        t = r.installed_id if r.installed_id is not None else r.planned_id
        pt = survey.tags.get(t) if t is not None else None
        if pt is None:
            continue
        name = f"photos/tag_{t}.png"
        p, corners = pt.best
        draw_detection(shots[p], corners, t, out / name)
        r.measured = {"position_std_m": pt.position_std_m, "rotation_std_deg": pt.rotation_std_deg,
                      "photos": pt.photos, "photo": name, "photo_file": shots[p].name}


def _photo_summary(survey, shots, planned) -> dict:
    return {"photos": len(shots), "placed": len(survey.cameras), "without_tags": len(survey.no_tags),
            "not_placed": len(survey.unplaced_photos), "anchors": survey.anchors,
            "reprojection_rms_px": survey.rms_px, "guidance": photo_check.guidance(survey, planned)}
