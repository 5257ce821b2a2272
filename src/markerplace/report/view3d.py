"""The 3D view of the reports: the model with its tags, to orbit, zoom and click, inside the page.

:func:`scene_view_html` returns an HTML fragment (a ``<canvas>``, the scene as base64 binary
arrays in a ``<script type="application/json">``, and the viewer) that ``report.html`` of
``plan`` (:mod:`markerplace.report.plan_report`) and ``check.html`` of ``check``
(:mod:`markerplace.report.check_page`) embed. The page stays one self-contained file that opens
offline.

**Why a hand-written WebGL viewer** (``view3d.js``, package data, about 400 lines) and not
three.js from the npm registry: the view needs one coloured mesh, some quads, a polyline, an orbit
camera and picking, which WebGL 1 does in a few hundred lines; vendoring three.js would add a
setup step that needs the network (``npm`` on a fresh machine), ~600 kB to every report and a
version to keep up with, for nothing the page uses. The viewer picks by rendering object ids
into an off-screen framebuffer and reading the pixel under the pointer.

**What is drawn**, in the scene's internal frame (:mod:`markerplace.scene.worldframe`; the view
shows no coordinates): the model, decimated to at most ``max_triangles`` triangles with Open3D's
quadric decimation (:func:`view_mesh`; vertex clustering first for a model of millions of
faces), one colour per vertex (the part's vertex colours, or its texture sampled at the vertices
when the part is dense as a scan's, or the texture's mean colour for the big faces of a
procedural scene, times the part's base colour; glass is left out), shaded flat by a headlight; each planned tag as a quad in :data:`PLANNED_COLOR` with its number beside
it; after a check, each tag as found as a smaller quad in :data:`FOUND_COLOR` in front; an
optional camera path as a polyline. Everything above the *cut height* (a slider; by default just
above the highest tag) is not drawn, so ceilings and roofs do not hide the rooms. Clicking a tag
selects its card in the page (``id`` given per tag) and scrolls to it.

Size: 100k triangles take about 1.5 to 4 MB of HTML (positions quantised to 16 bits over the
bounding box, sub-millimetre on a 20 m building; 8-bit colours; 16- or 32-bit indices).
"""

from __future__ import annotations

import base64
import json
import logging
from dataclasses import dataclass
from importlib import resources
from typing import Sequence

import numpy as np

from markerplace.report.html import esc

log = logging.getLogger(__name__)

__all__ = ["MAX_TRIANGLES", "PRE_CLUSTER", "PLANNED_COLOR", "FOUND_COLOR", "PATH_COLOR", "ViewMesh", "view_mesh", "scene_view_html",
           "viewer_script"]

MAX_TRIANGLES = 100_000
"""Default triangle budget of the view's copy of the model (a 300k-face scan is decimated to it)."""
DENSE_PART = 2_000
"""A textured part with at least this many faces (a scan's) is coloured by sampling its texture at
the vertices; a smaller one (a procedural wall of two triangles) by its texture's mean colour."""
PRE_CLUSTER = 3
"""A model of more than this many times ``max_triangles`` faces is first clustered (Open3D vertex
clustering, a voxel of its mean edge times sqrt(faces / (PRE_CLUSTER max_triangles)): about
twice the budget) before the quadric decimation, which is slow on millions of faces."""
PLANNED_COLOR = (232, 89, 12)
"""RGB of a planned tag's quad (orange)."""
FOUND_COLOR = (28, 126, 214)
"""RGB of a tag as found (installed) by a check (blue)."""
PATH_COLOR = (47, 158, 68)
"""RGB of the camera path (green)."""
PLANNED_LIFT, FOUND_LIFT, FOUND_SCALE = 0.01, 0.02, 0.7
"""Quads float this far (metres) in front of their wall; a found tag is drawn at this fraction of its size."""
PATH_POINTS = 5_000
"""A longer camera path is subsampled to this many positions."""


@dataclass(frozen=True)
class ViewMesh:
    """The view's copy of a scene.

    Attributes:
        vertices: (V, 3) float32, metres, the scene's frame.
        faces: (F, 3) uint32 vertex indices.
        colors: (V, 3) uint8 RGB.
        source_faces: how many faces the scene had (before decimation, glass excluded).
    """

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    source_faces: int


