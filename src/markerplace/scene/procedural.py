"""Procedural interiors: build a textured :class:`Scene` from a :class:`Layout` description.

World frame: z up, metres, floor at z = 0. A layout is a set of axis-aligned room rectangles whose
edges are wall centre lines, doors between pairs of rooms, and per-room furniture and pictures in
room-local coordinates (metres from the room's (xmin, ymin) corner), so two rooms with the same
contents are identical up to a translation.

Geometry is made of boxes and quads only. Parts are grouped by material (texture + colour), so a
whole scene is a few dozen :class:`MeshPart` and repeated items share one texture array.

Furniture local frame: x = width, y = depth with the item's FRONT facing -y, z up, origin at the
footprint centre on the floor. ``yaw_deg`` turns the item counter-clockwise about z; its front
then faces (sin yaw, -cos yaw): 0 faces -y (stands against a north wall), 180 faces +y,
90 faces +x (against a west wall), -90 faces -x (against an east wall).
"""

from __future__ import annotations

import logging
import zlib
from dataclasses import dataclass, field

import numpy as np

from . import textures as tx
from .types import MeshPart, Room, Scene

log = logging.getLogger(__name__)


# ----------------------------------------------------------------------------------------------
# layout description


@dataclass(frozen=True)
class Item:
    """A piece of furniture. ``kind`` is a key of :data:`FURNITURE`; (x, y) its footprint centre in
    room-local metres; ``yaw_deg`` its rotation (0: front faces -y); ``variant`` picks colours."""

    kind: str
    x: float
    y: float
    yaw_deg: float = 0.0
    variant: int = 0


@dataclass(frozen=True)
class Picture:
    """A framed picture or poster on a room wall.

    Attributes:
        wall: ``"N"`` (y max), ``"S"`` (y min), ``"E"`` (x max) or ``"W"`` (x min).
        along: room-local coordinate of the picture centre along the wall (x for N/S, y for E/W).
        width: picture width in metres (height follows the image aspect ratio).
        image: a bundled photo name (:data:`textures.BUNDLED_PHOTOS`) or ``"art:<k>"`` for
            procedural art number k, or ``"whiteboard"``.
        z_center: height of the picture centre (default 1.5 m, eye level).
    """

    wall: str
    along: float
    width: float
    image: str
    z_center: float = 1.5


@dataclass(frozen=True)
class RoomSpec:
    """A room: footprint (xmin, ymin, xmax, ymax) on wall centre lines, floor and wall finish.

    Attributes:
        floor: ``"wood"``, ``"tiles"``, ``"carpet"`` or ``"wood_dark"``.
        wall_color: RGB 0-255 paint colour of its walls (inside faces).
        items / pictures: contents in room-local coordinates.
        template: rooms with the same template get identical seeded jitter (twins).
        lights: number of ceiling light panels.
    """

    name: str
    bounds: tuple[float, float, float, float]
    floor: str = "wood"
    wall_color: tuple[int, int, int] = (232, 228, 218)
    items: tuple[Item, ...] = ()
    pictures: tuple[Picture, ...] = ()
    template: str | None = None
    lights: int = 2


@dataclass(frozen=True)
class Door:
    """An opening (no door leaf, no glass) in the wall shared by rooms ``a`` and ``b``.

    ``at`` is the fraction along the shared wall segment of the opening centre (default 0.5);
    ``width`` defaults to 0.95 m and ``height`` to 2.1 m (a lintel closes the wall above).
    """

    a: str
    b: str
    at: float = 0.5
    width: float = 0.95
    height: float = 2.1


@dataclass(frozen=True)
class Layout:
    """A whole interior: rooms, doors, wall thickness (0.1 m) and ceiling height (2.7 m)."""

    name: str
    description: str
    rooms: tuple[RoomSpec, ...]
    doors: tuple[Door, ...] = ()
    wall_thickness: float = 0.1
    ceiling_height: float = 2.7
    twins: tuple[tuple[str, str], ...] = field(default=())

    @property
    def floor_area(self) -> float:
        """Sum of room footprints in m^2 (on wall centre lines)."""
        return float(sum((r.bounds[2] - r.bounds[0]) * (r.bounds[3] - r.bounds[1]) for r in self.rooms))


# ----------------------------------------------------------------------------------------------
# materials and mesh accumulation


@dataclass(frozen=True)
class Material:
    """Texture key (or None), RGBA base colour, and UV mapping: ``repeat`` metres per texture
    repeat (planar, world-scaled), or None to stretch the texture once over each face."""

    key: str
    texture: str | None = None
    color: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    repeat: float | None = 1.0


