"""Put tags recovered in a frame of their own onto the model: a robust rigid fit to the plan.

Each tag whose id is planned gives a correspondence (its recovered ``world_from_marker`` in the
solver's frame, its planned one in the model's). One correspondence alone fixes a rigid
transform (``model_from_solver = planned @ inv(recovered)``), so every tag is tried as the
hypothesis (RANSAC over all minimal sets); a tag *agrees* with a transform when it lands within
``tol_m`` of its planned centre and within ``tol_deg`` of its planned orientation (the full
rotation: a tag turned on its wall disagrees). The hypothesis with most agreeing tags (ties: the
least summed centre error) is refined by a robust rigid fit to the four corners of every agreeing
tag (Kabsch, iteratively reweighted with Cauchy weights of scale :data:`CAUCHY_M` per tag), and
agreement is checked again until it no longer changes. A tag hung
wrong is an outlier and does not move the frame; the tags that anchor it are reported.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markerplace.geometry import invert, marker_corners_local

__all__ = ["Anchor", "anchor_to_plan", "rotation_deg"]

MAX_REFINE = 10
CAUCHY_M = 0.01
"""Scale of the Cauchy weights of the refinement, metres: a tag hung 2 cm off (within the
tolerance, so it agrees) weighs a fifth of one hung to the millimetre, so it barely tilts the frame."""
IRLS_STEPS = 10


@dataclass(frozen=True)
class Anchor:
    """A fit of the solver's frame to the model's.

    Attributes:
        model_from_solver: (4, 4) rigid transform.
        tags: ids of the agreeing tags it was fitted to, sorted.
        rms_m: RMS distance of their corners from the planned corners after the fit, metres.
    """

    model_from_solver: np.ndarray
    tags: tuple
    rms_m: float


def rotation_deg(A: np.ndarray, B: np.ndarray) -> float:
    """Angle (degrees) of the rotation between the (3, 3) or (4, 4) orientations ``A`` and ``B``."""
    R = np.asarray(A, float)[:3, :3].T @ np.asarray(B, float)[:3, :3]
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def _agree(M: np.ndarray, recovered: dict, planned: dict, tol_m: float, tol_deg: float) -> list:
    out = []
    for t in recovered:
        T = M @ recovered[t]
        if np.linalg.norm(T[:3, 3] - planned[t][:3, 3]) <= tol_m and rotation_deg(T, planned[t]) <= tol_deg:
            out.append(t)
    return sorted(out)


def _kabsch(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(4, 4) rigid ``T`` minimising sum w |T src - dst|^2 over (n, 3) point pairs, (n,) weights."""
    w = w / w.sum()
    cs, cd = w @ src, w @ dst
    U, _, Vt = np.linalg.svd((src - cs).T @ ((dst - cd) * w[:, None]))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, cd - R @ cs
    return T


def _corners(T: np.ndarray, size: float) -> np.ndarray:
    return marker_corners_local(size) @ T[:3, :3].T + T[:3, 3]


def _fit(ids, recovered, planned, sizes):
    """Cauchy-weighted least squares over the tags' corners (:data:`CAUCHY_M`), by iteratively
    reweighted Kabsch; (transform, unweighted corner RMS)."""
    src = np.vstack([_corners(recovered[t], sizes[t]) for t in ids])
    dst = np.vstack([_corners(planned[t], sizes[t]) for t in ids])
    w = np.ones(len(ids))
    for _ in range(IRLS_STEPS):
        M = _kabsch(src, dst, np.repeat(w, 4))
        r = np.linalg.norm(src @ M[:3, :3].T + M[:3, 3] - dst, axis=1).reshape(len(ids), 4).mean(axis=1)
        w = 1.0 / (1.0 + (r / CAUCHY_M) ** 2)
    rms = float(np.sqrt(np.mean(np.sum((src @ M[:3, :3].T + M[:3, 3] - dst) ** 2, axis=1))))
    return M, rms


def anchor_to_plan(recovered: dict, planned: dict, sizes: dict, tol_m: float, tol_deg: float) -> Anchor | None:
    """The robust fit of the module docstring.

    Args:
        recovered: {tag_id: (4, 4) world_from_marker in the solver's frame}.
        planned: {tag_id: (4, 4) planned world_from_marker in the model's frame}.
        sizes: {tag_id: black-square edge, metres}.
        tol_m, tol_deg: agreement tolerance (centre distance, rotation angle).

    Returns:
        The :class:`Anchor`, or None when fewer than two tags agree on any transform.
    """
    common = sorted(set(recovered) & set(planned))
    rec = {t: np.asarray(recovered[t], float) for t in common}
    plan = {t: np.asarray(planned[t], float) for t in common}
    best, best_key = None, None
    for t in common:
        M = plan[t] @ invert(rec[t])
        ids = _agree(M, rec, plan, tol_m, tol_deg)
        err = sum(float(np.linalg.norm((M @ rec[u])[:3, 3] - plan[u][:3, 3])) for u in ids)
        key = (-len(ids), err)
        if best_key is None or key < best_key:
            best, best_key = ids, key
    if best is None or len(best) < 2:
        return None
    ids = best
    for _ in range(MAX_REFINE):
        M, rms = _fit(ids, rec, plan, sizes)
        again = _agree(M, rec, plan, tol_m, tol_deg)
        if len(again) < 2 or again == ids:
            break
        ids = again
    M, rms = _fit(ids, rec, plan, sizes)
    return Anchor(M, tuple(ids), rms)
