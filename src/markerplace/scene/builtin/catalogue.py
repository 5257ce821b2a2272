"""Built-in scenes: layouts of the procedural interiors and a per-process cache of built scenes.

Sizes follow the paper's scenes: office ~110 m^2, studio ~150 m^2, apartment ~300 m^2,
room ~21 m^2, plus ``tiny`` (13 m^2) for fast tests, the two-storey ``house`` (158 m^2,
:mod:`.house`) and the two-storey office building ``campus`` for scale tests (2064 m^2,
:mod:`.campus`). Coordinates are metres, world z up; room
bounds are wall centre lines; furniture and pictures are in room-local coordinates.
"""

from __future__ import annotations

import functools

from markerplace.errors import UserError
from markerplace.scene.builtin.layout import Building, Door, Item, Layout, Opening, Picture, RoomSpec, chairs_around, wall_item, workstation
from markerplace.scene.builtin.campus import build_campus, campus_plan
from markerplace.scene.builtin.house import build_house, house_plan
from markerplace.scene.builtin.procedural import build_scene
from markerplace.scene.types import Scene

# ----------------------------------------------------------------------------------------------


def _tiny() -> Layout:
    size = (3.6, 3.6)
    room = RoomSpec(
        "room",
        (0.0, 0.0, 3.6, 3.6),
        floor="wood",
        items=(wall_item("bookshelf", size, "N", 1.0), wall_item("cabinet", size, "E", 1.2), Item("plant", 0.5, 0.5)),
        pictures=(Picture("W", 1.8, 0.8, "astronaut"),),
        lights=1,
    )
    return Layout("tiny", "one small room (13 m^2) with a bookshelf, a cabinet and a picture; for fast tests", (room,))


def _room() -> Layout:
    size = (5.0, 4.2)
    items = (
        wall_item("sofa", size, "S", 2.0),
        Item("rug", 2.0, 1.9),
        Item("coffee_table", 2.0, 1.9),
        wall_item("tv_stand", size, "N", 2.0),
        wall_item("bookshelf", size, "E", 1.0),
        wall_item("plant", size, "E", 3.5),
        *workstation(0.45, 3.1, 90.0),
    )
    room = RoomSpec(
        "living",
        (0.0, 0.0, 5.0, 4.2),
        floor="wood",
        wall_color=(234, 230, 220),
        items=items,
        pictures=(Picture("W", 1.3, 0.9, "chelsea"), Picture("N", 2.0, 0.6, "art:1", z_center=1.7)),
        lights=2,
    )
    return Layout("room", "a single living room (21 m^2): sofa, TV, a bookshelf, a desk, two pictures", (room,))


def _office() -> Layout:
    open_size = (9.0, 8.0)
    desks = []
    for cy in (2.6, 5.8):
        for x in (1.8, 3.3, 4.8):
            desks += workstation(x, round(cy - 0.35, 4), 0.0)
            desks += workstation(x, round(cy + 0.35, 4), 180.0)
    open_office = RoomSpec(
        "open_office",
        (0.0, 0.0, 9.0, 8.0),
        floor="carpet",
        wall_color=(236, 234, 228),
        items=(
            *desks,
            wall_item("bookshelf", open_size, "W", 5.5),
            wall_item("bookshelf", open_size, "W", 6.45),
            wall_item("cabinet", open_size, "W", 1.2),
            wall_item("printer", open_size, "S", 7.6),
            Item("plant", 8.4, 7.4),
        ),
        pictures=(
            Picture("S", 2.4, 2.0, "whiteboard"),
            Picture("S", 5.0, 0.7, "art:1"),
            Picture("E", 0.8, 0.7, "art:1"),
        ),
        lights=6,
    )
    meet_size = (5.0, 4.5)
    meeting = RoomSpec(
        "meeting",
        (9.0, 0.0, 14.0, 4.5),
        floor="wood",
        wall_color=(226, 231, 236),
        items=(
            Item("big_table", 2.6, 2.25),
            *chairs_around(2.6, 2.25, 0.55, (-0.7, 0.0, 0.7)),
            wall_item("tv_stand", meet_size, "E", 2.25),
        ),
        pictures=(Picture("S", 2.5, 1.0, "hubble"),),
        lights=2,
    )
    kit_size = (5.0, 3.5)
    kitchen = RoomSpec(
        "kitchen",
        (9.0, 4.5, 14.0, 8.0),
        floor="tiles",
        wall_color=(240, 233, 216),
        items=(
            wall_item("counter", kit_size, "N", 2.6),
            wall_item("fridge", kit_size, "N", 4.3),
            Item("table", 2.9, 1.5),
            *chairs_around(2.9, 1.5, 0.45, (-0.4, 0.4)),
        ),
        pictures=(Picture("E", 1.5, 0.6, "coffee"),),
        lights=1,
    )
    return Layout(
        "office",
        "an office (112 m^2): open-plan room with 12 identical desks, a meeting room and a kitchen",
        (open_office, meeting, kitchen),
        doors=(Door("open_office", "meeting"), Door("open_office", "kitchen"), Door("meeting", "kitchen", at=0.2)),
    )


