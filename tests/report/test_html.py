"""report.html of `plan` and `evaluate`, loaded in a real headless browser (:mod:`helpers.browser`;
the `browser` fixture is in tests/conftest.py), and the caption
maths (facing, wall, height above the local floor, distance along the wall to the nearest corner
or door edge) on hand-built rooms."""

from __future__ import annotations

import re

import numpy as np
import pytest

from helpers import FAST_2_YAWS as FAST
from helpers.browser import check_page, click_tag, view_call
from markerplace.cli.main import main
from markerplace.report.captions import describe_tag, facing_label, wall_side
from markerplace.report.html import markdown_to_html
from markerplace.report.installer import standing_distance
from markerplace.scene.raycast import RayCaster
from markerplace.scene.types import MeshPart, Scene
from markerplace.testbed.reporting.page import gallery_selection

# ---------------------------------------------------------------- hand-built rooms

T, H = 0.1, 2.7  # wall thickness, ceiling height


def box(name, lo, hi) -> MeshPart:
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float32)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                  [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], np.int32)
    return MeshPart(name, v, f)


def room_scene(extra=()) -> Scene:
    """Room with inner faces x in [0, 5], y in [0, 4]; a 0.9 m door in the east wall at y in
    [1.5, 2.4] (lintel at 2.1 m); a 4 cm thick picture on the north wall at x in [1, 2]."""
    parts = [box("floor", (-1, -1, -0.1), (7, 5, 0)), box("ceiling", (-1, -1, H), (7, 5, H + 0.1)),
             box("south", (-T, -T, 0), (5 + T, 0, H)), box("north", (-T, 4, 0), (5 + T, 4 + T, H)),
             box("west", (-T, 0, 0), (0, 4, H)),
             box("east_a", (5, 0, 0), (5 + T, 1.5, H)), box("east_b", (5, 2.4, 0), (5 + T, 4, H)),
             box("lintel", (5, 1.5, 2.1), (5 + T, 2.4, H)),
             box("picture", (1.0, 3.96, 1.0), (2.0, 4.0, 2.0)), *extra]
    return Scene("room_for_captions", tuple(parts), (), 0.0)


@pytest.fixture(scope="module")
def caster():
    return RayCaster(*room_scene().geometry())


def test_facing_and_wall_names():
    assert facing_label([1, 0, 0]) == "east (+x)" and wall_side([1, 0, 0]) == "west"
    assert facing_label([0, -1, 0]) == "south (-y)" and wall_side([0, -1, 0]) == "north"
    assert facing_label([-1, 0, 0]) == "west (-x)" and wall_side([-1, 0, 0]) == "east"
    assert facing_label([1, 1, 0]).startswith("north-east (+x+y") and wall_side([1, 1, 0]) == "south-west"
    assert facing_label([np.cos(0.2), np.sin(0.2), 0]) == "east (+x, 11 deg)"  # off-axis: the angle is given


def test_tag_one_point_two_metres_from_a_corner(caster):
    # on the south wall (faces north), centre 1.2 m east of the west wall's face
    place = describe_tag(caster, np.array([1.2, 0.0, 1.5]), np.array([0.0, 1.0, 0.0]), 0.0)
    assert place.facing == "north (+y)" and place.wall == "south"
    side, end = place.nearest
    # a viewer facing the south wall has west (-x) on the right
    assert side == "right" and end.kind == "corner"
    assert end.distance == pytest.approx(1.2, abs=0.03)
    assert place.left.distance == pytest.approx(3.8, abs=0.03) and place.left.kind == "corner"
    assert place.height == pytest.approx(1.5, abs=0.01)
    assert "1.20 m from the corner on its right" in place.distance_words()


def test_tag_near_a_door_reports_the_door_edge(caster):
    # on the east wall (faces west), 0.9 m south of the door's south jamb at y = 1.5
    place = describe_tag(caster, np.array([5.0, 0.6, 1.5]), np.array([-1.0, 0.0, 0.0]), 0.0)
    assert place.wall == "east"
    assert place.left.kind == "door edge" and place.left.distance == pytest.approx(0.9, abs=0.02)  # north = left
    assert place.right.kind == "corner" and place.right.distance == pytest.approx(0.6, abs=0.02)
    assert place.nearest[0] == "right"
    place = describe_tag(caster, np.array([5.0, 3.3, 1.5]), np.array([-1.0, 0.0, 0.0]), 0.0)
    side, end = place.nearest  # 0.9 m north of the door's north jamb at y = 2.4, 0.7 m from the corner
    assert side == "left" and end.kind == "corner" and end.distance == pytest.approx(0.7, abs=0.02)
    assert place.right.kind == "door edge" and place.right.distance == pytest.approx(0.9, abs=0.02)


