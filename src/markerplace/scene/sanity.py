"""Sanity checks of a mesh file on load (used by :mod:`markerplace.scene.loader`).

* :func:`drop_non_finite`: vertices with NaN/inf coordinates (or under a non-finite node
  transform) are dropped with the faces that use them, with a warning giving the counts; a file
  where more than :data:`MAX_NON_FINITE_FRACTION` of the vertices are bad is refused.
* :func:`recentre_offset`: the whole-metre offset that brings a model far from the origin
  (survey coordinates) back near it before the float32 conversion; see
  :mod:`markerplace.scene.worldframe` for how it is undone on every output.
* :func:`up_axis_scores` / :func:`check_up_axis`: which axis looks like "up" (a floor facing up
  at the bottom of the model, furniture tops facing up above it); warns, naming the ``--up``
  value, when another axis fits far better than the one the file was read with.
* :func:`missing_textures`: texture files a ``.gltf`` or an OBJ's ``.mtl`` refers to that do not
  exist, so the warning names them.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from markerplace.errors import UserError
from markerplace.scene.mesh_text import decode_text, original_names

log = logging.getLogger("markerplace.scene.loader")

_WARNED: set[str] = set()


def warn_once(message: str, *args) -> None:
    """Log a warning once per process, and only in the main process: the scene is loaded again
    by each stage and in every rendering worker, and the user needs to read it once."""
    text = message % args if args else message
    if multiprocessing.parent_process() is not None or text in _WARNED:
        log.debug(text)
        return
    _WARNED.add(text)
    log.warning(text)


MAX_NON_FINITE_FRACTION = 0.05
"""A file with more than this fraction of NaN/inf vertices is refused, not repaired."""
RECENTRE_DISTANCE_M = 1000.0
"""Models whose bounding-box centre is farther than this from the origin (any axis) are recentred.
float32 resolves 0.06 mm at 1 km and 62 mm at 1000 km."""


def drop_non_finite(instances: list[tuple], world_from_file: np.ndarray, path: Path) -> list[tuple]:
    """Remove vertices that are not finite in the world frame, and the faces using them.

    Args:
        instances: (name, trimesh.Trimesh, (4, 4) file_from_mesh, *rest) per mesh instance (``rest``
            is passed through).
        world_from_file: (4, 4) rotation and scale of the file into the world frame.
        path: the file (for messages).

    Returns:
        The instances, each mesh repaired in place (a mesh shared by several instances is
        repaired once), without instances left with no faces.

    Raises:
        UserError: more than :data:`MAX_NON_FINITE_FRACTION` of all vertices are bad.
    """
    bad_by_mesh: dict[int, np.ndarray] = {}
    total = bad = 0
    for _, mesh, file_from_mesh, *_ in instances:
        A = world_from_file @ file_from_mesh
        v = np.asarray(mesh.vertices, dtype=np.float64)
        if not np.all(np.isfinite(A)):
            mask = np.ones(len(v), dtype=bool)
        else:
            with np.errstate(all="ignore"):
                w = v @ A[:3, :3].T + A[:3, 3]
            mask = ~np.all(np.isfinite(w), axis=1)
        key = id(mesh)
        bad_by_mesh[key] = bad_by_mesh[key] | mask if key in bad_by_mesh else mask
        total += len(v)
        bad += int(mask.sum())
    if bad == 0:
        return instances
    if bad > MAX_NON_FINITE_FRACTION * total:
        raise UserError(f"{path}: {bad} of {total} vertices ({100 * bad / total:.0f} %) have NaN or infinite "
                        "coordinates; the file is damaged: re-export it")
    dropped_faces = 0
    done: set[int] = set()
    out = []
    for name, mesh, file_from_mesh, *rest in instances:
        key = id(mesh)
        if key not in done and bad_by_mesh[key].any():
            keep = ~bad_by_mesh[key][np.asarray(mesh.faces)].any(axis=1)
            dropped_faces += int((~keep).sum())
            mesh.update_faces(keep)
            mesh.remove_unreferenced_vertices()
            # unreferenced bad vertices stay in some trimesh versions: drop any that remain
            finite = np.all(np.isfinite(np.asarray(mesh.vertices, dtype=np.float64)), axis=1)
            if not finite.all():
                mesh.update_vertices(finite)
        done.add(key)
        if len(mesh.faces) > 0 and np.all(np.isfinite(world_from_file @ file_from_mesh)):
            out.append((name, mesh, file_from_mesh, *rest))
    warn_once("%s: dropped %d of %d vertices with NaN or infinite coordinates and the %d faces using them",
                path, bad, total, dropped_faces)
    return out


def recentre_offset(lo: np.ndarray, hi: np.ndarray, distance: float = RECENTRE_DISTANCE_M) -> np.ndarray:
    """(3,) whole-metre offset to subtract from world coordinates (float64) so the model's
    bounding box [lo, hi] is centred near the origin on every axis whose centre lies more than
    ``distance`` metres out (zero on the other axes)."""
    centre = 0.5 * (np.asarray(lo, dtype=np.float64) + np.asarray(hi, dtype=np.float64))
    return np.where(np.abs(centre) > distance, np.round(centre), 0.0)


# --- up axis -----------------------------------------------------------------------------------------

SIGNED_AXES = {"+x": (1.0, 0, 0), "-x": (-1.0, 0, 0), "+y": (0, 1.0, 0), "-y": (0, -1.0, 0),
               "+z": (0, 0, 1.0), "-z": (0, 0, -1.0)}
FLOOR_BAND_M = 0.3
"""A floor lies within this of the model's bottom along the up axis."""
FURNITURE_BAND_M = (0.3, 1.3)
"""Seats, tables and counters face up this far above the bottom."""
BOTTOM_SHARE = 0.1
"""The bottom is the lowest height facing up over this share of the footprint (in a floor band)."""
HORIZONTAL_COS = 0.95