def _studio() -> Layout:
    loft_size = (12.0, 10.0)
    loft = RoomSpec(
        "loft",
        (0.0, 0.0, 12.0, 10.0),
        floor="wood",
        wall_color=(238, 235, 228),
        items=(
            Item("rug", 3.0, 3.3),
            Item("coffee_table", 3.0, 3.3),
            Item("sofa", 3.0, 2.0, 180.0),
            Item("tv_stand", 3.0, 4.7, 0.0),
            wall_item("counter", loft_size, "N", 9.0),
            wall_item("fridge", loft_size, "N", 10.8),
            Item("table", 8.8, 6.6),
            *chairs_around(8.8, 6.6, 0.45, (-0.4, 0.4)),
            wall_item("bed", loft_size, "N", 2.2),
            wall_item("nightstand", loft_size, "N", 0.9),
            wall_item("nightstand", loft_size, "N", 3.5),
            wall_item("wardrobe", loft_size, "W", 6.2),
            wall_item("bookshelf", loft_size, "S", 7.5),
            wall_item("bookshelf", loft_size, "S", 8.45),
            wall_item("plant", loft_size, "S", 11.3),
            Item("plant", 0.5, 0.5),
        ),
        pictures=(
            Picture("N", 2.2, 1.0, "astronaut", z_center=1.7),
            Picture("W", 2.5, 1.2, "art:2"),
            Picture("S", 3.0, 0.8, "art:3"),
        ),
        lights=6,
    )
    bath = RoomSpec(
        "bathroom",
        (12.0, 0.0, 15.0, 4.0),
        floor="bath_tiles",
        wall_color=(225, 235, 238),
        items=(wall_item("bathtub", (3.0, 4.0), "S", 1.2), wall_item("sink", (3.0, 4.0), "E", 2.6)),
        pictures=(Picture("N", 1.5, 0.4, "coins"),),
        lights=1,
    )
    storage = RoomSpec(
        "storage",
        (12.0, 4.0, 15.0, 7.0),
        floor="tiles",
        wall_color=(230, 230, 225),
        items=(wall_item("bookshelf", (3.0, 3.0), "E", 0.8), wall_item("bookshelf", (3.0, 3.0), "E", 1.75), wall_item("cabinet", (3.0, 3.0), "N", 2.2)),
        lights=1,
    )
    study = RoomSpec(
        "study",
        (12.0, 7.0, 15.0, 10.0),
        floor="carpet",
        wall_color=(232, 228, 215),
        items=(*workstation(2.2, 2.5, 0.0), wall_item("bookshelf", (3.0, 3.0), "E", 1.0)),
        pictures=(Picture("S", 1.5, 0.7, "rocket"),),
        lights=1,
    )
    return Layout(
        "studio",
        "a loft studio (150 m^2): one large living/kitchen/bedroom space plus bathroom, storage and study",
        (loft, bath, storage, study),
        doors=(Door("loft", "bathroom"), Door("loft", "storage"), Door("loft", "study")),
    )