class MeshBuilder:
    """Accumulates quads per material and emits one :class:`MeshPart` per material."""

    def __init__(self, scene_name: str, bank: tx.TextureBank, texture_fns: dict):
        self.scene_name = scene_name
        self.bank = bank
        self.texture_fns = texture_fns
        self._data: dict[str, dict] = {}
        self._mats: dict[str, Material] = {}

    def quad(self, mat: Material, corners: np.ndarray, uv: np.ndarray, normal: np.ndarray) -> None:
        """Add a quad: (4, 3) corners counter-clockwise seen from the ``normal`` side, (4, 2) uv."""
        d = self._data.setdefault(mat.key, {"v": [], "uv": [], "n": []})
        self._mats[mat.key] = mat
        d["v"].append(np.asarray(corners, dtype=np.float64))
        d["uv"].append(np.asarray(uv, dtype=np.float64))
        d["n"].append(np.broadcast_to(np.asarray(normal, dtype=np.float64), (4, 3)))

    def parts(self) -> list[MeshPart]:
        out = []
        for key, d in self._data.items():
            mat = self._mats[key]
            v = np.concatenate(d["v"]).astype(np.float32)
            n_quads = len(d["v"])
            base = (np.arange(n_quads) * 4)[:, None]
            faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3).astype(np.int32)
            texture = None
            uv = None
            if mat.texture is not None:
                fn, args = self.texture_fns[mat.texture]
                texture = self.bank.get(mat.texture, fn, *args)
                uv = np.concatenate(d["uv"]).astype(np.float32)
            normals = np.concatenate(d["n"]).astype(np.float32)
            for arr in (v, faces, uv, normals):
                if arr is not None:
                    arr.flags.writeable = False
            out.append(
                MeshPart(
                    name=f"{self.scene_name}/{key}",
                    vertices=v,
                    faces=faces,
                    uv=uv,
                    texture=texture,
                    base_color=tuple(float(c) for c in mat.color),
                    normals=normals,
                )
            )
        return out


_AXES = {
    "+x": (np.array([1.0, 0, 0]), np.array([0, 0, 1.0])),
    "-x": (np.array([-1.0, 0, 0]), np.array([0, 0, 1.0])),
    "+y": (np.array([0, 1.0, 0]), np.array([0, 0, 1.0])),
    "-y": (np.array([0, -1.0, 0]), np.array([0, 0, 1.0])),
    "+z": (np.array([0, 0, 1.0]), np.array([0, 1.0, 0])),
    "-z": (np.array([0, 0, -1.0]), np.array([0, -1.0, 0])),
}


def _face(lo: np.ndarray, hi: np.ndarray, face: str):
    """Corners (4, 3), uv-plane coordinates (4, 2) in metres, normal, extent (w, h) of a box face.

    Corners go bottom-left, bottom-right, top-right, top-left as seen from outside: counter-clockwise.
    Right = up x normal, so images on vertical faces read left to right and upright.
    """
    n, up = _AXES[face]
    right = np.cross(up, n)
    c = (lo + hi) / 2
    half = (hi - lo) / 2
    c = c + n * (np.abs(n) @ half)  # centre of the face
    hr = np.abs(right) @ half
    hu = np.abs(up) @ half
    corners = np.array([c - right * hr - up * hu, c + right * hr - up * hu, c + right * hr + up * hu, c - right * hr + up * hu])
    plane = np.stack([corners @ right, corners @ up], axis=1)
    return corners, plane, n, (2 * hr, 2 * hu)


def add_box(
    mb: MeshBuilder,
    lo,
    hi,
    mats: Material | dict[str, Material],
    transform: tuple[float, np.ndarray] | None = None,
    skip: tuple[str, ...] = ("-z",),
) -> None:
    """Add an axis-aligned box [lo, hi] (local metres) with one material or one per face.

    ``mats`` may map face names ("+x", "-x", "+y", "-y", "+z", "-z", or "*" for the rest) to
    materials. ``transform`` = (yaw radians, (3,) translation) places the local box in the world.
    Faces in ``skip`` are omitted (default: the bottom, which stands on something).
    """
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    if transform is not None:
        yaw, t = transform
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    for face in _AXES:
        if face in skip:
            continue
        mat = mats if isinstance(mats, Material) else mats.get(face, mats.get("*"))
        if mat is None:
            continue
        corners, plane, n, (w, h) = _face(lo, hi, face)
        if w <= 0 or h <= 0:
            continue
        if mat.repeat is None:
            uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
        else:
            uv = plane / mat.repeat
        if transform is not None:
            corners = corners @ R.T + t
            n = R @ n
        mb.quad(mat, corners, uv, n)


# ----------------------------------------------------------------------------------------------
# furniture: each builder adds boxes in the item frame (front faces -y), origin on the floor


def _desk(mb, pal, T, rng, v):
    w, d, h, top = 1.4, 0.7, 0.74, 0.03
    add_box(mb, (-w / 2, -d / 2, h - top), (w / 2, d / 2, h), {"+z": pal["desk_top"], "*": pal["desk_edge"]}, T, skip=())
    for sx in (-1, 1):
        add_box(mb, (sx * w / 2 - 0.025 - sx * 0.025, -d / 2 + 0.03, 0), (sx * w / 2 + 0.025 - sx * 0.025, d / 2 - 0.03, h - top), pal["metal"], T)
    add_box(mb, (-w / 2 + 0.05, d / 2 - 0.05, 0.35), (w / 2 - 0.05, d / 2 - 0.03, h - top), pal["desk_edge"], T)  # modesty panel