def _part_colors(part) -> np.ndarray:
    """(N, 3) uint8 colour per vertex of one :class:`~markerplace.scene.types.MeshPart`."""
    n = len(part.vertices)
    base = np.asarray(part.base_color, float)[:3]
    if part.colors is not None:
        rgb = np.asarray(part.colors, float)[:, :3]
    elif part.texture is not None:
        tex = np.asarray(part.texture)
        if part.uv is not None and len(part.faces) >= DENSE_PART:
            h, w = tex.shape[:2]
            uv = np.asarray(part.uv, float)
            uv = np.where((uv < 0) | (uv > 1), uv % 1.0, uv)  # repeat outside [0, 1], as the renderer does
            col = np.clip((uv[:, 0] * w).astype(int), 0, w - 1)
            row = np.clip(((1.0 - uv[:, 1]) * h).astype(int), 0, h - 1)  # v grows upwards, row 0 = top
            rgb = tex[row, col, :3].astype(float)
        else:
            rgb = np.broadcast_to(tex.reshape(-1, tex.shape[-1])[:, :3].mean(axis=0), (n, 3))
    else:
        rgb = np.full((n, 3), 255.0)
    return np.clip(np.round(rgb * base), 0, 255).astype(np.uint8)


def view_mesh(scene, max_triangles: int = MAX_TRIANGLES) -> ViewMesh:
    """The scene's opaque parts as one vertex-coloured mesh of at most ``max_triangles`` triangles
    (Open3D quadric decimation when it has more, after vertex clustering when it has more than
    :data:`PRE_CLUSTER` times that; vertex colours are carried along)."""
    parts = [p for p in scene.parts if not p.transparent and len(p.faces)]
    if not parts:
        return ViewMesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32), np.zeros((0, 3), np.uint8), 0)
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts])
    verts = np.concatenate([np.asarray(p.vertices, np.float64) for p in parts])
    faces = np.concatenate([np.asarray(p.faces, np.int64) + o for p, o in zip(parts, offsets)])
    colors = np.concatenate([_part_colors(p) for p in parts])
    source = len(faces)
    if source > max_triangles:
        import open3d as o3d

        mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(verts), o3d.utility.Vector3iVector(faces))
        mesh.vertex_colors = o3d.utility.Vector3dVector(colors / 255.0)
        if source > PRE_CLUSTER * max_triangles:  # a dense scan: vertex clustering first (13x faster on 1.1 M faces)
            sample = faces[:: max(1, source // 20_000)]
            edge = float(np.linalg.norm(verts[sample[:, 0]] - verts[sample[:, 1]], axis=1).mean())
            voxel = edge * np.sqrt(source / (PRE_CLUSTER * max_triangles))
            mesh = mesh.simplify_vertex_clustering(voxel, o3d.geometry.SimplificationContraction.Average)
        mesh = mesh.simplify_quadric_decimation(target_number_of_triangles=int(max_triangles))
        mesh.remove_unreferenced_vertices()
        verts, faces = np.asarray(mesh.vertices), np.asarray(mesh.triangles)
        colors = np.clip(np.round(np.asarray(mesh.vertex_colors) * 255.0), 0, 255).astype(np.uint8)
        log.info("3D view: %d faces decimated to %d", source, len(faces))
    return ViewMesh(verts.astype(np.float32), faces.astype(np.uint32), colors.astype(np.uint8), source)


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def _tags(markers: Sequence, lift: float, scale: float, labels: Sequence[str], cards: Sequence[str | None]) -> list:
    out = []
    for m, label, card in zip(markers, labels, cards):
        T = np.asarray(m.world_from_marker, float)
        c = T[:3, 3] + lift * T[:3, 2]
        h = 0.5 * float(m.size) * scale
        u, v = h * T[:3, 0], h * T[:3, 1]
        corners = [c - u - v, c + u - v, c + u + v, c - u + v]
        out.append({"id": int(m.tag_id), "label": str(label), "card": card,
                    "corners": [[round(float(x), 4) for x in p] for p in corners],
                    "centre": [round(float(x), 4) for x in c], "normal": [round(float(x), 4) for x in T[:3, 2]],
                    "up": [round(float(x), 4) for x in T[:3, 1]], "size": float(m.size)})
    return out


def viewer_script() -> str:
    """The viewer (``view3d.js``) as one inline ``<script>``; it starts every ``.mp-view3d`` on the
    page once, so a page may hold it more than once."""
    js = resources.files("markerplace.report").joinpath("view3d.js").read_text(encoding="utf-8")
    return f"<script>\n{js}\n</script>"


def scene_view_html(scene, planned: Sequence, found: Sequence | None = None, camera_path: np.ndarray | None = None,
                    max_triangles: int = MAX_TRIANGLES, *, planned_labels: Sequence[str] | None = None,
                    planned_cards: Sequence[str | None] | None = None, found_labels: Sequence[str] | None = None,
                    found_cards: Sequence[str | None] | None = None, view_id: str = "mp-view3d",
                    height_px: int = 560) -> str:
    """An HTML fragment: the 3D view of ``scene`` with its tags (see the module docstring).

    Args:
        scene: a :class:`~markerplace.scene.types.Scene`; every position below is in its frame.
        planned: the planned :class:`~markerplace.markers.Marker` list, placement order.
        found: the tags as found or installed (a check), or None.
        camera_path: (P, 3) camera positions, metres, in walking order (a photo walk), or None.
        max_triangles: the model's triangle budget in the view (:func:`view_mesh`).
        planned_labels, found_labels: the number drawn beside each tag (default ``1, 2, ...`` for
            the planned tags, ``id N`` for the found ones).
        planned_cards, found_cards: per tag the ``id`` of the page element its click selects
            (default ``tag1, tag2, ...`` for the planned tags, the plan report's cards; none for the
            found ones); None for a tag without a card.
        view_id: the element id of the view (unique on the page); tests reach the viewer as
            ``window.mpView3d[view_id]``.
        height_px: the canvas height, CSS pixels (its width follows the page).

    Returns:
        HTML: a ``<div class="mp-view3d">`` with the canvas, its controls and data, then the viewer's
        ``<script>``.
    """
    planned, found = list(planned), list(found or [])
    mesh = view_mesh(scene, max_triangles)
    lo = mesh.vertices.min(axis=0).astype(float) if len(mesh.vertices) else np.zeros(3)
    hi = mesh.vertices.max(axis=0).astype(float) if len(mesh.vertices) else np.ones(3)
    extent = np.maximum(hi - lo, 1e-6)
    q = np.round((mesh.vertices - lo) / extent * 65535.0).clip(0, 65535).astype("<u2")
    wide = len(mesh.vertices) > 65535
    index = mesh.faces.astype("<u4" if wide else "<u2")
    path = np.zeros((0, 3)) if camera_path is None else np.asarray(camera_path, float).reshape(-1, 3)
    if len(path) > PATH_POINTS:
        path = path[np.linspace(0, len(path) - 1, PATH_POINTS).round().astype(int)]
    data = {
        "lo": lo.tolist(), "extent": extent.tolist(), "positions": _b64(q), "colors": _b64(mesh.colors),
        "indices": _b64(index), "index_bits": 32 if wide else 16, "triangles": int(len(mesh.faces)),
        "source_triangles": mesh.source_faces,
        "planned": _tags(planned, PLANNED_LIFT, 1.0, planned_labels or [str(i + 1) for i in range(len(planned))],
                         planned_cards or [f"tag{i + 1}" for i in range(len(planned))]),
        "found": _tags(found, FOUND_LIFT, FOUND_SCALE, found_labels or [f"id {m.tag_id}" for m in found],
                       found_cards or [None] * len(found)),
        "path": [[round(float(x), 3) for x in p] for p in path],
        "colors_rgb": {"planned": PLANNED_COLOR, "found": FOUND_COLOR, "path": PATH_COLOR},
    }
    blob = json.dumps(data, separators=(",", ":")).replace("</", "<\\/")
    legend = [f'<span class="mp-swatch" style="background:rgb{PLANNED_COLOR}"></span> planned tags']
    if found:
        legend.append(f'<span class="mp-swatch" style="background:rgb{FOUND_COLOR}"></span> tags as found')
    if len(path):
        legend.append(f'<span class="mp-swatch" style="background:rgb{PATH_COLOR}"></span> camera path')
    decimated = (f"; the model decimated from {mesh.source_faces:,} to {len(mesh.faces):,} triangles"
                 if mesh.source_faces > len(mesh.faces) else "")
    vid = esc(view_id)
    return (f'<div class="mp-view3d" id="{vid}">'
            f'<div class="mp-view3d-stage" style="height:{int(height_px)}px"><canvas></canvas>'
            '<div class="mp-view3d-labels"></div></div>'
            '<div class="mp-view3d-bar"><label>cut above <input type="range" class="mp-cut" step="0.05"> '
            '<span class="mp-cut-value"></span> m</label> <button type="button" class="mp-reset">reset view</button> '
            + " ".join(legend) + '</div>'
            f'<p class="note">Drag to orbit, right-drag or shift-drag to pan, wheel to zoom; click a tag for its '
            f'card. Nothing above the cut height is drawn (move the slider to see lower storeys){decimated}.</p>'
            f'<script type="application/json" class="mp-view3d-data">{blob}</script></div>' + viewer_script())
