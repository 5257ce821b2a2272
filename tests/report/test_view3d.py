"""The reports' 3D view (report/view3d.py, view3d.js): the view's copy of the model, and the view
in headless chromium (software WebGL): it draws, each tag is drawn where it was planned (the
screenshot's pixel at the tag's projected centre has the tag's colour), and a click on a tag
selects its card; on room, house and a scan-like model."""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest

from helpers.browser import click_tag, screenshot, view_call
from markerplace.geometry import world_from_marker_pose
from markerplace.markers import Marker
from markerplace.report.html import write_page
from markerplace.report.view3d import FOUND_COLOR, PLANNED_COLOR, scene_view_html, view_mesh
from markerplace.scene.raycast import RayCaster
from markerplace.scene.types import MeshPart, Scene

BACKGROUND = (237, 241, 245)
"""The view's clear colour (0.93, 0.945, 0.96) in 8 bits."""
VIEW = "mp-view3d"


def wall_tags(scene, points, size=0.4, first_id=0, all_hit=True) -> list[Marker]:
    """One tag per ``(x, y, z, yaw_deg)``: on the first wall hit by the horizontal ray from (x, y, z)
    towards yaw (between 1.3 and 10 m away), facing back along the ray. ``all_hit``: every ray
    must hit (else the misses are left out)."""
    rc = RayCaster(*scene.geometry())
    o = np.array([p[:3] for p in points], float)
    d = np.array([[np.cos(np.radians(p[3])), np.sin(np.radians(p[3])), 0.0] for p in points])
    t, _ = rc.first_hits(o, d, max_t=10.0)
    hit = np.isfinite(t) & (t > 1.3)
    assert hit.all() or not all_hit, t
    return [Marker(first_id + i, size, world_from_marker_pose(o[i] + t[i] * d[i], -d[i])) for i in np.flatnonzero(hit)]


def moved(m: Marker, along: float) -> Marker:
    """``m`` shifted along its wall (its x axis), metres: a tag hung off its spot."""
    T = np.array(m.world_from_marker)
    T[:3, 3] += along * T[:3, 0]
    return Marker(m.tag_id, m.size, T)


def view_page(path, scene, planned, found=None, **kw):
    """A page with the view and one card per tag (ids tag1.. and found1..) below it."""
    found = found or []
    frag = scene_view_html(scene, planned, found, found_cards=[f"found{j + 1}" for j in range(len(found))], **kw)
    cards = "".join(f'<div class="tag" id="tag{i + 1}"><h3>#{i + 1}</h3></div>' for i in range(len(planned)))
    cards += "".join(f'<div class="tag" id="found{j + 1}"><h3>found {j + 1}</h3></div>' for j in range(len(found)))
    return write_page(path, "3D view", frag + cards + '<div style="height: 3000px"></div>')


def open_view(driver, path):
    """Load the page; the view's API once it has drawn (asserts no error and no SEVERE console line)."""
    driver.get(path.resolve().as_uri())
    api = driver.execute_script(f"return window.mpView3d && window.mpView3d['{VIEW}'] && "
                                f"{{error: window.mpView3d['{VIEW}'].error, frames: window.mpView3d['{VIEW}'].frames}}")
    assert api and api["error"] is None and api["frames"] >= 1, api
    severe = [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]
    assert not severe, severe
    return api


def js(driver, call: str):
    return view_call(driver, VIEW, call)


def canvas_pixels(driver) -> np.ndarray:
    r = driver.execute_script(f"var r = document.querySelector('#{VIEW} canvas').getBoundingClientRect();"
                              "return [r.left, r.top, r.width, r.height]")
    x, y, w, h = (int(round(v)) for v in r)
    return screenshot(driver)[y:y + h, x:x + w]


def pixel(shot, x, y) -> np.ndarray:
    """The median colour of the 3 x 3 pixels around client position (x, y)."""
    xi, yi = int(round(x)), int(round(y))
    return np.median(shot[yi - 1:yi + 2, xi - 1:xi + 2].reshape(-1, 3), axis=0)


