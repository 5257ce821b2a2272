"""Installer views: what a person sees standing in front of a tag's spot, with the tag drawn in.

For each placed tag two renders of the scene with every placed tag drawn (the renderer draws
markers as textured quads):

- **close**: from about :data:`CLOSE_DISTANCE` in front of the spot, at the tag's height
  (eye level), looking straight at it, :data:`CLOSE_HFOV` degrees wide; the tag is outlined.
- **wide**: from as far back as the room allows (up to :data:`WIDE_DISTANCE`), :data:`WIDE_HFOV`
  degrees wide, turned towards the nearest corner or wall edge just enough to show it (the tag
  stays in view, :func:`wide_turn`); the tag is outlined and two dimension lines show the
  caption's measurements: along the wall to that corner or edge, and down to the local floor.

The camera always stands in free space: a ray from the tag along its normal (at its height)
stops at the first obstacle, the camera keeps :data:`BODY_CLEARANCE` from it, and its grid cell
in the discretization's occupancy must be free (stepping closer until one is; see
:func:`standing_distance`).

Frames: the scene's internal frame (world z up, metres); images are RGB uint8, row 0 on top.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..geometry import Intrinsics, project, world_from_cam_pose
from ..render.tags import outer_size

__all__ = ["CLOSE_DISTANCE", "WIDE_DISTANCE", "standing_distance", "wide_turn", "InstallerViews", "render_installer_views",
           "draw_outline", "draw_dimension"]

CLOSE_DISTANCE = 2.0
"""Preferred distance of the close view from the tag, metres."""
WIDE_DISTANCE = 4.5
"""Farthest distance of the wide view from the tag, metres."""
MIN_DISTANCE = 0.6
"""Nearest a view stands to the tag, metres (closer only when nothing else is free)."""
BODY_CLEARANCE = 0.3
"""Room kept between the camera and the obstacle behind it, metres."""
CLOSE_HFOV = 60.0
WIDE_HFOV = 80.0
VIEW_MARGIN_DEG = 8.0
"""Angle kept between the image border and the tag or the reference corner in the wide view."""
IMAGE_SIZE = (640, 480)
"""Width and height of both views, pixels."""
OUTLINE_BGR = (255, 0, 255)
DIMENSION_RGB = (255, 140, 0)


def standing_distance(caster, occupancy: np.ndarray | None, origin: Sequence[float], resolution: float,
                      position: np.ndarray, normal: np.ndarray, want: float) -> float:
    """How far in front of a tag a camera can stand, metres (at most ``want``).

    Args:
        caster: :class:`~markerplace.scene.raycast.RayCaster` of the scene.
        occupancy: (H, W) int8 occupancy layer of the tag's storey (0 = free; see
            :class:`~markerplace.plan.discretization.Discretization`), or None (rays only).
        origin / resolution: the grid's lower-left corner (x0, y0) and cell size, metres.
        position: (3,) tag centre; normal: (3,) horizontal wall normal towards the room.
        want: preferred distance, metres.

    Returns:
        The largest distance in steps of 0.1 m from ``want`` down to :data:`MIN_DISTANCE` whose
        camera is at least :data:`BODY_CLEARANCE` short of the first obstacle along the normal
        and on a free occupancy cell; if no such step, the largest one short of the obstacle;
        never below 0.3 m.
    """
    p = np.asarray(position, float)
    n = np.asarray(normal, float)
    hit, _ = caster.first_hits((p + 0.05 * n)[None], n[None], max_t=want + 1.0)
    limit = min(want, float(hit[0]) + 0.05 - BODY_CLEARANCE) if np.isfinite(hit[0]) else want
    steps = np.round(np.arange(limit, MIN_DISTANCE - 1e-9, -0.1), 3)
    if occupancy is not None:
        H, W = occupancy.shape
        for d in steps:
            c = p + d * n
            col = int(np.floor((c[0] - origin[0]) / resolution))
            row = int(np.floor((c[1] - origin[1]) / resolution))
            if 0 <= row < H and 0 <= col < W and occupancy[row, col] == 0:
                return float(d)
    return float(max(limit, 0.3)) if len(steps) == 0 else float(steps[0])


def _bgr(rgb: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(rgb[..., ::-1])


def draw_outline(rgb: np.ndarray, K: np.ndarray, world_from_cam: np.ndarray, marker, label: str | None = None,
                 thickness: int = 3) -> np.ndarray:
    """Draw a rectangle 1.2 times the tag's printed sheet (black square + quiet zone) around a
    marker, and ``label`` above it; returns a new (H, W, 3) RGB image."""
    import cv2

    img = _bgr(rgb)
    h = 0.6 * outer_size(marker.size)
    local = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], float)
    corners = local @ marker.world_from_marker[:3, :3].T + marker.world_from_marker[:3, 3]
    uv, z = project(K, world_from_cam, corners)
    if np.all(z > 0.05):
        pts = np.round(uv).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [pts], True, OUTLINE_BGR, thickness, cv2.LINE_AA)
        if label:
            x, y = int(uv[:, 0].min()), int(uv[:, 1].min()) - 8
            _text(img, label, (x, max(y, 18)), OUTLINE_BGR)
    return img[..., ::-1].copy()


def _text(img_bgr: np.ndarray, text: str, org: tuple[int, int], color, centred: bool = False) -> None:
    """Write ``text`` on a white box at ``org`` (its left end, or its middle when ``centred``),
    kept inside the image."""
    import cv2

    H, W = img_bgr.shape[:2]
    (tw, th), _ = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, 0.6, 2)
    x = int(np.clip(org[0] - (tw // 2 if centred else 0), 2, max(2, W - tw - 2)))
    y = int(np.clip(org[1], th + 2, H - 4))
    cv2.rectangle(img_bgr, (x - 2, y - th - 3), (x + tw + 2, y + 4), (255, 255, 255), -1)
    cv2.putText(img_bgr, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, 0.6, color, 2, cv2.LINE_AA)


def draw_dimension(rgb: np.ndarray, K: np.ndarray, world_from_cam: np.ndarray, a: np.ndarray, b: np.ndarray,
                   text: str, ticks: bool = True, text_below: bool = False) -> np.ndarray:
    """Draw a dimension line between world points ``a`` and ``b`` (3,) with end ticks (unless
    ``ticks`` is False: a plain extension line) and ``text`` beside its middle (right of it, or
    centred under it with ``text_below``; clamped into the image); returns a new RGB image.
    Nothing is drawn when either end is behind the camera."""
    import cv2

    img = _bgr(rgb)
    uv, z = project(K, world_from_cam, np.stack([a, b]))
    if np.all(z > 0.05):
        H, W = img.shape[:2]
        lim = 4 * max(H, W)
        pa, pb = (tuple(int(v) for v in np.clip(np.round(p), -lim, lim)) for p in uv)
        color = DIMENSION_RGB[::-1]
        cv2.line(img, pa, pb, color, 2, cv2.LINE_AA)
        d = uv[1] - uv[0]
        perp = np.array([-d[1], d[0]]) / max(np.linalg.norm(d), 1e-9) * 8
        for p in (uv[0], uv[1]) if ticks else ():
            cv2.line(img, tuple(int(v) for v in np.clip(np.round(p - perp), -lim, lim)),
                     tuple(int(v) for v in np.clip(np.round(p + perp), -lim, lim)), color, 2, cv2.LINE_AA)
        mid = np.clip(0.5 * (uv[0] + uv[1]), [0, 0], [W - 1, H - 1])
        if text and text_below:
            _text(img, text, (int(mid[0]), int(mid[1]) + 24), color, centred=True)
        elif text:
            _text(img, text, (int(mid[0]) + 8, int(mid[1]) + 6), color)
    return img[..., ::-1].copy()


def wide_turn(place, distance: float, hfov_deg: float = WIDE_HFOV, margin_deg: float = VIEW_MARGIN_DEG) -> float:
    """Yaw (radians, counter-clockwise) to add to a camera ``distance`` metres in front of a tag,
    looking straight at it, so that the nearest corner or wall edge of ``place`` (a
    :class:`~markerplace.report.captions.TagPlace`) is in view: just enough to bring it
    ``margin_deg`` inside the image border, and never so much that the tag leaves the same
    margin. 0 when it is in view already or there is none."""
    ref = place.reference_point()
    if ref is None:
        return 0.0
    side, end = place.nearest
    half = np.radians(hfov_deg / 2.0 - margin_deg)
    turn = float(np.clip(np.arctan2(end.distance, distance) - half, 0.0, half))
    # turning counter-clockwise swings the view from the wall normal towards -tangent (the viewer's left)
    return turn if side == "left" else -turn


@dataclass(frozen=True, eq=False)
class InstallerViews:
    """The two views of one tag.

    Attributes:
        close, wide: (H, W, 3) uint8 RGB images (annotated).
        close_distance, wide_distance: camera distance from the tag, metres.
        close_from_cam, wide_from_cam: (4, 4) ``world_from_cam`` of each view.
    """

    close: np.ndarray
    wide: np.ndarray
    close_distance: float
    wide_distance: float
    close_from_cam: np.ndarray
    wide_from_cam: np.ndarray


def render_installer_views(scene, markers: Sequence, places: Sequence, caster, occupancy_of, origin,
                           resolution: float, labels: Sequence[str]) -> list[InstallerViews]:
    """Render the close and wide view of every marker.

    Args:
        scene: the scene (internal frame).
        markers: the placed :class:`~markerplace.markers.Marker` list (all are drawn in every view).
        places: one :class:`~markerplace.report.captions.TagPlace` per marker (fitted wall
            normal, local floor, nearest corner or edge).
        caster: ray caster of the scene.
        occupancy_of: function marker index -> (H, W) occupancy layer of its storey, or None.
        origin / resolution: the occupancy grid's lower-left corner and cell size, metres.
        labels: outline label per marker (e.g. ``"#1 id 0"``).
    """
    from ..render.renderer import Renderer

    views = []
    W, H = IMAGE_SIZE
    close_intr = Intrinsics.from_fov(W, H, CLOSE_HFOV)
    wide_intr = Intrinsics.from_fov(W, H, WIDE_HFOV)
    with Renderer(scene, close_intr, markers=list(markers)) as close_r, \
            Renderer(scene, wide_intr, markers=list(markers)) as wide_r:
        for i, (m, place) in enumerate(zip(markers, places)):
            p = np.asarray(m.position, float)
            n = np.asarray(place.normal, float)
            occ = occupancy_of(i)
            yaw = float(np.arctan2(-n[1], -n[0]))
            d_close = standing_distance(caster, occ, origin, resolution, p, n, CLOSE_DISTANCE)
            d_wide = max(standing_distance(caster, occ, origin, resolution, p, n, WIDE_DISTANCE), d_close)
            T_close = world_from_cam_pose(p + d_close * n, yaw)
            T_wide = world_from_cam_pose(p + d_wide * n, yaw + wide_turn(place, d_wide))
            close = draw_outline(close_r.render(T_close, depth=False, normal=False).rgb, close_intr.K, T_close, m,
                                 labels[i])
            wide = wide_r.render(T_wide, depth=False, normal=False).rgb
            ref = place.reference_point()
            front = place.on_wall + 0.01 * n
            side = -1.0
            if ref is not None:
                name, end = place.nearest
                side = 1.0 if name == "left" else -1.0  # the height line goes on the other side
                below = np.array([0.0, 0.0, 0.6 * outer_size(m.size) + 0.12])  # under the outline, not across the tag
                wide = draw_dimension(wide, wide_intr.K, T_wide, front, front - below, "", ticks=False)
                wide = draw_dimension(wide, wide_intr.K, T_wide, front - below, ref + 0.01 * n - below,
                                      f"{end.distance:.2f} m", text_below=True)
            beside = front + side * (0.6 * outer_size(m.size) + 0.15) * place.tangent
            wide = draw_dimension(wide, wide_intr.K, T_wide, np.array([beside[0], beside[1], place.floor_z]), beside,
                                  f"{place.height:.2f} m")
            wide = draw_outline(wide, wide_intr.K, T_wide, m, labels[i], thickness=2)
            views.append(InstallerViews(close, wide, d_close, d_wide, T_close, T_wide))
    return views
