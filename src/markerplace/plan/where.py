"""Where the cameras will be (``plan --where FILE``, ``evaluate --where FILE``): a weight per
feasible camera pose from the places and directions of use.

The file is a GeoJSON FeatureCollection in the model's frame (the frame of placement.json:
metres, x/y of the world, z up; not longitude/latitude), format in docs/where.md::

    {"type": "FeatureCollection", "default_weight": 0,
     "features": [
       {"type": "Feature", "properties": {"name": "kitchen", "weight": 2},
        "geometry": {"type": "Polygon", "coordinates": [[[0, 4], [6, 4], [6, 7.5], [0, 7.5], [0, 4]]]}},
       {"type": "Feature", "properties": {"width": 1.2, "heading": "along"},
        "geometry": {"type": "LineString", "coordinates": [[1, 5.5], [9.5, 5.2]]}},
       {"type": "Feature", "properties": {"radius": 0.5, "yaw_deg": [90]},
        "geometry": {"type": "Point", "coordinates": [3, 2]}}]}

* ``Polygon`` (a zone, a room): the poses inside its outer ring and outside its holes.
* ``LineString`` (a route): the poses within ``width``/2 (required, metres, > 0) of the polyline;
  with ``heading`` ``"along"`` only those looking along it (either way of travel), ``"forward"``
  only those looking the way its points go; without ``heading`` every yaw.
* ``Point`` (listed poses): the poses within ``radius`` (metres, default 0.5) of it; with
  ``yaw_deg`` (a number or a list) only those looking that way.

A pose's yaw counts as "looking that way" when it is within ``heading_tolerance_deg`` (default
:data:`DEFAULT_TOLERANCE_DEG`, inclusive) of the direction. Every feature has a ``weight`` >= 0
(default 1); it may be limited to one storey with ``storey`` (the index of ``storeys`` in
placement.json, 0 = the lowest floor) or ``z`` (metres, the camera height it is for: poses whose
camera is within :data:`Z_TOLERANCE` of it); without either it holds on every storey.

A pose's weight is the **largest** weight of the features that hold it (a route through a room
does not count twice; a weight-0 zone carves a hole out of a weighted one), and the file's
``default_weight`` (default 0) where none does. The weights are then scaled to sum to the number
of poses N, so that a weighted sum over poses reads on the same scale as the unweighted one
(``expected-recall``'s expected poses, ``--target-recall``'s share).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from markerplace.errors import UserError
from markerplace.input_paths import check_input_file
from markerplace.jsonfile import read_json

log = logging.getLogger(__name__)

__all__ = ["DEFAULT_RADIUS", "DEFAULT_TOLERANCE_DEG", "Z_TOLERANCE", "Where", "WhereFeature", "load_where",
           "parse_where", "raw_pose_weights", "pose_weights", "disc_pose_weights"]

DEFAULT_RADIUS = 0.5
"""Radius of a ``Point`` without one, metres."""
DEFAULT_TOLERANCE_DEG = 30.0
"""How far (degrees) a pose's yaw may be from a heading or a ``yaw_deg`` and still count."""
Z_TOLERANCE = 1.0
"""A feature with ``z`` holds for poses whose camera height is within this (metres) of it."""

_TOP_KEYS = {"type", "features", "default_weight", "name", "note"}
_FEATURE_KEYS = {"type", "geometry", "properties", "id"}
_COMMON = {"weight", "storey", "z", "name", "note"}
_PROPS = {"Polygon": _COMMON,
          "LineString": _COMMON | {"width", "heading", "heading_tolerance_deg"},
          "Point": _COMMON | {"radius", "yaw_deg", "heading_tolerance_deg"}}
_HEADINGS = ("along", "forward")


@dataclass(frozen=True, eq=False)
class WhereFeature:
    """One zone, route or listed pose, model (user) frame.

    Attributes:
        kind: ``Polygon``, ``LineString`` or ``Point``.
        rings: Polygon: its rings, each (V, 2) metres (the first the outer one); LineString:
            one (V, 2) polyline; Point: one (1, 2).
        weight: >= 0.
        width: LineString: corridor width, metres (else 0).
        heading: LineString: ``along``, ``forward`` or None (any yaw).
        yaws: Point: (Y,) radians the poses must look at, or None (any yaw).
        radius: Point: metres (else 0).
        tolerance: radians a yaw may be off a heading or a listed yaw.
        storey: the storey index it holds on, or None.
        z: the camera height it is for, metres (user frame), or None.
        label: for messages: ``feature 3 ("kitchen")``.
    """

    kind: str
    rings: tuple
    weight: float = 1.0
    width: float = 0.0
    heading: str | None = None
    yaws: np.ndarray | None = None
    radius: float = 0.0
    tolerance: float = math.radians(DEFAULT_TOLERANCE_DEG)
    storey: int | None = None
    z: float | None = None
    label: str = ""


