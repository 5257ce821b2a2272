"""The human baseline: tags where a person would hang them without a planner.

The paper's real experiment compares OMP with tags "placed by a human": "the human prioritizes
centers in less textured areas". :func:`human_placement` does that deterministically (no seed;
every tie goes to the lower index) from what a plan run already has, the candidate marker poses
and the map images' SIFT points (:class:`~markerplace.plan.types.PlanData`):

1. **Wall stretches** (:func:`wall_stretches`): the candidates of one flat wall between corners,
   door openings or turns. Two candidates are linked when they are on the same storey, their
   normals differ by at most ``normal_tol_deg``, they lie in one plane (within
   ``coplanar_tol``), they are at most the marker spacing + ``gap_margin`` apart (the spacing is
   the median distance of a candidate to its nearest neighbour on the same wall line), and the
   occupancy layer says the wall runs on between them: free space all along the segment
   ``probe_offset`` in front of the wall (no corner, no tall furniture) and no free cell one
   cell behind it (no door opening). The stretches are the connected components of these links
   (consecutive candidates along the perimeter, also across the start of a perimeter loop). A
   stretch's **centre** is its candidate nearest the middle of its candidates' extent.
2. **Texture** (:func:`wall_texture`): distinct SIFT keypoints with a 3D point per square metre of
   the wall around a stretch: points within ``plane_tol`` of the wall plane, within
   ``band_height / 2`` of the tag height (the wall band around eye level), within the stretch's
   extent plus ``window / 2`` at each end, seen by a camera in front of the wall; one point per
   ``voxel`` cube (a spot seen from many poses counts once). Each candidate gets the same
   measure over a ``window``-wide box around it. SIFT density rather than image gradient
   energy: the keypoints are exactly what the localizer matches (a plain wall is where it has
   nothing to hold on to, the spot a person picks by eye), they are already computed for every
   map image with 3D points (no re-rendering), and counting distinct 3D points per square
   metre of wall does not depend on how many cameras look at the wall or from how far.
3. **Rooms** (:func:`wall_rooms`): connected pieces of each storey's free space (occupancy 0)
   after an opening by ``doorway_half_width`` (cells farther than that from non-free space are
   the room cores: a doorway up to twice as wide separates rooms, a wider opening joins them);
   the cores grow back over the free space (watershed on the distance map, so the boundary
   falls at the doorway); pieces smaller than ``min_room_area`` join their neighbours and free
   space without any core (a narrow corridor) is a room of its own. A candidate belongs to the
   room in front of it. This works on any mesh (no room metadata needed).
4. **Selection** (:func:`select`): round 1 offers each stretch's centre; later rounds (only when
   k exceeds the number of stretches) offer each stretch's next spot, its remaining candidates
   least textured first. In each round the tags still to place are shared among the rooms in
   proportion to their free area (largest remainder, ties to the lower room), no room getting
   more than it has spots in that round (held at that, the rest shared again among the others); rooms
   without candidates get none. Within a room the least-textured spots win (round 1: stretch
   texture; later rounds: the candidate's own). No two tags share a stretch while any stretch
   is free. The order is round, then texture, then candidate index. Existing markers count as
   placed in the scores but do not change the choice.

Frames: world z up, metres; normals are horizontal unit vectors towards the free space.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from markerplace.errors import UserError
from markerplace.plan.discretize.artifact import Discretization
from markerplace.plan.discretize.grid import Grid
from markerplace.plan.types import PlanData

log = logging.getLogger(__name__)

__all__ = ["HumanConfig", "WallAnalysis", "wall_stretches", "wall_texture", "wall_rooms", "largest_remainder",
           "select", "analyse", "human_placement"]


@dataclass(frozen=True)
class HumanConfig:
    """Settings of the human baseline (metres unless stated).

    Attributes:
        normal_tol_deg: candidates of one stretch face the same way within this, degrees.
        coplanar_tol: candidates of one stretch lie within this of each other's wall plane.
        gap_margin: a stretch has no gap wider than the marker spacing plus this.
        probe_offset: the wall is followed on the occupancy layer this far in front of it.
        plane_tol: SIFT points within this of the wall plane are on the wall.
        band_height: height of the wall band around the tag height whose points count.
        window: width of wall around a candidate (and beyond a stretch's end candidates) whose
            points count.
        voxel: points in one cube of this edge count once.
        doorway_half_width: free space narrower than twice this separates rooms.
        min_room_area: free pieces smaller than this (m^2) are not rooms of their own.
    """

    normal_tol_deg: float = 10.0
    coplanar_tol: float = 0.1
    gap_margin: float = 0.3
    probe_offset: float = 0.15
    plane_tol: float = 0.05
    band_height: float = 1.0
    window: float = 1.0
    voxel: float = 0.02
    doorway_half_width: float = 0.55
    min_room_area: float = 2.0


@dataclass(frozen=True, eq=False)
class WallAnalysis:
    """What the human baseline sees of a plan (C candidates, S stretches, R rooms).

    Attributes:
        stretch_of: (C,) int64 stretch of each candidate (stretches numbered by their lowest
            candidate index).
        centre: (S,) int64 centre candidate of each stretch.
        stretch_texture: (S,) distinct SIFT points per m^2 of the wall around each stretch.
        candidate_texture: (C,) the same over a ``window``-wide box around each candidate.
        room_of: (C,) int64 room of each candidate.
        room_area: (R,) free area of each room, m^2.
        spacing: the marker spacing found, metres (0 when no two candidates share a wall line).
    """

    stretch_of: np.ndarray
    centre: np.ndarray
    stretch_texture: np.ndarray
    candidate_texture: np.ndarray
    room_of: np.ndarray
    room_area: np.ndarray
    spacing: float


def _tangent(n: np.ndarray) -> np.ndarray:
    """(..., 3) horizontal unit vectors along the wall: up x normal."""
    return np.stack([-n[..., 1], n[..., 0], np.zeros(n.shape[:-1])], axis=-1)


def _grid(disc: Discretization, storey: int) -> tuple[Grid, np.ndarray]:
    occ = disc.occupancy_of(int(storey))
    o = np.asarray(disc.grid_origin, float)
    return Grid(float(o[0]), float(o[1]), float(disc.grid_resolution), occ.shape[0], occ.shape[1]), occ


def _same_line(pos: np.ndarray, nrm: np.ndarray, sto: np.ndarray, i: np.ndarray, j: np.ndarray,
               conf: HumanConfig) -> np.ndarray:
    """(P,) bool: candidates i and j face the same way on one wall plane of one storey."""
    return ((sto[i] == sto[j]) & (np.einsum("ij,ij->i", nrm[i], nrm[j]) >= np.cos(np.radians(conf.normal_tol_deg)))
            & (np.abs(np.einsum("ij,ij->i", nrm[i], pos[j] - pos[i])) <= conf.coplanar_tol))


def _spacing(pos: np.ndarray, nrm: np.ndarray, sto: np.ndarray, conf: HumanConfig) -> float:
    """Median distance from a candidate to its nearest neighbour on the same wall line, metres."""
    from scipy.spatial import cKDTree

    C = len(pos)
    if C < 2:
        return 0.0
    kn = min(9, C)
    dist, nb = cKDTree(pos).query(pos, k=kn)
    i = np.repeat(np.arange(C), kn - 1)
    j, d = nb[:, 1:].ravel(), dist[:, 1:].ravel()
    d = np.where(_same_line(pos, nrm, sto, i, j, conf), d, np.inf).reshape(C, kn - 1).min(axis=1)
    return float(np.median(d[np.isfinite(d)])) if np.isfinite(d).any() else 0.0


def _wall_runs_on(disc: Discretization, a: np.ndarray, b: np.ndarray, n: np.ndarray, storey: int,
                  conf: HumanConfig) -> bool:
    """The occupancy layer shows one wall from ``a`` to ``b`` (3,) with normal ``n``: free space
    all along in front of it and no free cell one cell behind it (a door opening)."""
    grid, occ = _grid(disc, storey)
    m = int(np.ceil(np.linalg.norm(b[:2] - a[:2]) / (0.5 * grid.res))) + 1
    line = a[:2] + np.linspace(0.0, 1.0, m)[:, None] * (b[:2] - a[:2])
    front = grid.lookup(occ, line + conf.probe_offset * n[:2], -1)
    behind = grid.lookup(occ, line - grid.res * n[:2], -1)
    return bool(np.all(front == 0) and not np.any(behind == 0))


def wall_stretches(disc: Discretization, conf: HumanConfig) -> tuple[np.ndarray, np.ndarray, float]:
    """Group the candidates into flat wall stretches (module docstring, step 1).

    Returns:
        stretch_of: (C,) int64 stretch per candidate, numbered by lowest candidate index.
        centre: (S,) int64 centre candidate of each stretch.
        spacing: the marker spacing found, metres.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pos = np.asarray(disc.candidate_position, float)
    nrm = np.asarray(disc.candidate_normal, float)
    sto = np.asarray(disc.candidate_storey, np.int64)
    C = len(pos)
    spacing = _spacing(pos, nrm, sto, conf)
    pairs = cKDTree(pos).query_pairs(spacing + conf.gap_margin, output_type="ndarray") if C > 1 else np.zeros((0, 2))
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if len(pairs):
        pairs = pairs[_same_line(pos, nrm, sto, pairs[:, 0], pairs[:, 1], conf)]
        pairs = np.array([p for p in pairs if _wall_runs_on(disc, pos[p[0]], pos[p[1]], nrm[p[0]], sto[p[0]], conf)],
                         np.int64).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(C, C))
    _, raw = connected_components(graph, directed=False)
    _, first, stretch_of = np.unique(raw, return_index=True, return_inverse=True)
    stretch_of = np.argsort(np.argsort(first, kind="stable"), kind="stable")[stretch_of].astype(np.int64)
    centre = np.zeros(stretch_of.max() + 1 if C else 0, np.int64)
    for s in range(len(centre)):
        members = np.flatnonzero(stretch_of == s)
        u = (pos[members] - pos[members[0]]) @ _tangent(nrm[members[0]])
        centre[s] = members[int(np.argmin(np.abs(u - 0.5 * (u.min() + u.max()))))]
    return stretch_of, centre, spacing