def up_axis_scores(vertices: np.ndarray, faces: np.ndarray) -> dict[str, tuple[float, float]]:
    """How much each signed world axis looks like "up", from the geometry alone.

    For a candidate up axis a, with faces "facing up" when n.a > 0.95 and "facing down" when
    n.a < -0.95 (n the unit face normal) and heights h = centroid.a above the bottom, the lowest
    height with up-facing area of at least 10 % of the footprint within 0.3 m above it (not the
    lowest vertex: in a multi-level model that is a pit's or a stairwell's bottom, the floors lie
    above it):

        score(a) = area facing up with h < 0.3 m (floor)  -  area facing down there
                   + area facing up with 0.3 <= h <= 1.3 m (furniture tops)

    A floor seen from the room faces up at the bottom of the model; along a horizontal axis the
    bottom is an outer wall face or a wall seen edge-on. Looking at the model upside down swaps
    floor and ceiling, so the sign of up is told apart only by the furniture term.

    Args:
        vertices: (V, 3) world metres; faces: (F, 3) indices.

    Returns:
        axis name (``"+x"``, ..., ``"-z"``) -> (score in m^2, footprint in m^2: the bounding-box
        area across that axis).
    """
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(n, axis=1)
    ok = area2 > 0
    n = n[ok] / area2[ok, None]
    area = 0.5 * area2[ok]
    centroid = tri[ok].mean(axis=1)
    extent = v.max(axis=0) - v.min(axis=0)
    out = {}
    for name, axis in SIGNED_AXES.items():
        a = np.asarray(axis)
        d = n @ a
        up, down = d > HORIZONTAL_COS, d < -HORIZONTAL_COS
        i = int(np.argmax(np.abs(a)))
        footprint = float(np.prod(np.delete(extent, i)))
        h = centroid @ a - _bottom(centroid[up] @ a, area[up], float((v @ a).min()), BOTTOM_SHARE * footprint)
        floor = (h > -1e-6) & (h < FLOOR_BAND_M)
        furniture = (h >= FURNITURE_BAND_M[0]) & (h <= FURNITURE_BAND_M[1])
        score = area[up & floor].sum() - area[down & floor].sum() + area[up & furniture].sum()
        out[name] = (float(score), footprint)
    return out