def _monitor(mb, pal, T, rng, v):
    # on a desk top (z 0.74), near the back
    z0 = 0.74
    add_box(mb, (-0.1, 0.05, z0), (0.1, 0.2, z0 + 0.02), pal["plastic_dark"], T)
    add_box(mb, (-0.025, 0.12, z0), (0.025, 0.15, z0 + 0.15), pal["plastic_dark"], T)
    add_box(mb, (-0.3, 0.06, z0 + 0.12), (0.3, 0.1, z0 + 0.48), {"-y": pal["screen"], "*": pal["plastic_dark"]}, T, skip=())
    add_box(mb, (-0.22, -0.25, z0), (0.22, -0.1, z0 + 0.02), {"+z": pal["keyboard"], "*": pal["plastic_dark"]}, T)


def _chair(mb, pal, T, rng, v):
    add_box(mb, (-0.23, -0.23, 0.42), (0.23, 0.23, 0.5), pal["fabric"], T, skip=())
    add_box(mb, (-0.22, 0.2, 0.55), (0.22, 0.26, 1.0), pal["fabric"], T, skip=())
    add_box(mb, (-0.03, -0.03, 0.05), (0.03, 0.03, 0.42), pal["metal"], T)
    add_box(mb, (-0.28, -0.04, 0.0), (0.28, 0.04, 0.05), pal["metal"], T)
    add_box(mb, (-0.04, -0.28, 0.0), (0.04, 0.28, 0.05), pal["metal"], T)


def _bookshelf(mb, pal, T, rng, v):
    w, d, h = 0.9, 0.35, 2.0
    body = pal["wood"]
    add_box(mb, (-w / 2, -d / 2, 0), (w / 2, d / 2, h), {"-y": pal["books"], "*": body}, T)
    # side panels proud of the book front give depth edges
    for sx in (-1, 1):
        add_box(mb, (sx * w / 2 - 0.02, -d / 2 - 0.02, 0), (sx * w / 2 + 0.02, -d / 2 + 0.001, h), body, T)


def _cabinet(mb, pal, T, rng, v):
    w, d, h = 0.8, 0.45, 1.0
    add_box(mb, (-w / 2, -d / 2, 0), (w / 2, d / 2, h), {"-y": pal["drawers"], "+z": pal["desk_top"], "*": pal["wood"]}, T)


def _wardrobe(mb, pal, T, rng, v):
    w, d, h = 1.2, 0.6, 2.0
    add_box(mb, (-w / 2, -d / 2, 0), (w / 2, d / 2, h), {"-y": pal["wardrobe_front"], "*": pal["wood"]}, T)


def _table(mb, pal, T, rng, v, w=1.6, d=0.9):
    h = 0.75
    add_box(mb, (-w / 2, -d / 2, h - 0.04), (w / 2, d / 2, h), {"+z": pal["table_top"], "*": pal["desk_edge"]}, T, skip=())
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (w / 2 - 0.06), sy * (d / 2 - 0.06)
            add_box(mb, (x - 0.025, y - 0.025, 0), (x + 0.025, y + 0.025, h - 0.04), pal["desk_edge"], T)


def _big_table(mb, pal, T, rng, v):
    _table(mb, pal, T, rng, v, w=2.4, d=1.1)


def _coffee_table(mb, pal, T, rng, v):
    add_box(mb, (-0.5, -0.3, 0.0), (0.5, 0.3, 0.42), {"+z": pal["table_top"], "*": pal["wood"]}, T)


def _sofa(mb, pal, T, rng, v):
    w, d = 2.0, 0.9
    f = pal["sofa"]
    add_box(mb, (-w / 2, -d / 2, 0), (w / 2, d / 2, 0.42), f, T)
    add_box(mb, (-w / 2, d / 2 - 0.2, 0.42), (w / 2, d / 2, 0.85), f, T)
    for sx in (-1, 1):
        add_box(mb, (sx * w / 2 - 0.1 - sx * 0.1, -d / 2, 0.42), (sx * w / 2 + 0.1 - sx * 0.1, d / 2 - 0.2, 0.62), f, T)
    for cx in (-0.45, 0.45):
        add_box(mb, (cx - 0.42, -d / 2 + 0.05, 0.42), (cx + 0.42, d / 2 - 0.22, 0.52), pal["cushion"], T)


def _bed(mb, pal, T, rng, v):
    w, d = 1.6, 2.05  # headboard at +y (against the wall)
    add_box(mb, (-w / 2, -d / 2, 0), (w / 2, d / 2, 0.3), pal["wood"], T)
    add_box(mb, (-w / 2 + 0.03, -d / 2 + 0.03, 0.3), (w / 2 - 0.03, d / 2 - 0.05, 0.52), pal["duvet"], T)
    add_box(mb, (-w / 2, d / 2 - 0.06, 0), (w / 2, d / 2, 1.05), pal["wood"], T)
    for cx in (-0.38, 0.38):
        add_box(mb, (cx - 0.3, d / 2 - 0.5, 0.52), (cx + 0.3, d / 2 - 0.12, 0.64), pal["pillow"], T)