def wall_texture(disc: Discretization, points_world: np.ndarray, pose_index: np.ndarray, boxes: np.ndarray,
                 conf: HumanConfig) -> np.ndarray:
    """Distinct SIFT points per m^2 of wall in each box (module docstring, step 2).

    Args:
        disc: the discretization (camera positions).
        points_world: (K, 3) world metres of the map images' keypoints (NaN: no 3D point).
        pose_index: (K,) camera pose of each keypoint.
        boxes: (B, 3) rows (candidate, u_lo, u_hi): the wall plane and tag height of candidate
            ``row[0]``, and the extent [u_lo, u_hi] along its tangent (up x normal) from its
            centre, metres.

    Returns:
        (B,) points per m^2.
    """
    from scipy.spatial import cKDTree

    P = np.asarray(points_world, float)
    ok = np.isfinite(P).all(axis=1)
    P, cam = P[ok], np.asarray(disc.world_from_cam)[np.asarray(pose_index)[ok], :3, 3]
    out = np.zeros(len(boxes))
    if len(P) == 0 or len(boxes) == 0:
        return out
    tree = cKDTree(P[:, :2])
    c = np.asarray(boxes[:, 0], np.int64)
    p0, n = np.asarray(disc.candidate_position, float)[c], np.asarray(disc.candidate_normal, float)[c]
    t = _tangent(n)
    lo, hi = boxes[:, 1], boxes[:, 2]
    mid = p0 + (0.5 * (lo + hi))[:, None] * t
    radius = np.hypot(0.5 * (hi - lo), conf.plane_tol) + 1e-9
    for b, rows in enumerate(tree.query_ball_point(mid[:, :2], radius)):
        rows = np.asarray(rows, np.int64)
        d = P[rows] - p0[b]
        u = d @ t[b]
        keep = ((np.abs(d @ n[b]) <= conf.plane_tol) & (u >= lo[b]) & (u <= hi[b])
                & (np.abs(d[:, 2]) <= 0.5 * conf.band_height) & (np.einsum("ij,j->i", cam[rows] - P[rows], n[b]) > 0))
        keys = np.floor(P[rows[keep]] / conf.voxel).astype(np.int64)
        out[b] = len(np.unique(keys, axis=0)) / ((hi[b] - lo[b]) * conf.band_height)
    return out