def assert_tags_drawn_where_planned(driver, kinds):
    """Turn the camera to each tag in turn: the screenshot at its projected centre has its colour."""
    js(driver, "labels(false)")
    colours = {"planned": PLANNED_COLOR, "found": FOUND_COLOR}
    for kind, n in kinds.items():
        for i in range(n):
            js(driver, f"focusTag('{kind}', {i})")
            t = [p for p in js(driver, "projectedTags()") if p["kind"] == kind and p["index"] == i][0]
            shot = screenshot(driver)
            assert np.abs(pixel(shot, t["x"], t["y"]) - colours[kind]).max() <= 8, (kind, i, pixel(shot, t["x"], t["y"]))
            assert t["visible"]
    js(driver, "labels(true)")
    js(driver, "reset()")


# ---------------------------------------------------------------- the view's copy of the model

def grid_part(n: int, colors=None, texture=None, uv=None, **kw) -> MeshPart:
    """An n x n cell grid on z = 0 over [0, 1]^2 (2 n^2 faces)."""
    g = np.linspace(0.0, 1.0, n + 1)
    xx, yy = np.meshgrid(g, g)
    v = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1).astype(np.float32)
    k = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None]).ravel()
    f = np.concatenate([np.stack([k, k + 1, k + n + 2], 1), np.stack([k, k + n + 2, k + n + 1], 1)]).astype(np.int32)
    if uv == "xy":
        uv = v[:, :2].copy()
    return MeshPart("grid", v, f, uv=uv, colors=colors, texture=texture, **kw)


def test_view_mesh_colours_glass_and_decimation():
    red_left = np.where((np.linspace(0, 1, 101)[None].repeat(101, 0).ravel() < 0.5)[:, None], [255, 0, 0, 255],
                        [0, 0, 255, 255]).astype(np.uint8)
    tex = np.zeros((4, 4, 3), np.uint8)
    tex[:2] = (0, 200, 0)  # top half of the image green: v >= 0.5
    parts = (grid_part(100, colors=red_left),  # 20,000 faces, vertex colours
             grid_part(2, texture=tex, uv="xy", base_color=(1, 0.5, 1, 1)),  # small: the texture's mean times base
             grid_part(40, texture=tex, uv="xy"),  # 3,200 faces: sampled at the vertices
             grid_part(3, transparent=True))  # glass: left out
    small = view_mesh(Scene("s", parts[1:]))
    assert small.source_faces == 8 + 3200 and len(small.faces) == small.source_faces
    assert (small.colors[:9] == [0, 50, 0]).all()  # the mean (0, 100, 0) times base (1, 0.5, 1)
    dense = small.colors[9:]
    upper = small.vertices[9:, 1] > 0.55
    assert (dense[upper] == [0, 200, 0]).all() and (dense[small.vertices[9:, 1] < 0.45] == 0).all()
    mesh = view_mesh(Scene("s", parts[:1]), max_triangles=2000)
    assert 1000 < len(mesh.faces) <= 2000 and mesh.source_faces == 20_000
    c = mesh.colors.astype(int)  # carried along: red, blue or a mixture of the two (colour is not in the quadric)
    assert (c[:, 1] == 0).all() and (np.abs(c[:, 0] + c[:, 2] - 255) <= 2).all()
    assert (c[:, 0] > 200).any() and (c[:, 2] > 200).any()


def test_fragment_is_one_offline_piece():
    from markerplace.scene import load_scene

    scene = load_scene("tiny")
    tags = wall_tags(scene, [(1.8, 1.8, 1.5, 0), (1.8, 1.8, 1.5, 90)])
    html = scene_view_html(scene, tags, camera_path=np.zeros((7000, 3)))
    assert not re.search(r"""(src|href)\s*=\s*["'](?!data:|#)""", html)
    data = json.loads(re.search(r'<script type="application/json" class="mp-view3d-data">(.*?)</script>', html, re.S)
                      .group(1).replace("<\\/", "</"))
    assert [t["card"] for t in data["planned"]] == ["tag1", "tag2"] and data["found"] == []
    assert len(data["path"]) == 5000 and data["index_bits"] == 16
    assert data["planned"][0]["centre"] == pytest.approx(list(tags[0].position + 0.01 * tags[0].normal), abs=1e-4)


# ---------------------------------------------------------------- in the browser

@pytest.fixture(scope="module")
def room():
    from markerplace.scene import load_scene

    return load_scene("room")