def _nightstand(mb, pal, T, rng, v):
    add_box(mb, (-0.25, -0.2, 0), (0.25, 0.2, 0.55), {"-y": pal["drawers"], "*": pal["wood"]}, T)


def _counter(mb, pal, T, rng, v):
    w, d = 2.4, 0.62
    add_box(mb, (-w / 2, -d / 2 + 0.05, 0), (w / 2, d / 2, 0.86), {"-y": pal["kitchen_front"], "*": pal["kitchen_body"]}, T)
    add_box(mb, (-w / 2, -d / 2, 0.86), (w / 2, d / 2, 0.9), pal["stone"], T, skip=())
    add_box(mb, (-0.3, -0.15, 0.9), (0.3, 0.2, 0.91), pal["metal"], T)  # sink rim


def _fridge(mb, pal, T, rng, v):
    add_box(mb, (-0.3, -0.32, 0), (0.3, 0.32, 1.85), {"-y": pal["fridge_front"], "*": pal["white"]}, T)


def _tv_stand(mb, pal, T, rng, v):
    add_box(mb, (-0.8, -0.2, 0), (0.8, 0.2, 0.5), {"-y": pal["drawers"], "*": pal["wood"]}, T)
    add_box(mb, (-0.6, -0.03, 0.55), (0.6, 0.03, 1.25), {"-y": pal["tv"], "*": pal["plastic_dark"]}, T, skip=())
    add_box(mb, (-0.15, -0.1, 0.5), (0.15, 0.1, 0.55), pal["plastic_dark"], T)


def _plant(mb, pal, T, rng, v):
    add_box(mb, (-0.18, -0.18, 0), (0.18, 0.18, 0.4), pal["pot"], T)
    add_box(mb, (-0.3, -0.3, 0.4), (0.3, 0.3, 1.2), pal["leaves"], T, skip=())


def _rug(mb, pal, T, rng, v):
    add_box(mb, (-1.0, -0.7, 0.0), (1.0, 0.7, 0.01), {"+z": pal["rug"], "*": pal["rug_edge"]}, T)


def _bathtub(mb, pal, T, rng, v):
    add_box(mb, (-0.85, -0.38, 0), (0.85, 0.38, 0.55), pal["white"], T)


def _sink(mb, pal, T, rng, v):
    add_box(mb, (-0.4, -0.25, 0), (0.4, 0.25, 0.85), {"-y": pal["drawers"], "+z": pal["white"], "*": pal["wood"]}, T)


def _printer(mb, pal, T, rng, v):
    add_box(mb, (-0.4, -0.3, 0), (0.4, 0.3, 0.75), pal["wood"], T)
    add_box(mb, (-0.25, -0.22, 0.75), (0.25, 0.22, 1.05), {"+z": pal["plastic_dark"], "*": pal["white"]}, T)


# kind -> (builder, footprint width, depth, height)
FURNITURE = {
    "desk": (_desk, 1.4, 0.7, 0.74),
    "monitor": (_monitor, 0.6, 0.5, 1.22),
    "chair": (_chair, 0.56, 0.56, 1.0),
    "bookshelf": (_bookshelf, 0.94, 0.39, 2.0),
    "cabinet": (_cabinet, 0.8, 0.45, 1.0),
    "wardrobe": (_wardrobe, 1.2, 0.6, 2.0),
    "table": (_table, 1.6, 0.9, 0.75),
    "big_table": (_big_table, 2.4, 1.1, 0.75),
    "coffee_table": (_coffee_table, 1.0, 0.6, 0.42),
    "sofa": (_sofa, 2.0, 0.9, 0.85),
    "bed": (_bed, 1.6, 2.05, 1.05),
    "nightstand": (_nightstand, 0.5, 0.4, 0.55),
    "counter": (_counter, 2.4, 0.62, 0.91),
    "fridge": (_fridge, 0.6, 0.64, 1.85),
    "tv_stand": (_tv_stand, 1.6, 0.4, 1.25),
    "plant": (_plant, 0.6, 0.6, 1.2),
    "rug": (_rug, 2.0, 1.4, 0.01),
    "bathtub": (_bathtub, 1.7, 0.76, 0.55),
    "sink": (_sink, 0.8, 0.5, 0.85),
    "printer": (_printer, 0.8, 0.6, 1.05),
}
TALL_AGAINST_WALL = {"bookshelf", "wardrobe", "fridge"}
MAX_FREE_HEIGHT = 1.4


# ----------------------------------------------------------------------------------------------
# textures and palette


