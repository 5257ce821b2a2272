"""Camera poses and tag poses together from tag corners seen in photos: a GTSAM factor graph.

Unknowns: one ``Pose3`` per photo (``world_from_cam``, OpenCV camera: x right, y down, z
forward) and one per tag (``world_from_marker``, marker frame: x right, y up, z out of the
wall), in a frame of the solver's own (the first tag's, see below; :mod:`markerplace.
localization.tag_anchor` moves it onto the model). Measurements: the 4 detected corners of each
tag in each photo (pixels, the detector's order, :func:`markerplace.geometry.marker_corners_local`),
one 8-vector factor per detection (:class:`gtsam.CustomFactor` with analytic Jacobians: the
tag's known corners moved by the tag pose into the world, by the camera pose into the camera
and projected by the photo's pinhole ``K``), under a Huber loss on :data:`PIXEL_SIGMA` pixels,
so a misdetection weighs little. Tag sizes are known (the black square's edge, metres).

Initial values: each detection's camera-from-tag pose by IPPE square (``cv2.solvePnP``,
:func:`~markerplace.localization.tags.pose_from_tag`'s object points), chained outwards from the
tag seen in most photos over the detection with the largest image area. Photos and tags not
linked to that tag through shared detections form other components, each solved alone.

Gauge: a tight prior on one tag (the component's most-seen) fixes the frame of the solve. The
covariances (:meth:`BundleResult.covariances`, ``gtsam.Marginals``) are computed with the frame
fixed by priors the caller chooses (the tags that anchor it on the model), the measurement sigma
scaled by the residuals (a posteriori variance factor, at least :data:`MIN_SCALE`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import cv2
import networkx as nx
import numpy as np

from markerplace.geometry import invert, marker_corners_local
from markerplace.localization.tags import MARKER_FROM_APRILTAG

log = logging.getLogger(__name__)

__all__ = ["Detection", "BundleResult", "solve_tags", "pnp_cam_from_marker"]

PIXEL_SIGMA = 1.0
"""Assumed corner noise, pixels (one sigma per coordinate)."""
HUBER_K = 1.345
"""Huber threshold in sigmas (95 % efficiency on Gaussian noise)."""
OUTLIER_PX = 6.0
"""A detection whose RMS corner reprojection error exceeds this after a solve is dropped and
the component solved again (a wrong id or a corner on the wrong edge)."""
GAUGE_SIGMA = 1e-6
"""Prior sigma (radians, metres) that fixes the gauge tag of a solve."""
MIN_SCALE = 0.25
"""The a posteriori variance factor is never taken below this (corner noise of at least
``PIXEL_SIGMA * sqrt(MIN_SCALE)`` = 0.5 px: a perfect fit does not make a tag certain)."""


@dataclass(frozen=True)
class Detection:
    """One tag in one photo.

    Attributes:
        photo: index of the photo.
        tag_id: tag36h11 id.
        corners: (4, 2) pixels (pixel centres at integers), the detector's order.
    """

    photo: int
    tag_id: int
    corners: np.ndarray


@dataclass
class BundleResult:
    """What :func:`solve_tags` recovered, per connected component.

    Attributes:
        component: {tag_id: component index}; ``photo_component``: {photo: component index}.
        tags: {tag_id: (4, 4) world_from_marker} in its component's frame.
        cameras: {photo: (4, 4) world_from_cam} in its component's frame.
        cov: {tag_id: (6, 6) covariance of the tag pose, tangent (rotation, translation) in the
            tag's frame (GTSAM's ``Pose3`` convention), radians and metres}.
        photos_seen: {tag_id: photos whose detection of it was kept}.
        inliers: the detections kept.
        rms_px: RMS corner reprojection error over the kept detections, pixels.
        problems: per component what :meth:`covariances` needs (detections, cameras, sizes,
            solved poses, the a posteriori variance factor).
    """

    component: dict = field(default_factory=dict)
    photo_component: dict = field(default_factory=dict)
    tags: dict = field(default_factory=dict)
    cameras: dict = field(default_factory=dict)
    cov: dict = field(default_factory=dict)
    photos_seen: dict = field(default_factory=dict)
    inliers: list = field(default_factory=list)
    rms_px: float = 0.0
    problems: dict = field(default_factory=dict)

    def covariances(self, component: int, priors: dict) -> dict:
        """{tag_id: (6, 6) covariance of its pose} in ``component`` (tangent (rotation,
        translation) in the tag's frame, GTSAM's ``Pose3`` convention; radians, metres), the
        frame fixed by ``priors``: {tag_id: (rotation sigma, radians; position sigma, metres)},
        e.g. the tags that place the component on the model (the caller stores them in :attr:`cov`)."""
        sub, Ks, sizes, tags, cams, scale = self.problems[component]
        return _covariances(sub, Ks, sizes, tags, cams, priors, scale)

    def std(self, tag_id: int) -> tuple[float, float]:
        """(position std, metres; rotation std, degrees) of a tag: the square root of the largest
        eigenvalue of its translation / rotation covariance block (the worst direction)."""
        C = self.cov[tag_id]
        pos = float(np.sqrt(max(np.linalg.eigvalsh(C[3:, 3:]).max(), 0.0)))
        rot = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(C[:3, :3]).max(), 0.0))))
        return pos, rot


def pnp_cam_from_marker(corners: np.ndarray, size: float, K: np.ndarray) -> np.ndarray | None:
    """(4, 4) ``cam_from_marker`` of one detection by IPPE square, or None when it fails."""
    h = size / 2.0
    obj = np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]]).reshape(4, 1, 3)
    ok, rvec, tvec = cv2.solvePnP(obj, np.asarray(corners, float).reshape(4, 1, 2), np.asarray(K, float), None,
                                  flags=cv2.SOLVEPNP_IPPE_SQUARE)
    if not ok or not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))) or tvec.reshape(3)[2] <= 0:
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.reshape(3)
    return T @ MARKER_FROM_APRILTAG


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _corner_error(K: np.ndarray, local: np.ndarray, measured: np.ndarray):
    """The error function of one detection's factor: keys (camera, tag)."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]

    def error(this, values, jacobians):
        cam = values.atPose3(this.keys()[0])
        tag = values.atPose3(this.keys()[1])
        Rc, tc = cam.rotation().matrix(), cam.translation()
        Rt, tt = tag.rotation().matrix(), tag.translation()
        err = np.zeros(8)
        Jc, Jt = np.zeros((8, 6)), np.zeros((8, 6))
        for k in range(4):
            pm = local[k]
            pw = Rt @ pm + tt
            q = Rc.T @ (pw - tc)
            z = max(q[2], 1e-6)
            err[2 * k] = fx * q[0] / z + cx - measured[k, 0]
            err[2 * k + 1] = fy * q[1] / z + cy - measured[k, 1]
            dproj = np.array([[fx / z, 0.0, -fx * q[0] / z ** 2], [0.0, fy / z, -fy * q[1] / z ** 2]])
            Jc[2 * k:2 * k + 2] = dproj @ np.hstack([_skew(q), -np.eye(3)])
            Jt[2 * k:2 * k + 2] = dproj @ Rc.T @ np.hstack([-Rt @ _skew(pm), Rt])
        if jacobians is not None:
            jacobians[0] = Jc
            jacobians[1] = Jt
        return err

    return error