def test_room_view_draws_tags_where_planned_and_a_click_selects_the_card(room, browser, tmp_path):
    planned = wall_tags(room, [(2.5, 2.0, 1.5, 0), (2.5, 2.0, 1.6, 90), (2.5, 2.0, 1.4, 180), (2.5, 2.0, 1.5, 270)])
    found = [moved(planned[0], -0.6), moved(planned[1], 0.5)]
    path = view_page(tmp_path / "room.html", room, planned, found, camera_path=np.array([[1, 1, 1.5], [3, 2, 1.5]]))
    open_view(driver := browser, path)
    px = canvas_pixels(driver).astype(int)
    assert (np.abs(px - BACKGROUND).max(axis=2) > 10).mean() > 0.2  # the model fills the canvas
    assert_tags_drawn_where_planned(driver, {"planned": 4, "found": 2})
    tags = js(driver, "projectedTags()")
    visible = [(t["kind"], t["index"]) for t in tags if t["visible"]]
    assert len(visible) >= 3, tags  # the initial view sees most tags over the near wall
    for kind, index in visible:
        card = f"tag{index + 1}" if kind == "planned" else f"found{index + 1}"
        assert click_tag(driver, VIEW, kind, index) == [card]
        top = driver.execute_script(f"return document.getElementById('{card}').getBoundingClientRect().top")
        assert abs(top) < 2  # scrolled to the card
    labels = driver.execute_script(f"return Array.from(document.querySelectorAll('#{VIEW} .mp-label')).map(e => e.textContent)")
    assert labels == ["1", "2", "3", "4", "id 0", "id 1"]


def test_house_view_cuts_storeys(house, browser, tmp_path):
    planned = wall_tags(house, [(3.0, 2.0, 1.3, 90), (8.0, 2.0, 1.5, 0), (2.5, 2.0, 4.5, 180), (6.5, 2.0, 4.5, 90)])
    path = view_page(tmp_path / "house.html", house, planned)
    open_view(browser, path)
    cut = js(browser, "camera()")["cut"]
    assert cut == pytest.approx(4.5 + 0.2 + 0.3, abs=0.01)  # above the upper storey's tags: its ceiling is gone
    seen = {t["index"] for t in js(browser, "projectedTags()") if t["visible"]}
    assert seen and seen <= {2, 3}  # the upper floor hides the ground floor's tags
    js(browser, "setCut(2.2)")  # the ground floor only
    seen = {t["index"] for t in js(browser, "projectedTags()") if t["visible"]}
    assert seen and seen <= {0, 1}
    assert_tags_drawn_where_planned(browser, {"planned": 4})


def test_scan_like_model_stays_small_and_opens(browser, tmp_path):
    """150k triangles of a scan-like room: decimated to 100k, a few MB of HTML, and it draws."""
    from helpers.atlas_scenes import multi_atlas_room

    scene = multi_atlas_room()
    assert scene.num_faces > 150_000
    planned = wall_tags(scene, [(3.0, 2.5, 1.5, 0), (3.0, 2.5, 1.5, 90)])
    path = view_page(tmp_path / "scan.html", scene, planned)
    assert path.stat().st_size < 8e6
    t = time.perf_counter()
    api = open_view(browser, path)
    assert time.perf_counter() - t < 30 and api["frames"] >= 1
    assert js(browser, "triangles") <= 100_000
    assert_tags_drawn_where_planned(browser, {"planned": 2})


@pytest.mark.slow
def test_scan_of_the_house_is_under_20_mb_and_opens(browser, tmp_path):
    """`scene export house --as-scan` (about 1.1 M faces; some 5 min to make): the report's view of
    it stays under 20 MB, opens, and draws its tags where planned."""
    from markerplace.cli.main import main
    from markerplace.scene import load_scene

    ply = tmp_path / "house_scan.ply"
    assert main(["--quiet", "scene", "export", "house", str(ply), "--as-scan"]) == 0
    scene = load_scene(str(ply), up="z")
    assert scene.num_faces > 300_000
    rooms = load_scene("house").rooms  # the scan is in the house's frame
    rays = [((r.bounds[0] + r.bounds[2]) / 2, (r.bounds[1] + r.bounds[3]) / 2, r.floor_z + 1.5, a)
            for r in rooms for a in (0, 90, 180, 270)]
    planned = wall_tags(scene, rays, all_hit=False)[::8]
    assert len(planned) >= 3
    path = view_page(tmp_path / "scan.html", scene, planned)
    assert path.stat().st_size < 20e6
    assert open_view(browser, path)["frames"] >= 1 and js(browser, "triangles") <= 100_000
    assert_tags_drawn_where_planned(browser, {"planned": len(planned)})