def _twin_bedroom(name: str, bounds: tuple[float, float, float, float]) -> RoomSpec:
    size = (4.0, 6.5)
    return RoomSpec(
        name,
        bounds,
        floor="wood_dark",
        wall_color=(228, 232, 226),
        items=(
            wall_item("bed", size, "S", 2.0),
            wall_item("nightstand", size, "S", 0.75),
            wall_item("nightstand", size, "S", 3.3),
            wall_item("wardrobe", size, "E", 4.2),
            *workstation(0.42, 3.6, 90.0),
            Item("rug", 2.2, 3.4),
        ),
        pictures=(Picture("W", 5.3, 0.7, "art:4"), Picture("E", 1.6, 0.7, "astronaut")),
        template="twin_bedroom",
        lights=2,
    )


def _apartment() -> Layout:
    living_size = (8.0, 6.5)
    living = RoomSpec(
        "living",
        (0.0, 0.0, 8.0, 6.5),
        floor="wood",
        wall_color=(238, 234, 224),
        items=(
            Item("rug", 3.5, 3.3),
            Item("coffee_table", 3.5, 3.3),
            Item("sofa", 3.5, 2.0, 180.0),
            Item("tv_stand", 3.5, 4.7, 0.0),
            wall_item("bookshelf", living_size, "W", 1.5),
            wall_item("bookshelf", living_size, "W", 2.45),
            wall_item("bookshelf", living_size, "W", 3.4),
            wall_item("plant", living_size, "S", 7.3),
        ),
        pictures=(Picture("S", 3.5, 1.2, "art:5"), Picture("W", 5.3, 0.8, "chelsea")),
        openings=(Opening("S", 1.5, 1.2, "window"), Opening("S", 5.8, 0.9, "glass_door", sill=0.0)),
        lights=4,
    )
    kitchen_size = (4.0, 6.5)
    kitchen = RoomSpec(
        "kitchen",
        (8.0, 0.0, 12.0, 6.5),
        floor="tiles",
        wall_color=(242, 236, 220),
        items=(
            wall_item("counter", kitchen_size, "S", 1.9),
            wall_item("fridge", kitchen_size, "S", 3.45),
            Item("table", 1.9, 4.3),
            *chairs_around(1.9, 4.3, 0.45, (-0.4, 0.4)),
        ),
        pictures=(Picture("E", 2.5, 0.6, "coffee"),),
        lights=2,
    )
    corridor = RoomSpec(
        "corridor",
        (0.0, 6.5, 20.0, 8.5),
        floor="wood",
        wall_color=(240, 240, 236),
        pictures=(
            Picture("S", 3.0, 1.0, "hubble"),
            Picture("S", 15.0, 0.8, "moon"),
            Picture("N", 1.8, 0.9, "camera"),
            Picture("N", 9.25, 0.8, "rocket"),
        ),
        openings=(Opening("W", 1.0, 0.9, "door", sill=0.0),),  # the front door
        lights=4,
    )
    master_size = (6.0, 6.5)
    master = RoomSpec(
        "master_bedroom",
        (0.0, 8.5, 6.0, 15.0),
        floor="carpet",
        wall_color=(236, 226, 222),
        items=(
            wall_item("bed", master_size, "N", 3.0),
            wall_item("nightstand", master_size, "N", 1.75),
            wall_item("nightstand", master_size, "N", 4.25),
            wall_item("wardrobe", master_size, "E", 3.0),
            wall_item("wardrobe", master_size, "E", 4.25),
            Item("rug", 3.0, 3.0),
            wall_item("plant", master_size, "W", 0.8),
        ),
        pictures=(Picture("N", 3.0, 1.0, "art:6", z_center=1.7), Picture("W", 3.5, 0.8, "ihc")),
        openings=(Opening("W", 5.3, 1.2, "window"),),
        lights=2,
    )
    bath = RoomSpec(
        "bathroom",
        (6.0, 8.5, 9.0, 15.0),
        floor="bath_tiles",
        wall_color=(225, 235, 238),
        items=(wall_item("bathtub", (3.0, 6.5), "N", 1.5), wall_item("sink", (3.0, 6.5), "W", 3.5)),
        lights=1,
    )
    study_size = (4.0, 6.5)
    study = RoomSpec(
        "study",
        (9.0, 8.5, 13.0, 15.0),
        floor="carpet",
        wall_color=(230, 232, 236),
        items=(
            *workstation(1.2, 3.6, 0.0),
            *workstation(2.7, 3.6, 0.0),
            wall_item("bookshelf", study_size, "N", 1.0),
            wall_item("bookshelf", study_size, "N", 1.95),
            wall_item("bookshelf", study_size, "N", 2.9),
        ),
        pictures=(Picture("E", 2.0, 0.8, "retina"),),
        lights=2,
    )
    bath2 = RoomSpec(
        "bathroom_2",
        (13.0, 8.5, 16.5, 15.0),
        floor="tiles",
        wall_color=(230, 236, 230),
        items=(wall_item("bathtub", (3.5, 6.5), "N", 1.75), wall_item("sink", (3.5, 6.5), "E", 3.5)),
        lights=1,
    )
    dining_size = (3.5, 6.5)
    dining = RoomSpec(
        "dining",
        (16.5, 8.5, 20.0, 15.0),
        floor="wood",
        wall_color=(236, 232, 222),
        items=(
            Item("table", 1.75, 4.0, 90.0),
            Item("chair", 1.0, 3.6, 90.0),
            Item("chair", 1.0, 4.4, 90.0),
            Item("chair", 2.5, 3.6, -90.0),
            Item("chair", 2.5, 4.4, -90.0),
            wall_item("cabinet", dining_size, "N", 1.75),
            wall_item("plant", dining_size, "E", 1.2),
        ),
        pictures=(Picture("W", 4.0, 0.8, "coffee"),),
        openings=(Opening("E", 4.0, 1.2, "window"),),
        lights=2,
    )
    bed_a = _twin_bedroom("bedroom_a", (12.0, 0.0, 16.0, 6.5))
    bed_b = _twin_bedroom("bedroom_b", (16.0, 0.0, 20.0, 6.5))
    return Layout(
        "apartment",
        "an apartment (300 m^2): corridor and 9 rooms, including two identical bedrooms (perceptual aliasing); "
        "windows, a glass door and a front door",
        (living, kitchen, bed_a, bed_b, corridor, master, bath, study, bath2, dining),
        doors=(
            Door("living", "corridor", at=0.8),
            Door("kitchen", "corridor"),
            Door("living", "kitchen"),
            Door("bedroom_a", "corridor", at=0.25),
            Door("bedroom_b", "corridor", at=0.25),
            Door("master_bedroom", "corridor", at=0.7),
            Door("bathroom", "corridor"),
            Door("study", "corridor"),
            Door("bathroom_2", "corridor"),
            Door("dining", "corridor"),
        ),
        twins=(("bedroom_a", "bedroom_b"),),
    )


