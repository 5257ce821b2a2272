"""Furniture of the procedural interiors, their textures and the material palette.

Furniture local frame: x = width, y = depth with the item's FRONT facing -y, z up, origin at the
footprint centre on the floor (metres). ``yaw_deg`` of a layout item turns it counter-clockwise
about z; its front then faces (sin yaw, -cos yaw): 0 faces -y (stands against a north wall), 180
faces +y, 90 faces +x (against a west wall), -90 faces -x (against an east wall).

Each builder ``fn(mb, pal, T, rng, variant)`` adds boxes to a :class:`~.meshkit.MeshBuilder`
with the palette ``pal`` (:func:`palette`) placed by ``T = (yaw radians, (3,) translation)``; the
caller labels them with the item's kind (a builder may label pieces more precisely: a
``tv_stand`` is a ``sideboard`` with a ``tv`` on it).
:data:`FURNITURE` maps a kind to (builder, footprint width, depth, height).
"""

from __future__ import annotations

from markerplace.scene.builtin import textures as tx
from markerplace.scene.builtin.meshkit import Material, add_box

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
    with mb.labelled("sideboard"):
        add_box(mb, (-0.8, -0.2, 0), (0.8, 0.2, 0.5), {"-y": pal["drawers"], "*": pal["wood"]}, T)
    with mb.labelled("tv"):
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


def _island(mb, pal, T, rng, v):
    # kitchen island: cupboard fronts on both long sides, stone top at 0.92 m
    w, d = 2.0, 0.9
    add_box(mb, (-w / 2 + 0.05, -d / 2 + 0.05, 0), (w / 2 - 0.05, d / 2 - 0.05, 0.88), {"-y": pal["kitchen_front"], "+y": pal["kitchen_front"], "*": pal["kitchen_body"]}, T)
    add_box(mb, (-w / 2, -d / 2, 0.88), (w / 2, d / 2, 0.92), pal["stone"], T, skip=())


def _armchair(mb, pal, T, rng, v):
    f = pal["sofa"]
    add_box(mb, (-0.4, -0.4, 0), (0.4, 0.4, 0.42), f, T)
    add_box(mb, (-0.4, 0.22, 0.42), (0.4, 0.4, 0.85), f, T)
    for sx in (-1, 1):
        add_box(mb, (sx * 0.4 - 0.08 - sx * 0.08, -0.4, 0.42), (sx * 0.4 + 0.08 - sx * 0.08, 0.22, 0.6), f, T)
    add_box(mb, (-0.24, -0.36, 0.42), (0.24, 0.2, 0.5), pal["cushion"], T)


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
    "island": (_island, 2.0, 0.9, 0.92),
    "armchair": (_armchair, 0.8, 0.8, 0.85),
}
TALL_AGAINST_WALL = {"bookshelf", "wardrobe", "fridge"}
MAX_FREE_HEIGHT = 1.4


# ----------------------------------------------------------------------------------------------
# textures and palette


def texture_fns() -> dict:
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
        "door_leaf": (tx.floor_tiles, (128, 2, (190, 150, 110), (120, 85, 55))),  # a four-panel door
    }


def palette() -> dict[str, Material]:
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
        # glass: opacity 76/255 (about 0.3, exact in 8 bits so a glTF round trip keeps it)
        "glass": M("glass", None, (0.78, 0.88, 0.92, 76 / 255), transparent=True),
        "glass_frame": M("glass_frame", None, (0.22, 0.23, 0.25, 1.0)),
        "concrete": M("concrete", None, (0.72, 0.71, 0.68, 1.0)),
        "door": M("door", "door_leaf", repeat=None),
    }


FLOORS = {
    "wood": ("wood_floor", 2.0),
    "wood_dark": ("wood_floor_dark", 2.0),
    "tiles": ("tiles", 2.0),
    "bath_tiles": ("bath_tiles", 1.2),
    "carpet": ("carpet", 1.0),
}