def wall_rooms(disc: Discretization, conf: HumanConfig) -> tuple[np.ndarray, np.ndarray]:
    """Rooms of the free space and the room of each candidate (module docstring, step 3).

    Returns:
        room_of: (C,) int64 room per candidate.
        room_area: (R,) free area per room, m^2 (rooms of every planned storey).
    """
    from scipy.ndimage import distance_transform_edt, label
    from skimage.segmentation import watershed

    C = len(disc.candidate_position)
    room_of = np.zeros(C, np.int64)
    areas: list[float] = []
    cell = float(disc.grid_resolution) ** 2
    eight = np.ones((3, 3), bool)
    for storey in np.asarray(disc.planned_storeys, np.int64):
        grid, occ = _grid(disc, storey)
        free = occ == 0
        dist = distance_transform_edt(free) * grid.res
        cores, _ = label(dist > conf.doorway_half_width, structure=eight)
        rooms = watershed(-dist, cores, mask=free)
        small = np.flatnonzero(np.bincount(rooms.ravel())[1:] * cell < conf.min_room_area) + 1
        if len(small) and len(small) < rooms.max():
            rooms = watershed(-dist, np.where(np.isin(cores, small), 0, cores), mask=free)
        rest, _ = label(free & (rooms == 0), structure=eight)  # free space without any core
        rooms = np.where(rest > 0, rest + rooms.max(), rooms)
        ids, rooms = np.unique(rooms, return_inverse=True)
        rooms = rooms.reshape(free.shape)  # 0 = not free when any cell is not free
        if ids[0] != 0:
            rooms = rooms + 1
        n_rooms = int(rooms.max())
        here = np.flatnonzero(np.asarray(disc.candidate_storey) == storey)
        if len(here) and n_rooms:
            _, (ri, ci) = distance_transform_edt(rooms == 0, return_indices=True)
            nearest = rooms[ri, ci]
            front = disc.candidate_position[here, :2] + conf.probe_offset * disc.candidate_normal[here, :2]
            room_of[here] = len(areas) + grid.lookup(nearest, front, 1) - 1
        areas.extend(float(a) * cell for a in np.bincount(rooms.ravel(), minlength=n_rooms + 1)[1:])
    return room_of, np.asarray(areas, float)


