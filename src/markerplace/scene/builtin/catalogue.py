"""Built-in scenes: layouts of the procedural interiors and a per-process cache of built scenes.

Sizes follow the paper's scenes: office ~110 m^2, studio ~150 m^2, apartment ~300 m^2,
room ~21 m^2, plus ``tiny`` (13 m^2) for fast tests, the two-storey ``house`` (158 m^2,
:mod:`.house`), the two-storey office building ``campus`` for scale tests (2064 m^2,
:mod:`.campus`) and the hotel floor ``corridor`` (288 m^2, ten identical guest rooms: hard to
localize in, :mod:`.corridor`; :func:`.corridor.build_corridor` takes the room count) with its
smaller copy ``corridor-small`` (141 m^2, four identical guest rooms: the demo's scene, read from
the same spec). Coordinates are metres, world z up; room
bounds are wall centre lines; furniture and pictures are in room-local coordinates.

The layouts are data: the rooms, furniture, pictures, windows and doors of each built-in are in
``scene/builtin/specs/<name>.toml`` (TOML; the format is in each file's header and in
:mod:`.spec_loader`, which reads them). The single-storey ones are read whole by
:func:`.spec_loader.load_layout`; :mod:`.house` and :mod:`.campus` add their storeys' heights and
the geometry beyond the layouts (stairs, slabs, glazing); :mod:`.corridor` lays out its guest
rooms and corridor from the room types in its file.
"""

from __future__ import annotations

import functools

from markerplace.errors import UserError
from markerplace.scene.builtin.campus import build_campus, campus_plan
from markerplace.scene.builtin.corridor import SMALL_NAME, build_corridor, build_small_corridor, corridor_plan, small_corridor_plan
from markerplace.scene.builtin.house import build_house, house_plan
from markerplace.scene.builtin.layout import Building, Layout
from markerplace.scene.builtin.procedural import build_scene
from markerplace.scene.builtin.spec_loader import load_layout
from markerplace.scene.types import Scene

# single-storey built-ins: their room specs are data (specs/<name>.toml, read by spec_loader)
_LAYOUTS = {name: functools.partial(load_layout, name) for name in ("office", "studio", "apartment", "room", "tiny")}
_LAYOUTS |= {"house": house_plan, "campus": campus_plan, "corridor": corridor_plan, SMALL_NAME: small_corridor_plan}
# built-ins with their own builders (multi-storey, or laid out in code); the others use
# procedural.build_scene
_BUILDERS = {"house": build_house, "campus": build_campus, "corridor": build_corridor, SMALL_NAME: build_small_corridor}
# built-ins read from another one's spec file (the others from specs/<name>.toml)
_SPECS = {SMALL_NAME: "corridor"}


def builtin_names() -> list[str]:
    """Names of the built-in scenes, in catalogue order."""
    return list(_LAYOUTS)


def spec_of(name: str) -> str:
    """The spec file (``specs/<spec>.toml``, without its suffix) built-in ``name`` is read from."""
    return _SPECS.get(name, name)


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