def test_a_picture_does_not_end_the_wall_and_a_tilted_normal_is_fitted(caster):
    # on the picture (4 cm proud of the north wall), 1.6 m from the west corner; normal 4 deg off
    a = np.radians(-90 + 4)
    place = describe_tag(caster, np.array([1.6, 3.96, 1.5]), np.array([np.cos(a), np.sin(a), 0.0]), 0.0)
    assert place.wall == "north"
    assert place.left.kind == "corner" and place.left.distance == pytest.approx(1.6, abs=0.03)
    assert place.right.kind == "corner" and place.right.distance == pytest.approx(3.4, abs=0.03)
    assert abs(place.normal[1] + 1.0) < 1e-3  # the wall's own normal, not the given one


def test_height_is_above_the_floor_given_not_the_furniture():
    # a 0.75 m dining table against the south wall: the height is above the floor the plan gives
    table = box("table", (1.5, 0.0, 0.72), (3.5, 0.9, 0.75))
    rc = RayCaster(*room_scene([table]).geometry())
    place = describe_tag(rc, np.array([2.5, 0.0, 1.5]), np.array([0.0, 1.0, 0.0]), 0.0)
    assert place.floor_z == 0.0 and place.height == pytest.approx(1.5)
    stage = box("stage", (0, 0, 0), (5, 1.5, 0.2))  # a 0.2 m platform along the south wall: its floor is given
    rc = RayCaster(*room_scene([stage]).geometry())
    place = describe_tag(rc, np.array([2.5, 0.0, 1.7]), np.array([0.0, 1.0, 0.0]), 0.2)
    assert place.floor_z == pytest.approx(0.2) and place.height == pytest.approx(1.5)


def test_installer_camera_stays_in_free_space():
    shelf = box("shelf", (1.0, 1.0, 0), (3.0, 1.4, 2.0))  # 1 m in front of the south wall
    rc = RayCaster(*room_scene([shelf]).geometry())
    p, n = np.array([2.0, 0.0, 1.5]), np.array([0.0, 1.0, 0.0])
    assert standing_distance(rc, None, (0, 0), 0.1, p, n, 2.0) == pytest.approx(0.7)
    p = np.array([4.0, 0.0, 1.5])  # clear of the shelf: the full 2 m, unless the grid says occupied
    assert standing_distance(rc, None, (0, 0), 0.1, p, n, 2.0) == pytest.approx(2.0)
    occ = np.zeros((40, 50), np.int8)
    occ[15:, :] = 1  # y >= 1.5 occupied: step closer to 1.4 m
    assert standing_distance(rc, occ, (0, 0), 0.1, p, n, 2.0) == pytest.approx(1.4)


def test_gallery_selection():
    inf = np.inf
    t_plan = np.array([0.01, 0.02, 0.5, inf, 0.01])
    r_plan = np.array([1.0, 1.0, 1.0, inf, 1.0])
    t_none = np.array([0.5, inf, 0.01, 0.01, 0.02])
    r_none = np.array([1.0, inf, 1.0, 1.0, 1.0])
    fixed, broken = gallery_selection(t_plan, r_plan, t_none, r_none, (0.05, 5.0))
    assert fixed.tolist() == [1, 0]  # the failure without markers first
    assert broken.tolist() == [3, 2]
    fixed, _ = gallery_selection(t_plan, r_plan, t_none, r_none, (0.05, 5.0), limit=1)
    assert fixed.tolist() == [1]


def test_markdown_tables_become_html_tables():
    html = markdown_to_html("# Title\n\nSome *words* and **bold**.\n\n| a | b |\n|---|---|\n| 1 | `x` |\n| 2 | 3 |\n")
    assert "<h2>Title</h2>" in html and "<em>words</em>" in html and "<strong>bold</strong>" in html
    assert html.count("<tr>") == 3 and "<th>a</th>" in html and "<code>x</code>" in html


# ---------------------------------------------------------------- the pages in a browser

@pytest.fixture(scope="module")
def tiny_plan(run_plan):
    return run_plan(2, options=FAST, folder="plan_report")


