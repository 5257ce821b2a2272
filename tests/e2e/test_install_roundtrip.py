"""Install round trip: from a plan's tags.pdf and placement.csv to tags on the walls to camera
poses from every robot's tag map.

A person is simulated literally, with nothing from the plan but what an installer is told:

1. **print**: tags.pdf is rasterized by poppler's ``pdftoppm``; each page's words are read by
   ``pdftotext`` (which tag, which tile, "this edge down"); the tiles are taped together where
   their printed edges and crosshairs put them (``pdf.tile_layout``, the page map's geometry);
2. **hang**: from the tag's ``placement.csv`` row only: find the wall (the storey's wall facing
   the given way near the place the floor plan shows, read 0.3 m off along the wall), measure
   the floor under it, run a tape along the wall from the named reference (corner, door edge
   or wall end: found in the model's geometry by rays, as a person finds it in the building)
   for the given distance, up from the floor for the given height, and hang the taped print
   flat on the wall with the edge marked "this edge down" at the bottom;
3. **look**: render camera views of the scene with only the hung prints on its walls (the
   plan's markers are not drawn), detect the tags, and compute each camera's pose from every
   tag map in ``tagmaps/`` with that consumer's own conventions (``tests/helpers/consumers.py``: WPILib
   through robotpy-apriltag, apriltag_ros, TagSLAM, the ROS 2 node).

Pass: every camera within 3 cm and 1 degree of where it was, for every tag of the plan and
every format. A turned tag family, a wrong tag frame in a map, a height measured to a table
top or a distance measured to furniture all fail it.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from helpers import consumers, printed_tags
from markerplace.cli.main import main
from markerplace.geometry import Intrinsics
from markerplace.render.renderer import Renderer
from markerplace.report.sheets import tile_layout
from markerplace.scene import load_scene
from markerplace.scene.raycast import RayCaster
from markerplace.scene.types import MeshPart, Scene

PLANS = {"room": 8, "house": 12}
"""Scene -> k: every tag of these plans is printed, hung and seen."""
DPI = 40
"""Raster of the printed pages: a 0.4 m tag's bit (50 mm) is about 80 px."""
PX_PER_MM = DPI / 25.4
INTR = Intrinsics.from_fov(1280, 960, 90.0)
"""The robot's camera: a 0.4 m tag 1.8 m away spans about 140 px."""
UP = np.array([0.0, 0.0, 1.0])
COMPASS = {"east": 0, "north-east": 45, "north": 90, "north-west": 135, "west": 180, "south-west": 225,
           "south": 270, "south-east": 315}
MAX_POSITION_M, MAX_ROTATION_DEG = 0.03, 1.0
LIFT_M = 0.002
"""Paper on the wall: drawn this far off the wall surface (depth-buffer precision)."""


@pytest.fixture(scope="module", params=list(PLANS))
def plan(request, tmp_path_factory):
    """(scene name, plan folder) of ``markerplace plan SCENE -k K``, run as a user runs it."""
    name = request.param
    out = tmp_path_factory.mktemp(f"plan_{name}")
    assert main(["--quiet", "plan", name, "-k", str(PLANS[name]), "--out", str(out)]) == 0
    return name, out


def _rows(folder: Path) -> list[dict]:
    with open(folder / "placement.csv", newline="") as fh:
        return list(csv.DictReader(fh))


# ---- 1. print ---------------------------------------------------------------------------------

def _pages(spec: str) -> list[int]:
    a, _, b = spec.partition("-")
    return list(range(int(a), int(b or a) + 1))


def print_and_tape(folder: Path, row: dict, work: Path) -> np.ndarray:
    """The taped print of one tag: (n, n) uint8, the square with its quiet zone, row 0 = top,
    the bottom being the edge its pages mark "this edge down"."""
    pdf = folder / "tags.pdf"
    pages = _pages(row["tags_pdf_pages"])
    images = printed_tags.rasterize(pdf, work / f"tag{row['order']}", DPI, pages[0], pages[-1])
    tiles, rows_down = {}, set()
    for page, image in zip(pages, images):
        words = printed_tags.page_text(pdf, page)
        m = printed_tags.TILE_WORDS.search(words)
        if m is None:
            assert "Page map" in words, f"page {page} names no tile and is no page map"
            continue
        order, tag_id, name, r, rows, c, cols = m.groups()
        assert (order, tag_id) == (row["order"], row["tag_id"]), f"page {page} is {order}/{tag_id}, not row {row}"
        tiles[name] = image
        if "this edge down" in words:
            rows_down.add(int(r))
    edge_mm = float(row["size_mm"]) * 12 / 8  # square + quiet zone: 8 + 2 x 2 bits of the family
    layout = tile_layout(edge_mm, "a4")
    assert sorted(tiles) == sorted(t.name for t in layout.tiles)
    assert rows_down == {layout.rows}, "the pages marked 'this edge down' are not the bottom row"
    return printed_tags.tape_tiles(layout, tiles, PX_PER_MM)


# ---- 2. hang ----------------------------------------------------------------------------------

def _unit(v):
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