def _hamilton(total: int, weights: np.ndarray) -> np.ndarray:
    """Largest-remainder shares of ``total`` by ``weights`` (all equal when they sum to 0);
    ties to the lower index."""
    w = weights if weights.sum() > 0 else np.ones(len(weights))
    exact = total * w / w.sum()
    share = np.floor(exact).astype(np.int64)
    share[np.lexsort((np.arange(len(w)), -(exact - share)))[:total - int(share.sum())]] += 1
    return share


def largest_remainder(total: int, weights: np.ndarray, caps: np.ndarray) -> np.ndarray:
    """(R,) int64 shares of ``total`` proportional to (R,) ``weights`` >= 0, none over (R,)
    ``caps``: largest-remainder rounding (ties to the lower index); a share over its cap is held
    at the cap and the rest is shared again among the others, from scratch. Sums to
    min(total, caps.sum())."""
    w, caps = np.asarray(weights, float), np.asarray(caps, np.int64)
    total = int(min(total, caps.sum()))
    fixed = caps <= 0
    while True:
        free = np.flatnonzero(~fixed)
        share = _hamilton(total - int(caps[fixed].sum()), w[free]) if len(free) else np.zeros(0, np.int64)
        over = share > caps[free]
        if not over.any():
            alloc = np.where(fixed, caps, 0)
            alloc[free] = share
            return alloc.astype(np.int64)
        fixed[free[over]] = True