def _bottom(heights: np.ndarray, areas: np.ndarray, lowest: float, min_area: float) -> float:
    """``lowest`` (the lowest vertex, metres along the axis) when the floor band above it holds
    ``min_area`` m^2 of the up-facing ``areas`` at ``heights``, else the lowest face height whose
    band does (else ``lowest``)."""
    order = np.argsort(heights)
    h, a = np.concatenate([[lowest], heights[order]]), np.concatenate([[0.0], areas[order]])
    cum = np.cumsum(a)
    ends = np.searchsorted(h, h + FLOOR_BAND_M, side="left") - 1  # last index in [h_i, h_i + band)
    ok = np.flatnonzero(cum[ends] - cum + a >= min_area)
    return float(h[ok[0]]) - 1e-6 if len(ok) else lowest


def check_up_axis(scene, world_from_file_rotation: np.ndarray, up_choices: dict[str, np.ndarray], path: Path,
                  up_read: str) -> str | None:
    """Warn (one line) when another axis looks far more like "up" than the world +z the file
    was read with, naming the ``--up`` value that would read it that way.

    "Far more": the other axis scores at least 30 % of its footprint (a real floor) and the
    axis as read scores under half of it. Returns the suggested ``--up`` value, else None.
    """
    vertices, faces = scene.geometry()
    if len(faces) == 0:
        return None
    scores = up_axis_scores(vertices, faces)
    best = max(scores, key=lambda k: scores[k][0])
    best_score, best_footprint = scores[best]
    current = scores["+z"][0]
    if best == "+z" or best_score < 0.3 * best_footprint or current >= 0.5 * best_score:
        return None
    # the world axis `best` is the file axis R^T a; find the --up value mapping it onto +z
    file_axis = world_from_file_rotation.T @ np.asarray(SIGNED_AXES[best])
    suggestion = next((k for k, R in up_choices.items() if np.allclose(R @ file_axis, (0, 0, 1), atol=1e-6)), None)
    if suggestion is None:
        return None
    warn_once("%s: read with --up %s, but its floor seems to face another way: %.0f m^2 of floor and furniture "
                "face up with --up %s against %.0f m^2 as read; if the plan looks wrong, pass --up %s",
                path, up_read, best_score, suggestion, max(current, 0.0), suggestion)
    return suggestion


# --- textures -----------------------------------------------------------------------------------------

def missing_textures(path: Path) -> list[str]:
    """Texture files that ``path`` (``.gltf``, or ``.obj`` through its ``.mtl`` files) names but
    that do not exist, as written in the file. Embedded and ``data:`` images are never missing."""
    path = Path(path)
    ext = path.suffix.lower()
    missing: list[str] = []
    try:
        if ext == ".gltf":
            doc = json.loads(path.read_text(encoding="utf-8"))
            for image in doc.get("images", []) or []:
                uri = image.get("uri") if isinstance(image, dict) else None
                if isinstance(uri, str) and not uri.startswith("data:") and not (
                        (path.parent / uri).is_file() or (path.parent / unquote(uri)).is_file()):
                    missing.append(uri)
        elif ext == ".obj":
            for mtl in _obj_material_libraries(path):
                if not mtl.is_file():
                    missing.append(mtl.name)
                    continue
                for line in decode_text(mtl.read_bytes()).splitlines():
                    parts = line.strip().split()
                    if parts and parts[0].lower().startswith("map_") and len(parts) > 1:
                        name = parts[-1]
                        if not any((mtl.parent / n).is_file() for n in original_names(name)):
                            missing.append(name)
    except (OSError, ValueError, AttributeError):
        return []
    return sorted(set(missing))


def _obj_material_libraries(path: Path) -> list[Path]:
    libs = []
    for line in decode_text(path.read_bytes()).splitlines():
        if line.startswith("mtllib"):
            name = line[len("mtllib"):].strip()
            if name:
                found = [path.parent / n for n in original_names(name) if (path.parent / n).is_file()]
                libs.append(found[0] if found else path.parent / name)
    return libs


def warn_missing_textures(path: Path) -> list[str]:
    """Log one warning naming the missing texture files of ``path``; returns them."""
    missing = missing_textures(path)
    if missing:
        shown = ", ".join(missing[:5]) + (f" and {len(missing) - 5} more" if len(missing) > 5 else "")
        warn_once("%s: texture file(s) not found next to it: %s; the parts using them are drawn without texture",
                    path, shown)
    return missing
