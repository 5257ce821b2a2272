"""Where the tags went, from photos: ``check --photos`` measures the installed tags for
:func:`markerplace.plan.installed_vs_plan.compare`.

1. the tags in the photos (:mod:`markerplace.localization.photo_tags`) are solved together with
   the cameras (:func:`markerplace.localization.tag_bundle.solve_tags`), per set of photos
   linked by shared tags;
2. each such set is put on the model by the tags that agree with the plan (or the
   ``--existing`` markers) within the check's tolerance (:func:`markerplace.localization.
   tag_anchor.anchor_to_plan`); a set with fewer than two agreeing tags is not placed and its
   tags are not measured;
3. a tag is *measured* when at least :data:`MIN_PHOTOS` photos kept a detection of it and its
   pose's standard deviation (from the factor graph's marginals, worst direction, relative to
   the anchoring tags, each held to the fit's RMS: :data:`ANCHOR_SIGMA_M`; an anchoring tag's
   relative to the others) is within the check's
   tolerance (metres and degrees); otherwise it is ``not measured``, never guessed;
4. a planned spot whose tag no photo measured is ``missing`` only when at least
   :data:`MIN_PHOTOS` placed photos looked at it (the spot's four corners in the image, facing
   the camera, at least :data:`MIN_EDGE_PX` pixels across, nothing in front of it in the model)
   and none of them detected any tag there; else ``not measured`` (a tag another photo could not
   measure may hang there), with a line saying to photograph it.

Everything is in the internal frame (:mod:`markerplace.scene.worldframe`), metres.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import numpy as np

from markerplace.errors import UserError
from markerplace.geometry import marker_corners_local
from markerplace.localization.tag_anchor import anchor_to_plan
from markerplace.localization.tag_bundle import Detection, solve_tags
from markerplace.markers import Marker

log = logging.getLogger(__name__)

__all__ = ["PhotoTag", "PhotoSurvey", "survey", "guidance", "MIN_PHOTOS"]

MIN_PHOTOS = 2
"""Photos that must see a tag for it to be measured (and look at a spot for it to be missing)."""
MIN_EDGE_PX = 20.0
"""A spot counts as looked at when its tag would span at least this many pixels (the detector
finds tags of about 10 px and up; twice that is a safe margin)."""
ANCHOR_SIGMA_M = 0.005
"""The frame is known to the anchoring tags' fit RMS, at least this (metres; their rotation to
that over the tag size, radians): the gauge of the uncertainties (the anchoring tags' own
uncertainty is about this)."""
MAX_VIEW_DEG = 70.0
OCCUPIED_SCALE = 1.5
"""A detection whose centre falls in the spot's image quad scaled by this about its centre is a
tag at the spot (in the wall's plane: foreshortened as the spot is)."""
"""... and the camera is within this angle of the tag's normal."""


@dataclass
class PhotoTag:
    """One tag id seen in the photos.

    Attributes:
        tag_id: its id.
        world_from_marker: (4, 4) recovered pose (internal frame); None when its photos were
            not placed on the model.
        position_std_m, rotation_std_deg: standard deviations (worst direction); None when not placed.
        photos: photos whose detection of it was kept (a tag detected but dropped as an
            outlier everywhere counts the photos that detected it).
        best: (photo index, (4, 2) corners) of its largest detection.
        measured: see the module docstring (3.).
        reason: why not measured ("" when measured).
    """

    tag_id: int
    world_from_marker: np.ndarray | None
    position_std_m: float | None
    rotation_std_deg: float | None
    photos: int
    best: tuple
    measured: bool
    reason: str = ""


@dataclass
class PhotoSurvey:
    """What the photos say.

    Attributes:
        tags: {tag_id: :class:`PhotoTag`}.
        cameras: {photo index: (4, 4) world_from_cam (internal frame)} of the placed photos.
        anchors: per placed set of photos, the ids of the tags that anchor it.
        looked_at: {planned tag id: placed photos that looked at its spot and saw no tag there;
            -1 when one saw a tag there}, for the spots whose tag was not measured.
        unplaced_photos: photos with tags whose set could not be placed; ``no_tags``: photos
            without any tag.
        rms_px: RMS corner reprojection error of the solve, pixels.
    """

    tags: dict
    cameras: dict
    anchors: list
    looked_at: dict
    unplaced_photos: list = field(default_factory=list)
    no_tags: list = field(default_factory=list)
    rms_px: float = 0.0

    def measured_markers(self, size_of) -> list[Marker]:
        """The measured tags as :class:`~markerplace.markers.Marker` s (internal frame), by id;
        ``size_of(tag_id)`` gives their size (metres)."""
        return [Marker(t, size_of(t), self.tags[t].world_from_marker) for t in sorted(self.tags) if self.tags[t].measured]


def _area(corners: np.ndarray) -> float:
    """Area of a quadrilateral's (4, 2) corners, pixels^2 (half the cross product of its diagonals)."""
    a, b = corners[2] - corners[0], corners[3] - corners[1]
    return 0.5 * abs(float(a[0] * b[1] - a[1] * b[0]))


def _in_view(cam: np.ndarray, K: np.ndarray, wh: tuple, T: np.ndarray, size: float) -> np.ndarray | None:
    """The points to check for a clear line of sight ((5, 3): the tag's corners and centre) when
    the spot ``T`` is in the photo's view (facing it, inside the image, large enough), else None."""
    corners = marker_corners_local(size) @ T[:3, :3].T + T[:3, 3]
    to_cam = cam[:3, 3] - T[:3, 3]
    dist = float(np.linalg.norm(to_cam))
    if dist < 1e-6 or np.degrees(np.arccos(np.clip(to_cam @ T[:3, 2] / dist, -1, 1))) > MAX_VIEW_DEG:
        return None
    q = (corners - cam[:3, 3]) @ cam[:3, :3]
    if np.any(q[:, 2] <= 0.05):
        return None
    uv = (q @ K.T)[:, :2] / q[:, 2:]
    if np.any(uv < 0) or np.any(uv[:, 0] > wh[0] - 1) or np.any(uv[:, 1] > wh[1] - 1):
        return None
    if np.linalg.norm(uv[1] - uv[0]) < MIN_EDGE_PX or np.linalg.norm(uv[3] - uv[0]) < MIN_EDGE_PX:
        return None
    return np.vstack([corners, T[:3, 3][None]]), uv


def _looked_at(spots: list, cameras: dict, Ks: dict, sizes: dict, caster, detections: list) -> dict:
    """{tag id: photos in ``cameras`` that looked at its planned spot and saw no tag there
    (module docstring, 4.), or -1 when a photo saw some tag there}; ``spots``: [(tag id, (4, 4)
    world_from_marker)]; ``detections``: per photo its detections. One batch of rays for all."""
    origins, targets, owner, occupied = [], [], [], set()
    for t, T in spots:
        for p, C in cameras.items():
            seen = _in_view(C, Ks[p][0], Ks[p][1], T, sizes[t])
            if seen is None:
                continue
            pts, uv = seen
            quad = (uv.mean(axis=0) + OCCUPIED_SCALE * (uv - uv.mean(axis=0))).astype(np.float32)
            if any(cv2.pointPolygonTest(quad, tuple(float(v) for v in np.asarray(d.corners).mean(axis=0)), False) >= 0
                   for d in detections[p]):
                occupied.add(t)  # a tag is there in this photo: whatever it is, the spot is not empty
            origins.append(np.repeat(C[None, :3, 3], len(pts), axis=0))
            targets.append(pts)
            owner += [(t, p)] * len(pts)
    out = {t: -1 if t in occupied else 0 for t, _ in spots}
    if not owner:
        return out
    o, q = np.vstack(origins), np.vstack(targets)
    n = np.linalg.norm(q - o, axis=1)
    hit, _ = caster.first_hits(o, (q - o) / n[:, None], n + 1.0)
    clear = {}
    for k, key in enumerate(owner):
        clear[key] = clear.get(key, True) and bool(hit[k] >= n[k] - 0.05)
    for (t, _), ok in clear.items():
        if t not in occupied:
            out[t] += int(ok)
    return out


def survey(detections: list, intrinsics: list, planned: list, existing: list, default_size: float, *,
           tol_m: float, tol_deg: float, caster) -> PhotoSurvey:
    """Steps 1-4 of the module docstring.

    Args:
        detections: per photo its :class:`~markerplace.localization.tags.TagDetection` s.
        intrinsics: per photo its :class:`~markerplace.geometry.Intrinsics`.
        planned, existing: the plan's markers and the ``--existing`` ones (internal frame).
        default_size: the plan's tag size (metres), for tags it did not plan.
        tol_m, tol_deg: the check's tolerance (anchoring and measurement).
        caster: :class:`~markerplace.scene.raycast.RayCaster` of the scene (internal frame).

    Raises:
        UserError: no tag in any photo; no set of photos with two tags as planned.
    """
    dets = [Detection(p, d.tag_id, np.asarray(d.corners, float)) for p, ds in enumerate(detections) for d in ds]
    if not dets:
        raise UserError(f"no tag36h11 tag found in any of the {len(detections)} photos: photograph the tags "
                        "(each at least 20 pixels across, in focus)")
    known = {int(m.tag_id): m for m in (*existing, *planned)}
    sizes = {d.tag_id: float(known[d.tag_id].size) if d.tag_id in known else float(default_size) for d in dets}
    Ks = {p: intr.K for p, intr in enumerate(intrinsics)}
    sol = solve_tags(dets, Ks, sizes)
    reference = {t: np.asarray(m.world_from_marker, float) for t, m in known.items()}
    anchors, tags, cameras, unplaced = [], {}, {}, set()
    for comp in sorted(set(sol.component.values())):
        ids = [t for t, c in sol.component.items() if c == comp]
        photos = [p for p, c in sol.photo_component.items() if c == comp]
        fit = anchor_to_plan({t: sol.tags[t] for t in ids}, reference, sizes, tol_m, tol_deg)
        if fit is None:
            unplaced.update(photos)
            continue
        anchors.append(list(fit.tags))
        sigma_m = max(fit.rms_m, ANCHOR_SIGMA_M)
        prior = {t: (sigma_m / max(sizes[t], 1e-3), sigma_m) for t in fit.tags}
        sol.cov.update(sol.covariances(comp, prior))
        for t in fit.tags:  # an anchoring tag's own: relative to the other anchoring tags
            sol.cov[t] = sol.covariances(comp, {u: p for u, p in prior.items() if u != t})[t]
        log.info("photos %s placed on the model by tags %s (corner RMS %.1f mm)", len(photos), list(fit.tags),
                 1000 * fit.rms_m)
        for p in photos:
            cameras[p] = fit.model_from_solver @ sol.cameras[p]
        for t in ids:
            tags[t] = fit.model_from_solver @ sol.tags[t]
    if not anchors:
        agree = sorted(set(sol.tags) & set(known))
        raise UserError(f"the photos do not show two tags hung as planned (within {100 * tol_m:.0f} cm and "
                        f"{tol_deg:.0f} deg) in one set of photos linked by shared tags (planned tags seen: "
                        f"{agree or 'none'}): photograph two or more tags that hang where the plan put them, "
                        "each with its neighbours, so the photos can be placed on the model")
    out = {}
    for t in sorted({d.tag_id for d in dets}):
        mine = [d for d in dets if d.tag_id == t]
        best = max(mine, key=lambda d: _area(d.corners))
        n_photos = len(sol.photos_seen.get(t, [])) or len({d.photo for d in mine})
        if t not in tags:
            out[t] = PhotoTag(t, None, None, None, n_photos, (best.photo, best.corners), False,
                              "its photos share no tag with the photos placed on the model" if t in sol.tags else
                              "its detections disagree with the other photos")
            continue
        pos, rot = sol.std(t)
        reason = ""
        if n_photos < MIN_PHOTOS:
            reason = f"seen in {n_photos} photo; take one more from another angle"
        elif pos > tol_m or rot > tol_deg:
            reason = (f"uncertain by {100 * pos:.1f} cm / {rot:.1f} deg (over {100 * tol_m:.0f} cm / {tol_deg:.0f} "
                      "deg): take closer photos from other angles")
        out[t] = PhotoTag(t, tags[t], pos, rot, n_photos, (best.photo, best.corners), not reason, reason)
    spots = [(int(m.tag_id), np.asarray(m.world_from_marker, float)) for m in planned
             if not (int(m.tag_id) in out and out[int(m.tag_id)].measured)]  # only these need it
    views = {p: (Ks[p], (intrinsics[p].width, intrinsics[p].height)) for p in cameras}
    looked = _looked_at(spots, cameras, views, {t: float(known[t].size) for t, _ in spots}, caster, detections)
    no_tags = [p for p, ds in enumerate(detections) if not ds]
    return PhotoSurvey(out, cameras, anchors, looked, sorted(unplaced), no_tags, sol.rms_px)


def guidance(s: PhotoSurvey, planned: list) -> list[str]:
    """Lines for the person walking with the phone: planned tags no photo saw, tags that need
    more views, photos not placed."""
    lines = []
    planned_ids = [int(m.tag_id) for m in planned]
    unseen = [t for t in planned_ids if t not in s.tags and 0 <= s.looked_at.get(t, 0) < MIN_PHOTOS]
    other = [t for t in planned_ids if t not in s.tags and s.looked_at.get(t, 0) < 0]
    if other:
        lines.append(f"the spot(s) of planned tag(s) {', '.join(map(str, other))} show another tag that could not be "
                     "measured: photograph it from closer, with a neighbouring tag in view")
    if unseen:
        lines.append(f"no photo saw planned tag(s) {', '.join(map(str, unseen))}: photograph their spots "
                     f"(at least {MIN_PHOTOS} photos each, with a neighbouring tag in view) and run check again")
    for t, pt in sorted(s.tags.items()):
        if not pt.measured:
            lines.append(f"tag {t} needs more views: {pt.reason}")
    if s.unplaced_photos:
        lines.append(f"{len(s.unplaced_photos)} photo(s) could not be placed on the model (their tags are not linked "
                     "to two tags hung as planned): add photos that show their tags together with such tags")
    return lines