def _texture_fns() -> dict:
    """Texture key -> (generator, args). Generators are called at most once per build."""
    return {
        "wall_paint": (tx.painted_wall, ((236, 234, 228),)),
        "wood_floor": (tx.wood_planks, (512, 8, (150, 105, 65))),
        "wood_floor_dark": (tx.wood_planks, (512, 10, (105, 70, 45))),
        "tiles": (tx.floor_tiles, (512, 4)),
        "bath_tiles": (tx.floor_tiles, (256, 8, (225, 232, 235), (150, 160, 165))),
        "carpet": (tx.carpet, (256,)),
        "ceiling": (tx.ceiling_tiles, (256, 4)),
        "wood": (tx.wood_grain, (256, (165, 115, 75))),
        "wood_light": (tx.wood_grain, (256, (205, 175, 135))),
        "fabric_blue": (tx.fabric, (128, (70, 90, 140))),
        "fabric_grey": (tx.fabric, (128, (120, 118, 112))),
        "fabric_red": (tx.fabric, (128, (150, 55, 50))),
        "books": (tx.book_spines, (256, 512, 5)),
        "screen": (tx.screen, (256, 160)),
        "tv": (tx.photo, ("rocket", 256)),
        "rug": (tx.rug, (256,)),
        "stone": (tx.countertop, (256,)),
        "leaves": (tx.foliage, (128,)),
        "keyboard": (tx.floor_tiles, (64, 8, (50, 50, 55), (15, 15, 15))),
        "drawers": (tx.floor_tiles, (128, 2, (170, 125, 85), (60, 45, 30))),
        "wardrobe_front": (tx.floor_tiles, (128, 2, (215, 210, 200), (90, 85, 80))),
        "kitchen_front": (tx.floor_tiles, (256, 4, (200, 205, 210), (70, 70, 75))),
        "fridge_front": (tx.floor_tiles, (64, 1, (225, 228, 230), (140, 140, 145))),
    }


def _palette() -> dict[str, Material]:
    M = Material
    return {
        "desk_top": M("desk_top", "wood_light", repeat=1.4),
        "desk_edge": M("desk_edge", None, (0.35, 0.3, 0.28, 1.0)),
        "metal": M("metal", None, (0.55, 0.56, 0.58, 1.0)),
        "plastic_dark": M("plastic_dark", None, (0.12, 0.12, 0.13, 1.0)),
        "white": M("white", None, (0.92, 0.92, 0.9, 1.0)),
        "screen": M("screen", "screen", repeat=None),
        "tv": M("tv", "tv", repeat=None),
        "keyboard": M("keyboard", "keyboard", repeat=None),
        "fabric": M("fabric", "fabric_blue", repeat=0.5),
        "sofa": M("sofa", "fabric_grey", repeat=0.6),
        "cushion": M("cushion", "fabric_red", repeat=0.6),
        "duvet": M("duvet", "fabric_blue", repeat=0.8),
        "pillow": M("pillow", None, (0.95, 0.95, 0.93, 1.0)),
        "wood": M("wood", "wood", repeat=1.0),
        "table_top": M("table_top", "wood", repeat=1.2),
        "books": M("books", "books", repeat=None),
        "drawers": M("drawers", "drawers", repeat=None),
        "wardrobe_front": M("wardrobe_front", "wardrobe_front", repeat=None),
        "kitchen_front": M("kitchen_front", "kitchen_front", repeat=2.4),
        "kitchen_body": M("kitchen_body", None, (0.85, 0.86, 0.88, 1.0)),
        "stone": M("stone", "stone", repeat=1.0),
        "fridge_front": M("fridge_front", "fridge_front", repeat=None),
        "pot": M("pot", None, (0.55, 0.3, 0.2, 1.0)),
        "leaves": M("leaves", "leaves", repeat=0.5),
        "rug": M("rug", "rug", repeat=None),
        "rug_edge": M("rug_edge", None, (0.5, 0.15, 0.15, 1.0)),
        "frame": M("frame", None, (0.1, 0.09, 0.08, 1.0)),
        "trim": M("trim", None, (0.93, 0.92, 0.88, 1.0)),
        "exterior": M("exterior", None, (0.6, 0.6, 0.6, 1.0)),
        "light": M("light", None, (1.0, 1.0, 0.97, 1.0)),
        "ceiling": M("ceiling", "ceiling", repeat=2.4),
    }


_FLOORS = {
    "wood": ("wood_floor", 2.0),
    "wood_dark": ("wood_floor_dark", 2.0),
    "tiles": ("tiles", 2.0),
    "bath_tiles": ("bath_tiles", 1.2),
    "carpet": ("carpet", 1.0),
}


# ----------------------------------------------------------------------------------------------
# walls


def _r(v: float) -> float:
    return round(float(v), 4)


def _wall_lines(rooms: tuple[RoomSpec, ...]):
    """Merged wall intervals per line: {("h", y): [(x0, x1), ...], ("v", x): [(y0, y1), ...]}."""
    lines: dict[tuple[str, float], list[tuple[float, float]]] = {}
    for r in rooms:
        x0, y0, x1, y1 = (_r(v) for v in r.bounds)
        lines.setdefault(("h", y0), []).append((x0, x1))
        lines.setdefault(("h", y1), []).append((x0, x1))
        lines.setdefault(("v", x0), []).append((y0, y1))
        lines.setdefault(("v", x1), []).append((y0, y1))
    merged = {}
    for key, ivs in lines.items():
        ivs = sorted(ivs)
        out = [list(ivs[0])]
        for a, b in ivs[1:]:
            if a <= out[-1][1] + 1e-9:
                out[-1][1] = max(out[-1][1], b)
            else:
                out.append([a, b])
        merged[key] = [tuple(iv) for iv in out]
    return merged


