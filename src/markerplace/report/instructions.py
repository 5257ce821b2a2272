"""The installer's instructions for each placed tag: one ``install`` object per marker in
``placement.json``, and the words made from it for ``placement.csv``, the captions of
``tags.pdf`` and ``tags/*.svg``, and ``report.html`` (one source, so they never disagree).

An ``install`` object holds everything a person (or a test) needs to hang the tag with a tape
measure and nothing else, in the plan's frame (the model file's coordinates, z up, metres):

=================  ==========================================================================
``storey``         storey index (0 = the lowest storey found); ``storey_floor_z``: its floor
``room``           the room the tag's wall belongs to (built-in scenes; null for mesh files)
``wall``           the wall it hangs on, one of 8 compass sectors (+x = east, +y = north of the
                   model), e.g. ``"north"``; ``facing``: the way its printed side looks
                   (``"south"``); ``facing_deg``: that direction, degrees counter-clockwise from +x
``surface``        what the tag is on (the plan's ``surface`` of the marker when it has one, else
                   ``"wall"``)
``floor_z``        the floor at the foot of the wall under the tag (where the installer stands;
                   never furniture: the plan's floor map)
``height_m``       the tag centre (the middle of the black square) above ``floor_z``
``left``/``right`` as you face the wall: ``reference`` (``corner``, ``door edge``, ``wall end`` or
                   ``none``), ``distance_m`` from the reference to the tag centre along the wall
                   plane (the same at the tag's height and at the floor line; null when none)
                   and ``point``, the reference on the wall at the tag's height (x, y, z)
``measure_from``   ``"left"`` or ``"right"``: the nearer reference (the one the views show)
``wall_point``     the wall surface behind the tag centre (x, y, z); ``wall_normal``: out of the
                   wall into the room; ``right_dir``: along the wall to the installer's right
``edge_down``      ``"caption"``: the printed tag's bottom edge is the one its caption is under,
                   marked "this edge down" (for tiled tags: under the bottom row of tiles)
``pages``          the pages of ``tags.pdf`` that hold the tag (1-based; a tiled tag's page map
                   first); ``tiles``: [rows, columns] of its tiles ([1, 1]: one page)
=================  ==========================================================================

So: the tag's centre is ``wall_point`` = reference ``point`` moved ``distance_m`` along the wall
towards the tag (``right_dir`` for the left reference, against it for the right one), at
``floor_z + height_m``; it hangs flat on the wall, upright (its top edge horizontal, caption
edge down), facing ``wall_normal``.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from markerplace.report.captions import MAX_RANGE, TagPlace, WallEnd, describe_tag, facing_label, facing_name, wall_side
from markerplace.runtime.atomic_io import fixed
from markerplace.scene.raycast import RayCaster

__all__ = ["install_instructions", "install_to_frame", "place_from_install", "storey_words", "wall_words",
           "height_words", "along_words", "surface_name", "pages_words", "CHECKLIST_COLUMNS", "checklist_row", "caption_lines"]

CHECKLIST_COLUMNS = ["order", "tag_id", "storey", "floor_z_m", "room", "wall", "faces", "surface",
                     "centre_height_above_floor_m", "left_reference", "left_reference_to_centre_m",
                     "right_reference", "right_reference_to_centre_m", "size_mm", "tags_pdf_pages", "x", "y", "z",
                     "yaw_deg", "gain"]
"""Columns of ``placement.csv``: one row per tag, in the order to hang them."""


def surface_name(surface) -> str:
    """Words for a marker's ``surface`` field (a string, or an object with ``kind``/``name``/
    ``label``); ``"wall"`` when absent."""
    if isinstance(surface, dict):
        surface = surface.get("kind") or surface.get("name") or surface.get("label")
    return "wall" if not surface else str(surface).replace("_", " ")


def _room_of(rooms: Sequence, point: np.ndarray, floor_z: float) -> str | None:
    """Name of the room whose footprint holds ``point`` (3,) and whose floor is within 0.6 m of
    ``floor_z``; None when none (mesh files have no rooms)."""
    for r in rooms:
        x0, y0, x1, y1 = r.bounds
        if x0 <= point[0] <= x1 and y0 <= point[1] <= y1 and abs(r.floor_z - floor_z) <= 0.6:
            return r.name.replace("_", " ")
    return None


def _end(place: TagPlace, side: str) -> dict:
    end = place.left if side == "left" else place.right
    point = place.end_point(side)
    return {"reference": end.kind, "distance_m": float(end.distance) if np.isfinite(end.distance) else None,
            "point": None if point is None else [float(v) for v in point]}


def install_instructions(scene, markers: Sequence, storeys: Sequence[int], storey_floors: Sequence[float],
                         floors: Sequence[float], surfaces: Sequence | None = None, caster=None) -> list[dict]:
    """One ``install`` object per marker (module docstring), in the frame of ``scene``.

    Args:
        scene: the scene (its ray caster measures the walls; its ``rooms`` name them).
        markers: placed :class:`~markerplace.markers.Marker` s, same frame.
        storeys / storey_floors: each marker's storey index and that storey's floor z, metres.
        floors: (M,) the floor under each tag, world z metres (the plan's floor map: a planned tag
            centre stands ``--height`` above it).
        surfaces: each marker's ``surface`` field (None: a wall).
        caster: the scene's :class:`~markerplace.scene.raycast.RayCaster` (built when None).
    """
    if caster is None and len(markers):
        caster = RayCaster(*scene.geometry())
    out = []
    for i, m in enumerate(markers):
        place = describe_tag(caster, np.asarray(m.position, float), np.asarray(m.normal, float), float(floors[i]))
        side = place.nearest[0]
        n = place.normal
        out.append({
            "storey": int(storeys[i]), "storey_floor_z": float(storey_floors[i]),
            "room": _room_of(getattr(scene, "rooms", ()), place.on_wall + 0.3 * n, place.floor_z),
            "wall": wall_side(n), "facing": facing_name(n),
            "facing_deg": float(np.degrees(np.arctan2(n[1], n[0])) % 360.0),
            "surface": surface_name(None if surfaces is None else surfaces[i]),
            "floor_z": place.floor_z, "height_m": place.height,
            "left": _end(place, "left"), "right": _end(place, "right"),
            "measure_from": side if np.isfinite(place.nearest[1].distance) else None,
            "wall_point": [float(v) for v in place.on_wall], "wall_normal": [float(v) for v in n],
            "right_dir": [float(v) for v in place.tangent], "edge_down": "caption",
        })
    return out


POINT_DECIMALS = 4
"""Points, heights and distances of an ``install`` object are rounded to 0.1 mm."""
VECTOR_DECIMALS = 6


def _rounded(install: dict) -> dict:
    """``install`` with points, heights and distances rounded to :data:`POINT_DECIMALS`, unit
    vectors to :data:`VECTOR_DECIMALS` and the facing angle to 0.01 degree."""
    def pts(v, k=POINT_DECIMALS):
        return None if v is None else [round(float(x), k) + 0.0 for x in v]

    d = dict(install)
    for key in ("storey_floor_z", "floor_z", "height_m"):
        d[key] = round(float(d[key]), POINT_DECIMALS) + 0.0
    d["facing_deg"] = round(float(d["facing_deg"]), 2) % 360.0 + 0.0
    d["wall_point"] = pts(d["wall_point"])
    d["wall_normal"], d["right_dir"] = pts(d["wall_normal"], VECTOR_DECIMALS), pts(d["right_dir"], VECTOR_DECIMALS)
    for side in ("left", "right"):
        e = dict(d[side])
        e["distance_m"] = None if e["distance_m"] is None else round(float(e["distance_m"]), POINT_DECIMALS) + 0.0
        e["point"] = pts(e["point"])
        d[side] = e
    return d


def install_to_frame(install: dict, offset) -> dict:
    """A copy of ``install`` with its points and heights moved by ``offset`` (3,) metres (e.g. the
    internal frame to the user's: ``p_user = p_internal + offset``; None: not moved), rounded
    (points to 0.1 mm, unit vectors to 1e-6)."""
    o = np.zeros(3) if offset is None else np.asarray(offset, float)
    d = dict(install)
    d["storey_floor_z"] = install["storey_floor_z"] + o[2]
    d["floor_z"] = install["floor_z"] + o[2]
    d["wall_point"] = [float(v) for v in np.add(install["wall_point"], o)]
    for side in ("left", "right"):
        e = dict(install[side])
        if e.get("point") is not None:
            e["point"] = [float(v) for v in np.add(e["point"], o)]
        d[side] = e
    return _rounded(d)


def place_from_install(install: dict) -> TagPlace:
    """The :class:`~markerplace.report.captions.TagPlace` an ``install`` object describes (same frame)."""
    def end(side):
        e = install[side]
        return WallEnd(np.inf if e["distance_m"] is None else float(e["distance_m"]), e["reference"])

    n = np.asarray(install["wall_normal"], float)

    return TagPlace(facing_label(n), install["wall"], float(install["height_m"]), float(install["floor_z"]),
                    end("left"), end("right"), n, np.asarray(install["right_dir"], float),
                    np.asarray(install["wall_point"], float), install.get("surface") or "wall")


def storey_words(install: dict) -> str:
    """E.g. ``"storey 1 (floor 3.00 m)"``, plus where the floor under the tag differs from it
    (a sunken room, a step)."""
    text = f"storey {install['storey']} (floor {install['storey_floor_z']:.2f} m)"
    step = install["floor_z"] - install["storey_floor_z"]
    if abs(step) >= 0.005:
        text += f", where the floor is {abs(step):.2f} m {'above' if step > 0 else 'below'} it"
    return text


def wall_words(install: dict) -> str:
    """E.g. ``"north wall of the kitchen (faces south)"``, or ``"bookcase front at the north wall
    (faces south)"`` when the tag is on something else than a wall."""
    where = f"{install['wall']} wall" + (f" of the {install['room']}" if install.get("room") else "") + \
        f" (faces {install['facing']})"
    surface = install.get("surface") or "wall"
    return where if surface == "wall" else f"{surface} at the {where}"


def height_words(install: dict) -> str:
    """E.g. ``"centre 1.50 m above the floor"``."""
    return f"centre {install['height_m']:.2f} m above the floor"


def along_words(install: dict, both: bool = True) -> str:
    """E.g. ``"1.20 m from the corner on the left, 2.05 m from the door edge on the right"``: the
    nearer first; ``both=False``: only the nearer. Distances are to the tag centre."""
    parts = []
    first = install.get("measure_from")
    surface = install.get("surface") or "wall"
    for side in ([first, "right" if first == "left" else "left"] if first else []):
        e = install[side]
        if e["distance_m"] is None:
            continue
        word = WallEnd(0.0, e["reference"]).words(surface)
        parts.append(f"{e['distance_m']:.2f} m from the {word} on the left" if side == "left"
                     else f"{e['distance_m']:.2f} m from the {word} on the right")
        if not both:
            break
    return ", ".join(parts) if parts else f"no corner or door edge within {MAX_RANGE:g} m"


def pages_words(pages: Sequence[int]) -> str:
    """``"14-26"`` for consecutive pages, ``"3"`` for one, ``""`` for none."""
    pages = list(pages)
    if not pages:
        return ""
    return str(pages[0]) if len(pages) == 1 else f"{pages[0]}-{pages[-1]}"


def caption_lines(record: dict) -> list[str]:
    """The caption printed under a tag (tags.pdf, tags/*.svg): which tag, where it goes, and
    "this edge down" (the caption marks the tag's bottom edge)."""
    head = f"#{record['order']}  {record['family']} id {record['tag_id']}  black square {1000 * record['size']:.0f} mm"
    inst = record.get("install")
    if inst is None:
        x, y, z = record["position"]
        return [head, f"tag centre ({x:.2f}, {y:.2f}, {z:.2f}) m, facing {record['yaw_deg']:.0f} deg",
                "this edge down"]
    return [head, f"storey {inst['storey']}, {wall_words(inst)}",
            f"{height_words(inst)}; {along_words(inst, both=False)}", "this edge down"]


def checklist_row(record: dict) -> list:
    """One ``placement.csv`` row (:data:`CHECKLIST_COLUMNS`) of a placement.json marker record
    with its ``install`` object."""
    inst = record["install"]
    x, y, z = record["position"]
    left, right = inst["left"], inst["right"]
    return [record["order"], record["tag_id"], inst["storey"], fixed(inst["floor_z"], 3), inst.get("room") or "",
            inst["wall"], inst["facing"], inst.get("surface") or "wall", fixed(inst["height_m"], 3),
            left["reference"], fixed(left["distance_m"], 3), right["reference"], fixed(right["distance_m"], 3),
            f"{1000 * record['size']:.0f}", pages_words(inst.get("pages", [])),
            fixed(x, 4), fixed(y, 4), fixed(z, 4), fixed(record["yaw_deg"], 2),
            "" if record.get("gain") is None else f"{record['gain']:.6g}"]
