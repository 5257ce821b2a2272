"""Installer views: what a person sees standing in front of a tag's spot, with the tag drawn in.

For each placed tag two renders of the scene with every placed tag drawn (the renderer draws
markers as textured quads):

- **close**: from about :data:`CLOSE_DISTANCE` in front of the spot, at the tag's height
  (eye level), looking straight at it, :data:`CLOSE_HFOV` degrees wide; the tag is outlined.
- **wide**: from as far back as the room allows (up to :data:`WIDE_DISTANCE`), :data:`WIDE_HFOV`
  degrees wide, turned towards the nearest corner or wall edge just enough to show it (the tag
  stays in view, :func:`wide_turn`); the tag is outlined and two dimension lines show the
  instructions' measurements: along the wall to the nearer corner or door edge, and down to the
  floor under the tag. Labels never overlap one another or cover the tag (:class:`LabelLayout`).

The camera always stands in free space: a ray from the tag along its normal (at its height)
stops at the first obstacle, the camera keeps :data:`BODY_CLEARANCE` from it, and its grid cell
in the discretization's occupancy must be free (stepping closer until one is); it also steps
closer until nothing stands between it and the tag (and, in the wide view, the corner or door
edge the dimension line runs to), so it never looks through a doorway from the next room (see
:func:`standing_distance`).

Frames: the scene's internal frame (world z up, metres); images are RGB uint8, row 0 on top.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from markerplace.geometry import Intrinsics, project, world_from_cam_pose
from markerplace.render.renderer import Renderer
from markerplace.tagfamily import outer_size

__all__ = ["CLOSE_DISTANCE", "WIDE_DISTANCE", "standing_distance", "wide_turn", "InstallerViews", "render_installer_views",
           "draw_outline", "draw_dimension", "Label", "LabelLayout"]

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
                      position: np.ndarray, normal: np.ndarray, want: float, see: np.ndarray | None = None) -> float:
    """How far in front of a tag a camera can stand, metres (at most ``want``).

    Args:
        caster: :class:`~markerplace.scene.raycast.RayCaster` of the scene.
        occupancy: (H, W) int8 occupancy layer of the tag's storey (0 = free; see
            :class:`~markerplace.plan.discretize.artifact.Discretization`), or None (rays only).
        origin / resolution: the grid's lower-left corner (x0, y0) and cell size, metres.
        position: (3,) tag centre; normal: (3,) horizontal wall normal towards the room.
        want: preferred distance, metres.
        see: (K, 3) points the camera must have in sight (nothing in between), e.g. the tag and
            the corner its dimension line runs to; None: none.

    Returns:
        The largest distance in steps of 0.1 m from ``want`` down to :data:`MIN_DISTANCE` whose
        camera is at least :data:`BODY_CLEARANCE` short of the first obstacle along the normal,
        on a free occupancy cell and in sight of ``see`` (a camera looking through a doorway
        from the next room steps into the tag's room); without such a step, the largest one
        that meets the first two; without that, the largest one short of the obstacle; never
        below 0.3 m.
    """
    p = np.asarray(position, float)
    n = np.asarray(normal, float)
    hit, _ = caster.first_hits((p + 0.05 * n)[None], n[None], max_t=want + 1.0)
    limit = min(want, float(hit[0]) + 0.05 - BODY_CLEARANCE) if np.isfinite(hit[0]) else want
    steps = np.round(np.arange(limit, MIN_DISTANCE - 1e-9, -0.1), 3)

    def free(d: float) -> bool:
        if occupancy is None:
            return True
        H, W = occupancy.shape
        c = p + d * n
        col = int(np.floor((c[0] - origin[0]) / resolution))
        row = int(np.floor((c[1] - origin[1]) / resolution))
        return 0 <= row < H and 0 <= col < W and occupancy[row, col] == 0

    def in_sight(d: float) -> bool:
        if see is None or len(see) == 0:
            return True
        pts = np.asarray(see, float).reshape(-1, 3)
        c = p + d * n
        dist = np.linalg.norm(pts - c, axis=1)
        t, _ = caster.first_hits(np.tile(c, (len(pts), 1)), pts - c, max_t=dist)
        return bool(np.all(~np.isfinite(t) | (t >= dist - 0.05)))

    ok = [d for d in steps if free(d)]
    seen = [d for d in ok if in_sight(d)]
    if seen:
        return float(seen[0])
    if ok:
        return float(ok[0])
    return float(max(limit, 0.3)) if len(steps) == 0 else float(steps[0])


def _bgr(rgb: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(rgb[..., ::-1])


FONT_SCALE = 0.6
FONT_THICKNESS = 2
LABEL_PAD = 3
"""White margin around a label's text, pixels (part of its box)."""


@dataclass(frozen=True)
class Label:
    """A text label drawn on a view: its text and its box (x0, y0, x1, y1), pixels, the white
    background included (x1, y1 exclusive)."""

    text: str
    box: tuple[int, int, int, int]


class LabelLayout:
    """Places the text labels of one image so that no two overlap and each stays inside it.

    Each label comes with anchor points in order of preference; the first box at an anchor that
    is inside the image and clear of every box placed (or reserved) so far wins; when none is,
    the boxes around the first anchor are searched outwards, ring by ring, for the nearest clear
    one. ``labels`` lists them; :meth:`draw` writes them, last, over every line.
    """

    def __init__(self, width: int, height: int):
        self.width, self.height = int(width), int(height)
        self.labels: list[Label] = []
        self._colors: list[tuple[int, int, int]] = []
        self._taken: list[tuple[int, int, int, int]] = []

    def draw(self, rgb: np.ndarray) -> np.ndarray:
        """A copy of the (H, W, 3) RGB image with every placed label written on its white box."""
        img = _bgr(rgb)
        for lab, color in zip(self.labels, self._colors):
            _draw_label(img, lab.text, lab.box, color)
        return img[..., ::-1].copy()

    @staticmethod
    def size(text: str) -> tuple[int, int]:
        """(width, height) of a label's box, pixels (text plus :data:`LABEL_PAD` on every side)."""
        import cv2

        (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, FONT_SCALE, FONT_THICKNESS)
        return tw + 2 * LABEL_PAD, th + base + 2 * LABEL_PAD

    def reserve(self, box: tuple[int, int, int, int]) -> None:
        """Keep labels off ``box`` (x0, y0, x1, y1), e.g. the tag's outline."""
        self._taken.append(tuple(int(v) for v in box))

    def _clear(self, box) -> bool:
        x0, y0, x1, y1 = box
        if x0 < 0 or y0 < 0 or x1 > self.width or y1 > self.height:
            return False
        return all(x1 <= a0 or a1 <= x0 or y1 <= b0 or b1 <= y0 for a0, b0, a1, b1 in self._taken)

    def place(self, text: str, anchors: Sequence[tuple[float, float]], color_bgr=(0, 0, 0)) -> tuple[int, int, int, int]:
        """The box of ``text`` (x0, y0, x1, y1): centred on the first anchor (x, y) where it is
        clear, else the nearest clear box around the first anchor. Records it (to be drawn in
        ``color_bgr`` by :meth:`draw`)."""
        w, h = self.size(text)

        def box_at(cx, cy):
            x0, y0 = int(round(cx - w / 2)), int(round(cy - h / 2))
            return x0, y0, x0 + w, y0 + h

        def inside(b):
            x0 = int(np.clip(b[0], 0, max(0, self.width - w)))
            y0 = int(np.clip(b[1], 0, max(0, self.height - h)))
            return x0, y0, x0 + w, y0 + h

        choice = next((b for b in (box_at(*a) for a in anchors) if self._clear(b)), None)
        if choice is None:
            cx, cy = anchors[0]
            step = 4
            for ring in range(1, max(self.width, self.height) // step):
                r = ring * step
                ring_boxes = [inside(box_at(cx + dx, cy + dy)) for dx in range(-r, r + 1, step)
                              for dy in (-r, r)] + [inside(box_at(cx + dx, cy + dy)) for dy in range(-r + step, r, step)
                                                    for dx in (-r, r)]
                ring_boxes.sort(key=lambda b: (b[0] + w / 2 - cx) ** 2 + (b[1] + h / 2 - cy) ** 2)
                choice = next((b for b in ring_boxes if self._clear(b)), None)
                if choice is not None:
                    break
        if choice is None:  # an image too small for its labels: the first anchor, kept inside
            choice = inside(box_at(*anchors[0]))
        self._taken.append(choice)
        self.labels.append(Label(text, choice))
        self._colors.append(tuple(int(v) for v in color_bgr))
        return choice


def _draw_label(img_bgr: np.ndarray, text: str, box: tuple[int, int, int, int], color) -> None:
    """Write ``text`` on a white box (a :class:`LabelLayout` box)."""
    import cv2

    x0, y0, x1, y1 = box
    (_, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, FONT_SCALE, FONT_THICKNESS)
    cv2.rectangle(img_bgr, (x0, y0), (x1 - 1, y1 - 1), (255, 255, 255), -1)
    cv2.putText(img_bgr, text, (x0 + LABEL_PAD, y0 + LABEL_PAD + th), cv2.FONT_HERSHEY_SIMPLEX, FONT_SCALE, color,
                FONT_THICKNESS, cv2.LINE_AA)


def _outline_uv(K: np.ndarray, world_from_cam: np.ndarray, marker) -> np.ndarray | None:
    """(4, 2) pixel corners of the rectangle 1.2 times the tag's sheet, None when behind the camera."""
    h = 0.6 * outer_size(marker.size)
    local = np.array([[-h, h, 0], [h, h, 0], [h, -h, 0], [-h, -h, 0]], float)
    corners = local @ marker.world_from_marker[:3, :3].T + marker.world_from_marker[:3, 3]
    uv, z = project(K, world_from_cam, corners)
    return uv if np.all(z > 0.05) else None


def draw_outline(rgb: np.ndarray, K: np.ndarray, world_from_cam: np.ndarray, marker, label: str | None = None,
                 thickness: int = 3, layout: LabelLayout | None = None) -> np.ndarray:
    """Draw a rectangle 1.2 times the tag's printed sheet (black square + quiet zone) around a
    marker, and ``label`` above it; returns a new (H, W, 3) RGB image. With a ``layout`` the
    outline is reserved (other labels keep off the tag) and the label only placed (drawn by
    ``layout.draw``, after every line); without one it is drawn here."""
    import cv2

    img = _bgr(rgb)
    own = layout is None
    layout = layout or LabelLayout(img.shape[1], img.shape[0])
    uv = _outline_uv(K, world_from_cam, marker)
    if uv is not None:
        pts = np.round(uv).astype(np.int32).reshape(-1, 1, 2)
        cv2.polylines(img, [pts], True, OUTLINE_BGR, thickness, cv2.LINE_AA)
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        layout.reserve((lo[0] - thickness, lo[1] - thickness, hi[0] + thickness + 1, hi[1] + thickness + 1))
        if label:
            w, h = layout.size(label)
            mid = 0.5 * (lo[0] + hi[0])
            layout.place(label, [(mid, lo[1] - h / 2 - 4), (mid, hi[1] + h / 2 + 4)], OUTLINE_BGR)
    out = img[..., ::-1].copy()
    return layout.draw(out) if own else out


def draw_dimension(rgb: np.ndarray, K: np.ndarray, world_from_cam: np.ndarray, a: np.ndarray, b: np.ndarray,
                   text: str, ticks: bool = True, text_below: bool = False,
                   layout: LabelLayout | None = None) -> np.ndarray:
    """Draw a dimension line between world points ``a`` and ``b`` (3,) with end ticks (unless
    ``ticks`` is False: a plain extension line) and ``text`` next to its middle (under it with
    ``text_below``, else right of it, or where no other label of ``layout`` is); returns a new RGB
    image. With a ``layout`` the text is only placed (drawn by ``layout.draw``, after every
    line). Nothing is drawn when either end is behind the camera."""
    import cv2

    img = _bgr(rgb)
    own = layout is None
    layout = layout or LabelLayout(img.shape[1], img.shape[0])
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
        if text:
            w, h = layout.size(text)
            mid = np.clip(0.5 * (uv[0] + uv[1]), [0, 0], [W - 1, H - 1])
            below, right, left = (mid[0], mid[1] + h / 2 + 6), (mid[0] + w / 2 + 8, mid[1]), (mid[0] - w / 2 - 8, mid[1])
            above = (mid[0], mid[1] - h / 2 - 6)
            layout.place(text, [below, above, right, left] if text_below else [right, left, below, above], color)
    out = img[..., ::-1].copy()
    return layout.draw(out) if own else out


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
        close_labels, wide_labels: the :class:`Label` s drawn on each view (no two overlap).
    """

    close: np.ndarray
    wide: np.ndarray
    close_distance: float
    wide_distance: float
    close_from_cam: np.ndarray
    wide_from_cam: np.ndarray
    close_labels: tuple = ()
    wide_labels: tuple = ()


def render_installer_views(scene, markers: Sequence, places: Sequence, caster, occupancy_of, origin,
                           resolution: float, labels: Sequence[str]) -> list[InstallerViews]:
    """Render the close and wide view of every marker.

    Args:
        scene: the scene (internal frame).
        markers: the placed :class:`~markerplace.markers.Marker` list (all are drawn in every view).
        places: one :class:`~markerplace.report.captions.TagPlace` per marker (fitted wall
            normal, the floor under it, nearest corner or door edge on each side).
        caster: ray caster of the scene.
        occupancy_of: function marker index -> (H, W) occupancy layer of its storey, or None.
        origin / resolution: the occupancy grid's lower-left corner and cell size, metres.
        labels: outline label per marker (e.g. ``"#1 id 0"``).
    """
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
            ref = place.reference_point()
            see = np.array([p + 0.02 * n] + ([] if ref is None else [ref + 0.02 * n]))
            d_close = standing_distance(caster, occ, origin, resolution, p, n, CLOSE_DISTANCE, see[:1])
            d_wide = max(standing_distance(caster, occ, origin, resolution, p, n, WIDE_DISTANCE, see), d_close)
            T_close = world_from_cam_pose(p + d_close * n, yaw)
            T_wide = world_from_cam_pose(p + d_wide * n, yaw + wide_turn(place, d_wide))
            close_layout = LabelLayout(W, H)
            close = draw_outline(close_r.render(T_close, depth=False, normal=False).rgb, close_intr.K, T_close, m,
                                 labels[i], layout=close_layout)
            close = close_layout.draw(close)
            wide = wide_r.render(T_wide, depth=False, normal=False).rgb
            layout = LabelLayout(W, H)
            wide = draw_outline(wide, wide_intr.K, T_wide, m, labels[i], thickness=2, layout=layout)
            front = place.on_wall + 0.01 * n
            side = -1.0
            if ref is not None:
                name, end = place.nearest
                side = 1.0 if name == "left" else -1.0  # the height line goes on the other side
                below = np.array([0.0, 0.0, 0.6 * outer_size(m.size) + 0.12])  # under the outline, not across the tag
                wide = draw_dimension(wide, wide_intr.K, T_wide, front, front - below, "", ticks=False, layout=layout)
                wide = draw_dimension(wide, wide_intr.K, T_wide, front - below, ref + 0.01 * n - below,
                                      f"{end.distance:.2f} m to the {end.words(place.surface)}", text_below=True, layout=layout)
            beside = front + side * (0.6 * outer_size(m.size) + 0.15) * place.tangent
            wide = draw_dimension(wide, wide_intr.K, T_wide, np.array([beside[0], beside[1], place.floor_z]), beside,
                                  f"{place.height:.2f} m", layout=layout)
            wide = layout.draw(wide)
            views.append(InstallerViews(close, wide, d_close, d_wide, T_close, T_wide, tuple(close_layout.labels),
                                        tuple(layout.labels)))
    return views