def _door_gaps(layout: Layout) -> dict[tuple[str, float], list[tuple[float, float, float]]]:
    """Door openings per wall line: (start, end, height) along the line."""
    rooms = {r.name: r for r in layout.rooms}
    gaps: dict[tuple[str, float], list[tuple[float, float, float]]] = {}
    for d in layout.doors:
        a, b = rooms[d.a].bounds, rooms[d.b].bounds
        if abs(a[2] - b[0]) < 1e-6 or abs(b[2] - a[0]) < 1e-6:
            x = a[2] if abs(a[2] - b[0]) < 1e-6 else a[0]
            lo, hi = max(a[1], b[1]), min(a[3], b[3])
            key = ("v", _r(x))
        elif abs(a[3] - b[1]) < 1e-6 or abs(b[3] - a[1]) < 1e-6:
            y = a[3] if abs(a[3] - b[1]) < 1e-6 else a[1]
            lo, hi = max(a[0], b[0]), min(a[2], b[2])
            key = ("h", _r(y))
        else:
            raise ValueError(f"door {d.a}-{d.b}: the rooms do not share a wall")
        margin = d.width / 2 + layout.wall_thickness
        if hi - lo < 2 * margin:
            raise ValueError(f"door {d.a}-{d.b}: shared wall too short for a {d.width} m opening")
        c = np.clip(lo + d.at * (hi - lo), lo + margin, hi - margin)
        gaps.setdefault(key, []).append((c - d.width / 2, c + d.width / 2, d.height))
    return gaps


def _room_at(rooms: tuple[RoomSpec, ...], x: float, y: float) -> RoomSpec | None:
    for r in rooms:
        x0, y0, x1, y1 = r.bounds
        if x0 < x < x1 and y0 < y < y1:
            return r
    return None


def _build_walls(mb: MeshBuilder, layout: Layout, pal: dict, wall_mats: dict[str, Material]) -> None:
    """Walls as thin slabs between junction pillars, with door openings and lintels."""
    t = layout.wall_thickness
    H = layout.ceiling_height
    ht = t / 2
    nodes = {(_r(x), _r(y)) for r in layout.rooms for x in (r.bounds[0], r.bounds[2]) for y in (r.bounds[1], r.bounds[3])}
    gaps = _door_gaps(layout)

    def side_mat(px: float, py: float) -> Material:
        room = _room_at(layout.rooms, px, py)
        return wall_mats[room.name] if room is not None else pal["exterior"]

    def slab(orient: str, c: float, a: float, b: float, z0: float, z1: float, caps: tuple[bool, bool]):
        # slab along the line between a and b (a < b), across [c - ht, c + ht], height [z0, z1]
        if orient == "h":
            lo, hi = np.array([a, c - ht, z0]), np.array([b, c + ht, z1])
            sides = {"+y": side_mat((a + b) / 2, c + 0.2), "-y": side_mat((a + b) / 2, c - 0.2)}
            ends = ("-x", "+x")
        else:
            lo, hi = np.array([c - ht, a, z0]), np.array([c + ht, b, z1])
            sides = {"+x": side_mat(c + 0.2, (a + b) / 2), "-x": side_mat(c - 0.2, (a + b) / 2)}
            ends = ("-y", "+y")
        mats = dict(sides)
        for end, cap in zip(ends, caps):
            if cap:
                mats[end] = pal["trim"]
        skip = ("+z", "-z") if z0 == 0.0 else ("+z",)
        if z0 > 0:
            mats["-z"] = pal["trim"]
        add_box(mb, lo, hi, mats, None, skip=skip)

    for (orient, c), intervals in _wall_lines(layout.rooms).items():
        on_line = sorted({(n[0] if orient == "h" else n[1]) for n in nodes if (n[1] if orient == "h" else n[0]) == c})
        line_gaps = sorted(gaps.get((orient, c), []))
        for a, b in intervals:
            cuts = [p for p in on_line if a - 1e-9 <= p <= b + 1e-9]
            for p, q in zip(cuts[:-1], cuts[1:]):
                # piece between two junctions, shortened to leave room for the pillars
                start, start_cap = p + ht, False
                for g0, g1, gh in line_gaps:
                    if g0 >= p and g1 <= q:
                        if g0 < start + 1e-6:
                            raise ValueError(f"door opening at {orient}={c} overlaps a wall junction")
                        slab(orient, c, start, g0, 0.0, H, (start_cap, True))
                        slab(orient, c, g0, g1, gh, H, (False, False))
                        start, start_cap = g1, True
                if q - ht > start + 1e-6:
                    slab(orient, c, start, q - ht, 0.0, H, (start_cap, False))
    for x, y in sorted(nodes):
        lo, hi = np.array([x - ht, y - ht, 0.0]), np.array([x + ht, y + ht, H])
        mats = {f: side_mat(x + 0.2 * n[0], y + 0.2 * n[1]) for f, (n, _) in _AXES.items() if f[1] != "z"}
        # a pillar face towards a wall slab is hidden; its room test may hit either side: fine
        add_box(mb, lo, hi, mats, None, skip=("+z", "-z"))