def _components(dets: list[Detection]) -> list[tuple[set, set]]:
    """Connected components of the photo-tag graph: [(photos, tag ids)], largest first."""
    g = nx.Graph()
    g.add_edges_from((("p", d.photo), ("t", d.tag_id)) for d in dets)
    out = []
    for comp in nx.connected_components(g):
        out.append(({n[1] for n in comp if n[0] == "p"}, {n[1] for n in comp if n[0] == "t"}))
    return sorted(out, key=lambda c: (-len(c[1]), -len(c[0]), min(c[1])))


def _initial(dets: list[Detection], Ks: dict, sizes: dict, photos: set, tags: set):
    """Initial (tags, cameras) of one component, chained from its most-seen tag by the
    detections of largest area; (root tag id, {tag: T}, {photo: T})."""
    rel = {}
    for i, d in enumerate(dets):
        T = pnp_cam_from_marker(d.corners, sizes[d.tag_id], Ks[d.photo])
        if T is not None:
            rel[i] = T
    area = {i: abs(cv2.contourArea(np.asarray(dets[i].corners, np.float32))) for i in rel}
    count = {t: sum(1 for i in rel if dets[i].tag_id == t) for t in tags}
    root = max(sorted(tags), key=lambda t: count[t])
    tag_T, cam_T = {root: np.eye(4)}, {}
    order = sorted(rel, key=lambda i: -area[i])
    changed = True
    while changed:
        changed = False
        for i in order:
            d = dets[i]
            if d.tag_id in tag_T and d.photo not in cam_T:
                cam_T[d.photo] = tag_T[d.tag_id] @ invert(rel[i])
                changed = True
            elif d.photo in cam_T and d.tag_id not in tag_T:
                tag_T[d.tag_id] = cam_T[d.photo] @ rel[i]
                changed = True
    return root, tag_T, cam_T


def _build(dets, Ks, sizes, tag_T, cam_T, gauge: int, sigma: float):
    import gtsam

    X = {p: gtsam.symbol("x", p) for p in cam_T}
    L = {t: gtsam.symbol("l", t) for t in tag_T}
    noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(HUBER_K),
                                           gtsam.noiseModel.Isotropic.Sigma(8, sigma))
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for d in dets:
        graph.add(gtsam.CustomFactor(noise, [X[d.photo], L[d.tag_id]],
                                     _corner_error(np.asarray(Ks[d.photo], float), marker_corners_local(sizes[d.tag_id]),
                                                   np.asarray(d.corners, float))))
    if gauge is not None:
        graph.add(gtsam.PriorFactorPose3(L[gauge], gtsam.Pose3(tag_T[gauge]),
                                         gtsam.noiseModel.Isotropic.Sigma(6, GAUGE_SIGMA)))
    for p, T in cam_T.items():
        values.insert(X[p], gtsam.Pose3(T))
    for t, T in tag_T.items():
        values.insert(L[t], gtsam.Pose3(T))
    return graph, values, X, L