class Person:
    """Finds walls, floors and corners in the model the way a person finds them in the building:
    by looking and with a tape measure (rays on the model's geometry)."""

    def __init__(self, scene: Scene):
        self.rc = RayCaster(*scene.geometry())

    def hit(self, origins, dirs, max_t=np.inf):
        origins = np.asarray(origins, float).reshape(-1, 3)
        dirs = np.broadcast_to(np.asarray(dirs, float), origins.shape)
        return self.rc.first_hits(origins, dirs, max_t)

    def wall(self, hint_xy, z: float, facing_deg: float) -> tuple[np.ndarray, np.ndarray]:
        """The wall facing ``facing_deg`` in front of ``hint_xy`` at height ``z``: a point on its
        surface and its normal into the room."""
        n0 = np.array([np.cos(np.radians(facing_deg)), np.sin(np.radians(facing_deg)), 0.0])
        start = np.array([hint_xy[0], hint_xy[1], z]) + 0.5 * n0
        t, face = self.hit(start, -n0, 2.0)
        assert np.isfinite(t[0]), f"no wall facing {facing_deg} deg near {hint_xy}"
        n = self.rc.face_normal[face[0]].astype(float)
        n = _unit(n if n @ n0 > 0 else -n)
        assert n @ n0 > np.cos(np.radians(22.5)), "the wall there does not face the way the sheet says"
        return start - t[0] * n0, n

    def floor(self, wall_point, n, tag_z: float) -> float:
        """Height of the floor a person stands on to hang the tag: the lowest level that covers
        a tenth of the ground 0.1-1.6 m in front of the wall and 1.5 m either side (a sofa, a
        desk or a sideboard against the wall cover parts of it, standing higher), and from which
        the tag is within reach (not 2.5 m or more below it: a stairwell's lower storey)."""
        right = np.cross(UP, n)
        pts = np.array([wall_point + a * n + b * right for a in (0.08, 0.4, 0.8, 1.2, 1.6)
                        for b in np.linspace(-1.5, 1.5, 16)])
        t, _ = self.hit(pts, -UP, 4.0)
        z = pts[np.isfinite(t), 2] - t[np.isfinite(t)]
        z = z[z > tag_z - 2.5]
        assert len(z), "no floor under the tag"
        share = (np.abs(z[:, None] - z[None]) < 0.02).mean(axis=1)
        return float(np.min(z[share >= 0.1]))

    def reference(self, wall_point, n, floor_z: float, height: float, direction, kind: str) -> np.ndarray:
        """Where a tape measure run along the wall from the tag's rough place towards
        ``direction`` starts: the ``kind`` of reference the sheet names. A corner is where the
        tape meets the next wall at the floor line, at the tag's height and up high (the farthest
        of the three: furniture stops a tape low down, not the tape above it); a door edge or a
        wall end is where the wall surface behind the tape stops at the floor line and at the
        tag's height. Returns the reference at the tag's height, on the wall plane."""
        ceiling_t, _ = self.hit(wall_point + 0.05 * n, UP, 10.0)
        top = min(floor_z + 2.3, wall_point[2] + (ceiling_t[0] if np.isfinite(ceiling_t[0]) else 10.0) - 0.1)
        heights = np.array([floor_z + 0.1, floor_z + height, top])
        base = wall_point.copy()
        along = []
        for h in heights:
            o = base.copy()
            o[2] = h
            t, _ = self.hit(o + 0.01 * n, direction, 30.0)
            along.append(t[0])
        corner = float(np.max(along))
        if kind == "corner":
            assert np.isfinite(corner), "no corner along the wall"
            d = corner  # the tape runs 1 cm off the wall: it meets the next wall at the corner line
        else:
            # where the wall surface behind the tape stops, at the floor line and at the tag's height
            s = np.arange(0.0, min(corner, 30.0) + 0.005, 0.005)
            gone = np.ones(len(s), dtype=bool)
            for h in heights[:2]:
                o = base[None] + s[:, None] * direction[None]
                o[:, 2] = h
                t, _ = self.hit(o + 0.1 * n, -n, 0.15)
                gone &= ~(np.abs(t - 0.1) < 0.03)
            assert gone.any(), f"the sheet says {kind!r} but the wall does not stop before the corner"
            d = float(s[np.argmax(gone)])
        ref = base + d * direction
        ref[2] = floor_z + height
        return ref


def hang(person: Person, row: dict) -> np.ndarray:
    """world_from_marker of the tag as a person hangs it from its placement.csv row."""
    facing = COMPASS[row["faces"]]
    x, y, z = float(row["x"]), float(row["y"]), float(row["z"])
    n0 = np.array([np.cos(np.radians(facing)), np.sin(np.radians(facing)), 0.0])
    rough = np.array([x, y]) + 0.3 * np.cross(UP, n0)[:2]  # the floor plan read 0.3 m off
    wall_point, n = person.wall(rough, z, facing)
    floor_z = person.floor(wall_point, n, z)
    assert abs(floor_z - float(row["floor_z_m"])) < 0.02, "the floor is not where the sheet says"
    height = float(row["centre_height_above_floor_m"])
    right = np.cross(UP, n)  # to a person's right as they face the wall (looking along -n)
    centres = []
    for side, sign in (("left", -1.0), ("right", 1.0)):
        kind = row[f"{side}_reference"]
        if kind == "none":
            continue
        ref = person.reference(wall_point, n, floor_z, height, sign * right, kind)
        centres.append(ref - sign * float(row[f"{side}_reference_to_centre_m"]) * right)
    assert centres, "the sheet names no reference to measure from"
    if len(centres) == 2:  # measured from both ends: the two agree
        assert np.linalg.norm(centres[0] - centres[1]) < 0.02, centres
    centre = centres[0]
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = right, UP, n, centre  # upright, flat on the wall
    return T