def select(analysis: WallAnalysis, k: int) -> list[int]:
    """k candidates by rounds over the stretches, shared over rooms (module docstring, step 4)."""
    a = analysis
    spots = []  # per stretch: its candidates in offer order (centre first, then least textured)
    for s, c in enumerate(a.centre):
        rest = np.flatnonzero((a.stretch_of == s) & (np.arange(len(a.stretch_of)) != c))
        spots.append([int(c)] + rest[np.lexsort((rest, a.candidate_texture[rest]))].tolist())
    order: list[int] = []
    rnd = 0
    while len(order) < k and any(len(sp) > rnd for sp in spots):
        offer = np.array([sp[rnd] for sp in spots if len(sp) > rnd], np.int64)
        tex = (a.stretch_texture[a.stretch_of[offer]] if rnd == 0 else a.candidate_texture[offer])
        offer = offer[np.lexsort((offer, tex))]
        rooms = a.room_of[offer]
        R = len(a.room_area)
        share = largest_remainder(k - len(order), a.room_area, np.bincount(rooms, minlength=R))
        taken = np.zeros(len(offer), bool)
        for r in range(R):
            taken[np.flatnonzero(rooms == r)[:share[r]]] = True
        order.extend(offer[taken].tolist())
        rnd += 1
    return order


def analyse(data: PlanData, conf: HumanConfig) -> WallAnalysis:
    """Stretches, textures and rooms of a prepared plan (steps 1-3 of the module docstring)."""
    disc = data.disc
    if getattr(data, "points_world", None) is None or getattr(data, "pose_index", None) is None:
        raise UserError("--method human needs the map images' SIFT points (PlanData.points_world): plan the scene "
                        "with markerplace.pipelines.plan.prepare")
    stretch_of, centre, spacing = wall_stretches(disc, conf)
    pos, nrm = np.asarray(disc.candidate_position, float), np.asarray(disc.candidate_normal, float)
    boxes = []
    for s, c in enumerate(centre):
        members = np.flatnonzero(stretch_of == s)
        u = (pos[members] - pos[c]) @ _tangent(nrm[c])
        boxes.append((c, u.min() - 0.5 * conf.window, u.max() + 0.5 * conf.window))
    boxes += [(c, -0.5 * conf.window, 0.5 * conf.window) for c in range(len(pos))]
    boxes = np.array(boxes, float).reshape(-1, 3)
    tex = wall_texture(disc, data.points_world, data.pose_index, boxes, conf)
    room_of, room_area = wall_rooms(disc, conf)
    return WallAnalysis(stretch_of, centre, tex[:len(centre)], tex[len(centre):], room_of, room_area, spacing)


def human_placement(data: PlanData, k: int, conf: HumanConfig = HumanConfig(), progress: bool = False) -> np.ndarray:
    """(k,) int64 candidate indices, in placement order, of the human baseline (module docstring)."""
    a = analyse(data, conf)
    S, rooms = len(a.centre), np.unique(a.room_of)
    log.info("human: %d wall stretches (marker spacing %.2f m) in %d rooms with candidates (%s m^2); texture "
             "%.0f-%.0f SIFT points/m^2 (median %.0f)", S, a.spacing, len(rooms),
             ", ".join(f"{a.room_area[r]:.1f}" for r in rooms), a.stretch_texture.min(initial=0),
             a.stretch_texture.max(initial=0), np.median(a.stretch_texture) if S else 0)
    if k > S:
        log.info("human: %d tags for %d wall stretches: %d go round again on the next-least-textured spots",
                 k, S, k - S)
    order = np.asarray(select(a, k), np.int64)
    if progress:
        for i, c in enumerate(order):
            s = a.stretch_of[c]
            log.info("human pick %d/%d: candidate %d, room %d, stretch %d (%d candidates, %.0f points/m^2)%s",
                     i + 1, k, c, a.room_of[c], s, int((a.stretch_of == s).sum()), a.stretch_texture[s],
                     "" if c == a.centre[s] else f", spot {a.candidate_texture[c]:.0f} points/m^2")
    return order