# ----------------------------------------------------------------------------------------------
# rooms: floors, ceilings, lights, furniture, pictures


def _build_room_shell(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict) -> None:
    x0, y0, x1, y1 = room.bounds
    H = layout.ceiling_height
    tex, rep = _FLOORS[room.floor]
    floor = Material(f"floor_{room.floor}", tex, repeat=rep)
    # floor quad (up) and ceiling quad (down), UVs in room-local metres so twin rooms match
    w, d = x1 - x0, y1 - y0
    c_floor = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]], dtype=float)
    uv = np.array([[0, 0], [w, 0], [w, d], [0, d]], dtype=float)
    mb.quad(floor, c_floor, uv / rep, (0, 0, 1))
    c_ceil = np.array([[x0, y1, H], [x1, y1, H], [x1, y0, H], [x0, y0, H]], dtype=float)
    uv_c = np.array([[0, d], [w, d], [w, 0], [0, 0]], dtype=float)
    mb.quad(pal["ceiling"], c_ceil, uv_c / pal["ceiling"].repeat, (0, 0, -1))
    # ceiling light panels on a regular grid
    n = room.lights
    if n > 0:
        cols = max(1, int(round(np.sqrt(n * w / d))))
        rows = max(1, int(np.ceil(n / cols)))
        for i in range(cols):
            for j in range(rows):
                cx = x0 + (i + 0.5) * w / cols
                cy = y0 + (j + 0.5) * d / rows
                add_box(mb, (cx - 0.3, cy - 0.6, H - 0.02), (cx + 0.3, cy + 0.6, H - 0.001), pal["light"], None, skip=("+z",))


def _template_rng(seed: int, room: RoomSpec) -> np.random.Generator:
    key = room.template or room.name
    return np.random.default_rng([seed & 0xFFFFFFFF, zlib.crc32(key.encode())])


def _build_furniture(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict, seed: int) -> None:
    rng = _template_rng(seed, room)
    x0, y0 = room.bounds[0], room.bounds[1]
    for item in room.items:
        if item.kind not in FURNITURE:
            raise ValueError(f"unknown furniture kind {item.kind!r}")
        fn = FURNITURE[item.kind][0]
        yaw = np.radians(item.yaw_deg)
        jx = jy = 0.0
        if item.kind == "chair":  # chairs are never pushed in exactly the same way
            yaw += rng.uniform(-0.35, 0.35)
            jx, jy = rng.uniform(-0.06, 0.06, 2)
        T = (yaw, np.array([x0 + item.x + jx, y0 + item.y + jy, 0.0]))
        fn(mb, pal, T, rng, item.variant)


def _build_pictures(mb: MeshBuilder, layout: Layout, room: RoomSpec, pal: dict, bank: tx.TextureBank) -> None:
    x0, y0, x1, y1 = room.bounds
    ht = layout.wall_thickness / 2
    for pic in room.pictures:
        key = f"pic:{pic.image}"
        if pic.image == "whiteboard":
            fn, args = tx.solid, ((246, 246, 244),)
        elif pic.image.startswith("art:"):
            fn, args = tx.abstract_art, (256, 320)
        else:
            fn, args = tx.framed_photo, (pic.image, 384)
        mb.texture_fns.setdefault(key, (fn, args))
        img = bank.get(key, fn, *args)
        aspect = img.shape[1] / img.shape[0]
        w = pic.width
        h = w / aspect if pic.image != "whiteboard" else min(1.1, w * 0.5)
        mat = Material(key, key, repeat=None)
        # picture in a local frame facing -y, then turned onto the wall
        gap, depth, border = 0.015, 0.025, 0.025
        wall_pos = {
            "N": (0.0, np.array([x0 + pic.along, y1 - ht, 0.0])),
            "S": (np.pi, np.array([x0 + pic.along, y0 + ht, 0.0])),
            "E": (-np.pi / 2, np.array([x1 - ht, y0 + pic.along, 0.0])),
            "W": (np.pi / 2, np.array([x0 + ht, y0 + pic.along, 0.0])),
        }
        yaw, t = wall_pos[pic.wall]
        z = pic.z_center
        frame = pal["trim"] if pic.image == "whiteboard" else pal["frame"]
        add_box(mb, (-w / 2 - border, -gap - depth, z - h / 2 - border), (w / 2 + border, -gap, z + h / 2 + border), frame, (yaw, t), skip=("+y",))
        add_box(mb, (-w / 2, -gap - depth - 0.002, z - h / 2), (w / 2, -gap - depth, z + h / 2), {"-y": mat}, (yaw, t), skip=())


# ----------------------------------------------------------------------------------------------
# validation and assembly