def paper(T: np.ndarray, print_img: np.ndarray, edge_m: float, name: str) -> MeshPart:
    """The taped print as a textured quad on the wall (row 0 of the print at the top)."""
    h = edge_m / 2
    local = np.array([[-h, h, LIFT_M], [h, h, LIFT_M], [h, -h, LIFT_M], [-h, -h, LIFT_M]])
    verts = local @ T[:3, :3].T + T[:3, 3]
    return MeshPart(name=name, vertices=verts.astype(np.float32), faces=np.array([[0, 3, 2], [0, 2, 1]], np.int32),
                    uv=np.array([[0, 1], [1, 1], [1, 0], [0, 0]], np.float32),
                    texture=np.repeat(print_img[:, :, None], 3, axis=2),
                    normals=np.repeat(T[None, :3, 2], 4, axis=0).astype(np.float32))


# ---- 3. look ----------------------------------------------------------------------------------

def look_at(eye, target) -> np.ndarray:
    z = _unit(np.asarray(target, float) - eye)
    x = _unit(np.cross(z, UP))
    T = np.eye(4)
    T[:3, 0], T[:3, 1], T[:3, 2], T[:3, 3] = x, np.cross(z, x), z, eye
    return T


def views(person: Person, T: np.ndarray, edge_m: float) -> list[np.ndarray]:
    """Up to two off-axis cameras in front of the tag, one on each side, with a clear view of
    it and standing in free space (closer and less oblique when something is in the way)."""
    c, n, right = T[:3, 3], T[:3, 2], T[:3, 0]
    corners = c + edge_m / 2 * np.array([s * right + u * UP for s, u in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    out = []
    for side in (-1.0, 1.0):
        for dist, lateral in ((1.8, 0.35), (1.4, 0.35), (1.1, 0.3), (1.8, 0.2), (1.4, 0.15), (0.9, 0.25)):
            eye = c + dist * n + side * lateral * dist * right - 0.15 * UP
            d = corners - eye
            t, _ = person.hit(np.repeat(eye[None], 4, 0), d / np.linalg.norm(d, axis=1, keepdims=True))
            clear = np.all(t >= np.linalg.norm(d, axis=1) - 0.01)
            around = person.hit(np.repeat(eye[None], 4, 0), np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0.0]]))[0]
            if clear and np.all(around > 0.1):
                out.append(look_at(eye, c))
                break
    assert out, f"no clear view of the hung tag at {np.round(c, 2)}"
    return out


def test_print_hang_look_every_tag_every_format(plan, tmp_path):
    name, folder = plan
    scene = load_scene(name)
    person = Person(scene)
    rows = _rows(folder)
    assert len(rows) == PLANS[name]
    prints, poses, failures, checked = [], {}, [], 0
    for row in rows:
        img = print_and_tape(folder, row, tmp_path)
        try:
            T = hang(person, row)
        except AssertionError as err:  # every tag's problem in one report
            failures.append(f"tag #{row['order']} (id {row['tag_id']}): cannot hang it from its row: {err}".split("\n")[0])
            continue
        edge_m = img.shape[0] / PX_PER_MM / 1000.0
        prints.append(paper(T, img, edge_m, f"print_{row['order']}"))
        poses[int(row["tag_id"])] = (T, edge_m)
    hung = Scene(scene.name, scene.parts + tuple(prints), scene.rooms, scene.floor_z, scene.source, scene.meta)
    with Renderer(hung, INTR) as renderer:
        for tag_id, (T, edge_m) in poses.items():
            for world_from_cam in views(person, T, edge_m):
                rgb = renderer.render(world_from_cam, depth=False, normal=False).rgb
                gray = np.ascontiguousarray(rgb.mean(axis=2).round().astype(np.uint8))
                estimates = consumers.camera_poses(folder / "tagmaps", gray, INTR.K)
                for fmt, per_tag in estimates.items():
                    if tag_id not in per_tag:
                        failures.append(f"{fmt}: tag {tag_id} not detected")
                        continue
                    dt, dr = consumers.pose_error(per_tag[tag_id], world_from_cam)
                    checked += 1
                    if dt > MAX_POSITION_M or dr > MAX_ROTATION_DEG:
                        failures.append(f"{fmt}: tag {tag_id}: camera {100 * dt:.1f} cm, {dr:.2f} deg off")
    assert not failures, f"{name}: {len(failures)} of {checked} camera poses fail: " + "; ".join(failures[:12])
    assert checked >= len(rows) * len(consumers.FORMATS)