def test_plan_report_in_browser(tiny_plan, browser):
    out = tiny_plan
    page = check_page(browser, out / "report.html")
    alts = page["images"]
    assert {"placement.png", "scores.png"} <= set(alts)
    assert sum("close view" in a for a in alts) == 2 and sum("wide view" in a for a in alts) == 2
    assert "Scores before and after" in page["text"] and "10th percentile" in page["text"]
    assert page["text"].count(" m above the floor (the middle of the black square") == 2
    assert re.search(r"\d\.\d\d m from the (corner|door edge|end of the wall) on the (left|right)", page["text"])
    assert "+x = east, +y = north" in page["text"]
    assert page["text"].count("On the wall (model part tiny/wall/") == 2  # what each tag is on


def test_plan_report_3d_view_opens_a_card(tiny_plan, browser):
    """The report's 3D view draws the plan's tags, numbered by placement order; a click on a tag
    (the camera turned to it) selects and scrolls to its card."""
    browser.get((tiny_plan / "report.html").resolve().as_uri())
    view = "mp-view3d"
    assert view_call(browser, view, "error") is None and view_call(browser, view, "frames") >= 1
    tags = view_call(browser, view, "projectedTags()")
    assert [(t["label"], t["card"]) for t in tags] == [("1", "tag1"), ("2", "tag2")]
    for i in range(2):
        view_call(browser, view, f"focusTag('planned', {i})")
        assert click_tag(browser, view, "planned", i) == [f"tag{i + 1}"]
        top, height = browser.execute_script(f"return [document.getElementById('tag{i + 1}').getBoundingClientRect()"
                                             ".top, window.innerHeight]")
        assert -2 <= top < height - 100  # scrolled to it


def test_reject_buttons_download_a_file_that_plan_exclude_accepts(tiny_plan, browser, tmp_path, capsys):
    """Reject tag #1, reject and un-reject #2: the download link holds #1's spot only, and a
    replan with it (from the cached stages) leaves that spot free."""
    import json
    import shutil
    from urllib.parse import unquote

    browser.get((tiny_plan / "report.html").resolve().as_uri())
    buttons = browser.find_elements("css selector", "button.mp-reject")
    assert len(buttons) == 2
    link = browser.find_element("id", "mp-rejected-download")
    assert link.get_attribute("aria-disabled") == "true"
    buttons[0].click()
    buttons[1].click()
    buttons[1].click()
    assert "Rejected" in buttons[0].text and buttons[1].text == "Reject this spot"
    assert browser.find_element("id", "mp-rejected-count").text == "1"
    href = link.get_attribute("href")
    assert href.startswith("data:application/json") and link.get_attribute("download") == "rejected.json"
    doc = json.loads(unquote(href.split(",", 1)[1]))
    first = json.loads((tiny_plan / "placement.json").read_text())["markers"][0]
    assert [s["order"] for s in doc["spots"]] == [1] and doc["scene"] == "tiny"
    assert [doc["spots"][0][k] for k in "xyz"] == pytest.approx(first["position"])
    rejected = tmp_path / "rejected.json"
    rejected.write_text(json.dumps(doc))
    replan = tmp_path / "replan"
    shutil.copytree(tiny_plan, replan)
    capsys.readouterr()
    assert main(["plan", "tiny", "-k", "2", "--out", str(replan), "--exclude", str(rejected), *FAST]) == 0
    assert "changes against the previous placement.json" in capsys.readouterr().out
    after = json.loads((replan / "placement.json").read_text())["markers"]
    assert all(np.linalg.norm(np.array(m["position"]) - first["position"]) > doc["spots"][0]["radius"] for m in after)


def test_evaluate_report_in_browser(tmp_path_factory, browser):
    out = tmp_path_factory.mktemp("eval_report")
    assert main(["evaluate", "tiny", "--out", str(out), "--tests", "12", "--test-sets", "weighted", "--runs", "1",
                 "--k", "2", "--methods", "none,omp", *FAST]) == 0
    page = check_page(browser, out / "report.html")
    assert "recall vs k" in page["images"]
    assert "All thresholds" in page["text"]
    # the gallery agrees with the stored per-query errors
    with np.load(out / "query_errors.npz") as z:
        methods, ks = list(z["weighted_method"]), list(z["weighted_k"])
        t, r = z["weighted_t_err"], z["weighted_r_err"]
    omp, none = methods.index("omp"), methods.index("none")
    assert ks[omp] == 2
    fixed, broken = gallery_selection(t[omp], r[omp], t[none], r[none], (0.05, 5.0), limit=10 ** 6)
    m = re.search(r"fixes (\d+) and breaks (\d+) of 12 test images", page["text"])
    assert m and (int(m.group(1)), int(m.group(2))) == (len(fixed), len(broken))
    shown = sorted(int(a.split()[-1]) for a in page["images"] if a.startswith("test image"))
    assert shown == sorted([*fixed[:6], *broken[:6]])