_LAYOUTS = {"office": _office, "studio": _studio, "apartment": _apartment, "room": _room, "tiny": _tiny, "house": house_plan,
            "campus": campus_plan}
# multi-storey built-ins: their own builders (single-storey ones use procedural.build_scene)
_BUILDERS = {"house": build_house, "campus": build_campus}


def builtin_names() -> list[str]:
    """Names of the built-in scenes, in catalogue order."""
    return list(_LAYOUTS)


@functools.lru_cache(maxsize=None)
def get_layout(name: str) -> Layout | Building:
    """The :class:`Layout` of a built-in scene, or the :class:`~.layout.Building` (one layout per
    storey) of a multi-storey one; both have ``rooms``, ``floor_area`` and ``description``.
    Raises UserError for an unknown name."""
    if name not in _LAYOUTS:
        raise UserError(f"unknown built-in scene {name!r}; choose one of {', '.join(_LAYOUTS)}")
    return _LAYOUTS[name]()


def build_builtin(name: str, seed: int = 0) -> Scene:
    """Build a built-in scene afresh (uncached); deterministic in ``seed``."""
    plan = get_layout(name)
    if name in _BUILDERS:
        return _BUILDERS[name](seed)
    return build_scene(plan, seed)


@functools.lru_cache(maxsize=16)
def get_builtin(name: str, seed: int = 0) -> Scene:
    """Built-in scene ``name`` for ``seed``, cached in this process (arrays are read-only)."""
    return build_builtin(name, seed)


def list_scenes() -> list[dict]:
    """One dict per built-in scene: name, area_m2 (floor area), rooms (count), description.

    Computed from the layouts; no mesh is built.
    """
    rows = []
    for name in _LAYOUTS:
        layout = get_layout(name)
        rows.append({"name": name, "area_m2": round(layout.floor_area, 2), "rooms": len(layout.rooms), "description": layout.description})
    return rows