def _optimize(dets, Ks, sizes, tag_T, cam_T, gauge):
    import gtsam

    graph, values, X, L = _build(dets, Ks, sizes, tag_T, cam_T, gauge, PIXEL_SIGMA)
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(100)
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-10)
    res = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    tags = {t: res.atPose3(k).matrix() for t, k in L.items()}
    cams = {p: res.atPose3(k).matrix() for p, k in X.items()}
    return tags, cams


def _residuals(dets, Ks, sizes, tags, cams) -> np.ndarray:
    """(n,) RMS corner reprojection error per detection, pixels."""
    out = np.zeros(len(dets))
    for i, d in enumerate(dets):
        pw = marker_corners_local(sizes[d.tag_id]) @ tags[d.tag_id][:3, :3].T + tags[d.tag_id][:3, 3]
        q = (pw - cams[d.photo][:3, 3]) @ cams[d.photo][:3, :3]
        uv = q @ np.asarray(Ks[d.photo], float).T
        uv = uv[:, :2] / np.maximum(uv[:, 2:], 1e-9)
        out[i] = float(np.sqrt(np.mean(np.sum((uv - d.corners) ** 2, axis=1))))
    return out


def _covariances(dets, Ks, sizes, tags, cams, priors: dict, scale: float) -> dict:
    """{tag: (6, 6) marginal covariance} with the gauge fixed by ``priors`` ({tag: (rotation
    sigma, radians; position sigma, metres)} at the solved poses)."""
    import gtsam

    graph, values, _, L = _build(dets, Ks, sizes, tags, cams, None, PIXEL_SIGMA * np.sqrt(scale))
    for t, (sr, sp) in priors.items():
        graph.add(gtsam.PriorFactorPose3(L[t], gtsam.Pose3(tags[t]),
                                         gtsam.noiseModel.Diagonal.Sigmas(np.array([sr] * 3 + [sp] * 3))))
    marg = gtsam.Marginals(graph, values)
    return {t: np.asarray(marg.marginalCovariance(k)) for t, k in L.items()}


def solve_tags(dets: list[Detection], Ks: dict, sizes: dict) -> BundleResult:
    """Solve every connected component of photos and tags (module docstring).

    Args:
        dets: the detections.
        Ks: {photo: (3, 3) camera matrix, pixels}.
        sizes: {tag_id: black-square edge, metres}.
    """
    out = BundleResult()
    sq, n = 0.0, 0
    for ci, (photos, tags) in enumerate(_components(dets)):
        sub = [d for d in dets if d.photo in photos]
        root, tag_T, cam_T = _initial(sub, Ks, sizes, photos, tags)
        sub = [d for d in sub if d.photo in cam_T and d.tag_id in tag_T]
        tagsol, camsol = _optimize(sub, Ks, sizes, tag_T, cam_T, root) if sub else (tag_T, cam_T)
        res = _residuals(sub, Ks, sizes, tagsol, camsol)
        if (res > OUTLIER_PX).any():
            log.info("component %d: %d of %d detections off by more than %.0f px after the solve: dropped, solved again",
                     ci, int((res > OUTLIER_PX).sum()), len(sub), OUTLIER_PX)
            sub = [d for d, r in zip(sub, res) if r <= OUTLIER_PX]
            camsol = {p: T for p, T in camsol.items() if any(d.photo == p for d in sub)}
            tagsol = {t: T for t, T in tagsol.items() if any(d.tag_id == t for d in sub)}
            if root not in tagsol or not sub:
                continue
            tagsol, camsol = _optimize(sub, Ks, sizes, tagsol, camsol, root)
            res = _residuals(sub, Ks, sizes, tagsol, camsol)
        if not sub:
            continue
        seen = {t: sorted({d.photo for d in sub if d.tag_id == t}) for t in tagsol}
        dof = max(8 * len(sub) - 6 * (len(tagsol) + len(camsol) - 1), 1)
        scale = max(float(np.sum(8 * res ** 2)) / dof / PIXEL_SIGMA ** 2, MIN_SCALE)
        out.problems[ci] = (sub, Ks, sizes, tagsol, camsol, scale)
        out.tags.update(tagsol)
        out.cameras.update(camsol)
        out.photos_seen.update(seen)
        out.component.update({t: ci for t in tagsol})
        out.photo_component.update({p: ci for p in camsol})
        out.inliers += sub
        sq += float(np.sum(4 * res ** 2))
        n += 4 * len(sub)
    out.rms_px = float(np.sqrt(sq / n)) if n else 0.0
    return out