def validate_layout(layout: Layout) -> None:
    """Raise ValueError when furniture leaves its room, blocks a door, or is too tall off the walls."""
    rooms = {r.name: r for r in layout.rooms}
    for d in layout.doors:
        if d.a not in rooms or d.b not in rooms:
            raise ValueError(f"door {d.a}-{d.b}: unknown room")
    gaps = _door_gaps(layout)
    ht = layout.wall_thickness / 2
    for room in layout.rooms:
        x0, y0, x1, y1 = room.bounds
        for pic in room.pictures:
            orient, line, base = {"N": ("h", y1, x0), "S": ("h", y0, x0), "E": ("v", x1, y0), "W": ("v", x0, y0)}[pic.wall]
            lo, hi = base + pic.along - pic.width / 2 - 0.05, base + pic.along + pic.width / 2 + 0.05
            span = (x0, x1) if orient == "h" else (y0, y1)
            if lo < span[0] + layout.wall_thickness or hi > span[1] - layout.wall_thickness:
                raise ValueError(f"{layout.name}/{room.name}: picture {pic.image} on wall {pic.wall} leaves the wall")
            for g0, g1, _ in gaps.get((orient, _r(line)), []):
                if hi > g0 - 0.1 and lo < g1 + 0.1:
                    raise ValueError(f"{layout.name}/{room.name}: picture {pic.image} on wall {pic.wall} overlaps a door")
        for item in room.items:
            _, w, d, h = FURNITURE[item.kind]
            yaw = np.radians(item.yaw_deg)
            c, s = abs(np.cos(yaw)), abs(np.sin(yaw))
            hw, hd = (w * c + d * s) / 2, (w * s + d * c) / 2
            cx, cy = x0 + item.x, y0 + item.y
            if item.kind != "monitor" and (cx - hw < x0 + ht - 1e-6 or cx + hw > x1 - ht + 1e-6 or cy - hd < y0 + ht - 1e-6 or cy + hd > y1 - ht + 1e-6):
                raise ValueError(f"{layout.name}/{room.name}: {item.kind} at ({item.x}, {item.y}) leaves the room")
            if h > MAX_FREE_HEIGHT and item.kind not in TALL_AGAINST_WALL and item.kind not in ("monitor", "tv_stand"):
                raise ValueError(f"{layout.name}/{room.name}: {item.kind} is taller than {MAX_FREE_HEIGHT} m")
            if item.kind in TALL_AGAINST_WALL:
                near = min(cx - hw - x0, x1 - cx - hw, cy - hd - y0, y1 - cy - hd)
                if near > ht + 0.05:
                    raise ValueError(f"{layout.name}/{room.name}: tall {item.kind} must stand against a wall")
            for (orient, line), glist in gaps.items():
                for g0, g1, _ in glist:
                    # keep 0.6 m clear on both sides of each opening
                    if orient == "v":
                        hit = abs(cx - line) < hw + 0.6 and cy + hd > g0 and cy - hd < g1
                    else:
                        hit = abs(cy - line) < hd + 0.6 and cx + hw > g0 and cx - hw < g1
                    if hit and item.kind != "rug":
                        raise ValueError(f"{layout.name}/{room.name}: {item.kind} at ({item.x}, {item.y}) blocks a door")


def build_scene(layout: Layout, seed: int = 0) -> Scene:
    """Build the textured :class:`Scene` of ``layout`` (deterministic in ``seed``).

    Returns a scene with read-only arrays, ``rooms`` set from the layout, ``floor_z = 0.0`` and
    ``source = "builtin:<name>"``; ``meta`` holds ``twins`` (pairs of identical rooms) and the
    ceiling height.
    """
    validate_layout(layout)
    bank = tx.TextureBank(seed)
    mb = MeshBuilder(layout.name, bank, _texture_fns())
    pal = _palette()
    wall_mats: dict[str, Material] = {}
    for room in layout.rooms:
        key = "wall_" + "_".join(str(c) for c in room.wall_color)
        tex_key = f"paint_{key}"
        mb.texture_fns.setdefault(tex_key, (tx.painted_wall, (room.wall_color,)))
        wall_mats[room.name] = Material(key, tex_key, repeat=2.0)
    _build_walls(mb, layout, pal, wall_mats)
    for room in layout.rooms:
        _build_room_shell(mb, layout, room, pal)
        _build_furniture(mb, layout, room, pal, seed)
        _build_pictures(mb, layout, room, pal, bank)
    parts = mb.parts()
    rooms = tuple(Room(r.name, tuple(float(v) for v in r.bounds)) for r in layout.rooms)
    meta = {"twins": [list(p) for p in layout.twins], "ceiling_height": layout.ceiling_height, "seed": int(seed)}
    log.debug("built %s: %d parts, %d faces, %d textures", layout.name, len(parts), sum(len(p.faces) for p in parts), len(bank))
    return Scene(name=layout.name, parts=tuple(parts), rooms=rooms, floor_z=0.0, source=f"builtin:{layout.name}", meta=meta)