@dataclass(frozen=True, eq=False)
class Where:
    """A parsed where file.

    Attributes:
        features: the features, in file order.
        default_weight: weight of the poses no feature holds, >= 0.
        doc: the file's JSON document as read (recorded in the run folder's config.json).
        source: the option and file, for messages (``--where route.json``).
    """

    features: tuple
    default_weight: float
    doc: dict
    source: str = "--where"


def _fail(src: str, what: str) -> UserError:
    return UserError(f"{src}: {what} (format: docs/where.md)")


def _number(value, src: str, what: str, low: float | None = None, strict: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise _fail(src, f"{what} must be a finite number, not {value!r}")
    if abs(value) > 1e7:
        raise _fail(src, f"{what} = {value:g} is not a value in metres or degrees")
    if low is not None and (value <= low if strict else value < low):
        raise _fail(src, f"{what} = {value:g} must be {'above' if strict else 'at least'} {low:g}")
    return float(value)


def _position(p, src: str, what: str) -> tuple[float, float]:
    if not isinstance(p, list) or len(p) not in (2, 3):
        raise _fail(src, f"{what} must be a position [x, y] (metres), not {p!r}")
    return _number(p[0], src, f"{what} x"), _number(p[1], src, f"{what} y")


def _positions(coords, src: str, what: str, least: int) -> np.ndarray:
    if not isinstance(coords, list):
        raise _fail(src, f"{what} must be a list of positions [x, y], not {type(coords).__name__}")
    pts = np.array([_position(p, src, f"{what} position {i + 1}") for i, p in enumerate(coords)], float).reshape(-1, 2)
    distinct = len(np.unique(pts, axis=0))
    if distinct < least:
        raise _fail(src, f"{what} has {distinct} distinct position(s); it needs at least {least}")
    return pts


def _feature(f, i: int, src: str) -> WhereFeature:
    where = f"{src}: feature {i + 1}"
    if not isinstance(f, dict) or f.get("type") != "Feature":
        raise _fail(where, 'must be a JSON object with "type": "Feature"')
    unknown = sorted(set(f) - _FEATURE_KEYS)
    if unknown:
        raise _fail(where, f"unknown key(s) {', '.join(map(repr, unknown))}; allowed: {', '.join(sorted(_FEATURE_KEYS))}")
    props = {} if f.get("properties") is None else f["properties"]
    geom = f.get("geometry")
    if not isinstance(props, dict):
        raise _fail(where, f'"properties" must be a JSON object, not {type(props).__name__}')
    if not isinstance(geom, dict) or geom.get("type") not in _PROPS:
        kind = geom.get("type") if isinstance(geom, dict) else geom
        raise _fail(where, f"geometry {kind!r} is not one of {', '.join(_PROPS)} (a geometry object with "
                           '"type" and "coordinates")')
    kind, coords = geom["type"], geom.get("coordinates")
    name = props.get("name")
    if name is not None:
        where = f'{where} ("{name}")'
    unknown = sorted(set(props) - _PROPS[kind])
    if unknown:
        raise _fail(where, f"{kind} has unknown properties {', '.join(map(repr, unknown))}; allowed: "
                           f"{', '.join(sorted(_PROPS[kind]))}")
    common = {"weight": _number(props.get("weight", 1.0), where, "weight", 0.0),
              "tolerance": math.radians(_number(props.get("heading_tolerance_deg", DEFAULT_TOLERANCE_DEG), where,
                                                "heading_tolerance_deg", 0.0, strict=True)),
              "z": None if props.get("z") is None else _number(props["z"], where, "z"), "label": where}
    storey = props.get("storey")
    if storey is not None and (isinstance(storey, bool) or not isinstance(storey, int) or storey < 0):
        raise _fail(where, f"storey must be a storey index 0, 1, ... (placement.json's storeys), not {storey!r}")
    common["storey"] = storey
    if kind == "Polygon":
        if not isinstance(coords, list) or not coords:
            raise _fail(where, "Polygon coordinates must be a list of rings [[[x, y], ...]]")
        rings = tuple(_positions(r, where, f"ring {j + 1}", 3) for j, r in enumerate(coords))
        return WhereFeature(kind, rings, **common)
    if kind == "LineString":
        if "width" not in props:
            raise _fail(where, "a LineString (route) needs a width property: the corridor width in metres, e.g. 1.2")
        heading = props.get("heading")
        if heading is not None and heading not in _HEADINGS:
            raise _fail(where, f"heading {heading!r} is not one of {', '.join(_HEADINGS)} (or leave it out: any yaw)")
        return WhereFeature(kind, (_positions(coords, where, "LineString", 2),), width=_number(
            props["width"], where, "width", 0.0, strict=True), heading=heading, **common)
    yaws = props.get("yaw_deg")
    if yaws is not None:
        yaws = yaws if isinstance(yaws, list) else [yaws]
        if not yaws:
            raise _fail(where, "yaw_deg is an empty list: give yaws in degrees (counter-clockwise from +x) or leave it out")
        yaws = np.radians([_number(y, where, "yaw_deg") for y in yaws])
    return WhereFeature(kind, (np.array([_position(coords, where, "Point")]),), yaws=yaws,
                        radius=_number(props.get("radius", DEFAULT_RADIUS), where, "radius", 0.0, strict=True),
                        **common)


def parse_where(doc, source: str = "--where") -> Where:
    """A :class:`Where` from a parsed JSON document (see the module docstring).

    Raises:
        UserError: one line for anything malformed (wrong types, unknown keys, a polygon with
            fewer than 3 points, a route without width, negative weights, no features).
    """
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise _fail(source, 'the file must be a GeoJSON object with "type": "FeatureCollection"')
    unknown = sorted(set(doc) - _TOP_KEYS)
    if unknown:
        raise _fail(source, f"unknown key(s) {', '.join(map(repr, unknown))}; allowed: {', '.join(sorted(_TOP_KEYS))}")
    features = doc.get("features")
    if not isinstance(features, list) or not features:
        raise _fail(source, '"features" must be a non-empty list of zones (Polygon), routes (LineString) and poses (Point)')
    parsed = tuple(_feature(f, i, source) for i, f in enumerate(features))
    default = _number(doc.get("default_weight", 0.0), source, "default_weight", 0.0)
    if default == 0.0 and all(f.weight == 0.0 for f in parsed):
        raise _fail(source, "every weight is 0 (and default_weight too): give the places of use a weight above 0")
    return Where(parsed, default, doc, source)


def load_where(path: str | Path, option: str = "--where") -> Where:
    """Read and check a where file (:func:`parse_where`); one-line :class:`UserError` for a
    missing file or one that is not JSON (:func:`markerplace.jsonfile.read_json`)."""
    path = Path(path)
    source = f"{option} {path}"
    check_input_file(path, source, "a GeoJSON file of zones, routes and poses",
                     "; give a GeoJSON file of zones, routes and poses (docs/where.md)")
    return parse_where(read_json(path, source), source)


def _inside(xy: np.ndarray, rings) -> np.ndarray:
    """(N,) bool: points inside the polygon (even-odd rule over all rings: holes are outside)."""
    inside = np.zeros(len(xy), bool)
    x, y = xy[:, 0:1], xy[:, 1:2]
    for ring in rings:
        a, b = ring, np.roll(ring, -1, axis=0)
        crosses = (a[None, :, 1] > y) != (b[None, :, 1] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = a[None, :, 0] + (y - a[None, :, 1]) * (b[None, :, 0] - a[None, :, 0]) / (b[None, :, 1] - a[None, :, 1])
        inside ^= (np.count_nonzero(crosses & (x < xc), axis=1) % 2).astype(bool)
    return inside


def _angle_off(yaw: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """|yaw - direction| wrapped to [0, pi], radians (broadcast)."""
    return np.abs((yaw - direction + np.pi) % (2 * np.pi) - np.pi)


def _route(xy: np.ndarray, yaw: np.ndarray, f: WhereFeature) -> np.ndarray:
    """(N,) bool: within width/2 of the polyline and, with a heading, looking along the
    direction of its nearest segment."""
    line = f.rings[0]
    a, d = line[:-1], np.diff(line, axis=0)  # (S, 2)
    length2 = np.maximum(np.sum(d * d, axis=1), 1e-18)
    t = np.clip(np.einsum("nsk,sk->ns", xy[:, None, :] - a[None], d) / length2, 0.0, 1.0)
    dist = np.linalg.norm(xy[:, None, :] - (a[None] + t[..., None] * d[None]), axis=2)  # (N, S)
    near = dist.min(axis=1) <= f.width / 2.0
    if f.heading is None:
        return near
    seg = np.argmin(dist, axis=1)
    direction = np.arctan2(d[seg, 1], d[seg, 0])
    ok = _angle_off(yaw, direction) <= f.tolerance + 1e-9
    if f.heading == "along":
        ok |= _angle_off(yaw, direction + np.pi) <= f.tolerance + 1e-9
    return near & ok


def _holds(f: WhereFeature, xyz: np.ndarray, yaw: np.ndarray, storey: np.ndarray) -> np.ndarray:
    """(N,) bool: the feature holds at the poses."""
    xy = xyz[:, :2]
    if f.kind == "Polygon":
        mask = _inside(xy, f.rings)
    elif f.kind == "LineString":
        mask = _route(xy, yaw, f)
    else:
        mask = np.linalg.norm(xy - f.rings[0][0], axis=1) <= f.radius
        if f.yaws is not None:
            mask &= np.any(_angle_off(yaw[:, None], f.yaws[None]) <= f.tolerance + 1e-9, axis=1)
    if f.storey is not None:
        mask &= storey == f.storey
    if f.z is not None:
        mask &= np.abs(xyz[:, 2] - f.z) <= Z_TOLERANCE
    return mask


def raw_pose_weights(where: Where, xyz: np.ndarray, yaw: np.ndarray, storey: np.ndarray) -> np.ndarray:
    """(N,) weight of each pose before scaling: the largest weight of the features that hold it,
    ``default_weight`` where none does; one warning per feature that holds no pose.

    Args:
        where: the parsed file.
        xyz: (N, 3) camera positions, model (user) frame, metres.
        yaw: (N,) radians, counter-clockwise from +x.
        storey: (N,) storey index of each pose.
    """
    weights, empty = _weigh(where, xyz, yaw, storey)
    _warn(empty)
    return weights


def _weigh(where: Where, xyz: np.ndarray, yaw: np.ndarray, storey: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """:func:`raw_pose_weights` without the warnings, and the labels of the features that hold no pose."""
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    yaw, storey = np.asarray(yaw, float).reshape(-1), np.asarray(storey).reshape(-1)
    best, empty = np.full(len(xyz), -1.0), []
    for f in where.features:
        mask = _holds(f, xyz, yaw, storey)
        if not mask.any():
            empty.append(f.label)
        best[mask] = np.maximum(best[mask], f.weight)
    return np.where(best < 0.0, where.default_weight, best), empty


def _warn(empty: list[str]) -> None:
    for label in empty:
        log.warning("%s holds no camera pose (is it in the model's frame, metres, on a planned storey?)", label)


def pose_weights(where: Where, xyz: np.ndarray, yaw: np.ndarray, storey: np.ndarray) -> np.ndarray:
    """(N,) weights of :func:`raw_pose_weights` scaled to sum to N (so a weighted mean is
    ``sum(w * x) / N``).

    Raises:
        UserError: no pose lies in any feature, or every pose's weight is 0 (says where the
            poses are, to compare with the file's coordinates).
    """
    w, empty = _weigh(where, xyz, yaw, storey)
    if not len(w) or w.sum() <= 0.0:
        xy = np.asarray(xyz, float).reshape(-1, 3)[:, :2]
        span = (f"; the camera poses span x {xy[:, 0].min():.2f}..{xy[:, 0].max():.2f}, "
                f"y {xy[:, 1].min():.2f}..{xy[:, 1].max():.2f}") if len(xy) else ""
        raise UserError(f"{where.source}: no camera pose of the plan lies in a zone, on a route or near a pose with a "
                        f"weight above 0{span}: give coordinates in the model's frame (metres, as in placement.json), "
                        "check storey/z, or set default_weight above 0")
    _warn(empty)
    return w * (len(w) / w.sum())


def disc_pose_weights(where: Where, disc, offset: np.ndarray | None = None) -> np.ndarray:
    """(N,) :func:`pose_weights` of a discretization's poses (internal frame; ``offset`` (3,)
    the scene's :func:`~markerplace.scene.worldframe.world_offset`, added to move them into the
    user's frame the file is in)."""
    xyz = np.asarray(disc.world_from_cam, float)[:, :3, 3]
    if offset is not None:
        xyz = xyz + np.asarray(offset, float).reshape(1, 3)
    storey = np.asarray(disc.location_storey)[np.asarray(disc.location_index)]
    yaw = np.arctan2(disc.world_from_cam[:, 1, 2], disc.world_from_cam[:, 0, 2])  # optical axis, CCW from +x
    return pose_weights(where, xyz, yaw, storey)
