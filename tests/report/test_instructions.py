"""The installer's instructions hold: measured on hand-built rooms (corners behind furniture,
door edges, windows that are no reference), followed literally from placement.json and
placement.csv on a real plan (the tag lands where it was planned), labels of the installer
views that never overlap (read back from the drawn pixels), tags.pdf pages that name their tag
and tile (read with poppler's pdftotext), and the sheets it takes said before it is written."""

from __future__ import annotations

import csv
import json
import logging
import shutil
import subprocess

import numpy as np
import pytest

from helpers import FAST_2_YAWS as FAST
from helpers import negative_zeros
from markerplace.report.captions import describe_tag
from markerplace.scene.raycast import RayCaster
from markerplace.scene.types import MeshPart, Scene

T, H = 0.1, 2.7  # wall thickness, ceiling height


def box(name, lo, hi) -> MeshPart:
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], np.float32)
    f = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4], [1, 2, 6], [1, 6, 5],
                  [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]], np.int32)
    return MeshPart(name, v, f, base_color=(0.8, 0.8, 0.75, 1.0))


def furnished_room() -> Scene:
    """Inner faces x in [0, 6], y in [0, 4], ceiling 2.7 m. South wall: a 2.0 m bookcase (0.35 m
    deep) against it at x in [4.6, 5.4] and a sideboard (0.9 m high) at x in [0.3, 1.3]; a window
    hole at x in [2.0, 3.0], z in [1.0, 2.0] (a niche at tag height only). East wall: a 0.9 m door
    at y in [1.5, 2.4] (lintel at 2.1 m). North wall: a 1 m wide partition stub ends at x = 1.0
    (an outside corner), the wall beyond it set back 0.5 m."""
    parts = [box("floor", (-1, -1, -0.1), (7, 6, 0)), box("ceiling", (-1, -1, H), (7, 6, H + 0.1)),
             box("south_a", (-T, -T, 0), (2.0, 0, H)), box("south_b", (3.0, -T, 0), (6 + T, 0, H)),
             box("sill", (2.0, -T, 0), (3.0, 0, 1.0)), box("head", (2.0, -T, 2.0), (3.0, 0, H)),
             box("west", (-T, 0, 0), (0, 4.5, H)),
             box("east_a", (6, 0, 0), (6 + T, 1.5, H)), box("east_b", (6, 2.4, 0), (6 + T, 4.5, H)),
             box("lintel", (6, 1.5, 2.1), (6 + T, 2.4, H)),
             box("north_stub", (-T, 4.0, 0), (1.0, 4.5, H)), box("north", (-T, 4.5, 0), (6 + T, 4.5 + T, H)),
             box("bookcase", (4.6, 0.0, 0.0), (5.4, 0.35, 2.0)), box("sideboard", (0.3, 0.0, 0.0), (1.3, 0.45, 0.9))]
    return Scene("furnished_room", tuple(parts), (), 0.0)


@pytest.fixture(scope="module")
def caster():
    return RayCaster(*furnished_room().geometry())


def test_a_corner_behind_furniture_is_measured_along_the_wall(caster):
    # south wall, faces north; centre at x = 3.6: right (west) runs over the window niche and the
    # sideboard to the west wall; left (east) passes behind the 2 m bookcase to the east wall
    place = describe_tag(caster, np.array([3.6, 0.0, 1.5]), np.array([0.0, 1.0, 0.0]), 0.0)
    assert place.wall == "south" and place.facing == "north (+y)"
    assert place.right.kind == "corner" and place.right.distance == pytest.approx(3.6, abs=0.02)
    assert place.left.kind == "corner" and place.left.distance == pytest.approx(2.4, abs=0.02)
    assert place.height == pytest.approx(1.5)


def test_door_edge_and_outside_corner(caster):
    # east wall, faces west, 0.5 m south of the door's south jamb (y = 1.5)
    place = describe_tag(caster, np.array([6.0, 1.0, 1.5]), np.array([-1.0, 0.0, 0.0]), 0.0)
    assert place.left.kind == "door edge" and place.left.distance == pytest.approx(0.5, abs=0.01)
    # the stub's face (y = 4.0), faces south: facing it, on the left (west) the west wall, on the
    # right (east) the stub ends at x = 1.0: an outside corner, the end of the wall
    place = describe_tag(caster, np.array([0.6, 4.0, 1.5]), np.array([0.0, -1.0, 0.0]), 0.0)
    assert place.wall == "north"
    assert place.right.kind == "wall end" and place.right.distance == pytest.approx(0.4, abs=0.01)
    assert place.left.kind == "corner" and place.left.distance == pytest.approx(0.6, abs=0.01)


def test_install_object_hangs_the_tag_where_it_was_measured(caster):
    """Follow an install object literally: from the named reference, the distance along the wall,
    at the height above the floor: the tag centre it names is the measured one."""
    from markerplace.geometry import world_from_marker_pose
    from markerplace.markers import Marker
    from markerplace.report.instructions import install_instructions

    scene = furnished_room()
    tags = [(np.array([3.6, 0.0, 1.5]), np.array([0.0, 1.0, 0.0])), (np.array([6.0, 1.0, 1.5]), np.array([-1.0, 0, 0])),
            (np.array([0.6, 4.0, 1.5]), np.array([0.0, -1.0, 0.0]))]
    markers = [Marker(i, 0.2, world_from_marker_pose(p, n)) for i, (p, n) in enumerate(tags)]
    installs = install_instructions(scene, markers, [0] * 3, [0.0] * 3, [0.0] * 3, caster=caster)
    for (p, n), inst in zip(tags, installs):
        for side, sign in (("left", 1.0), ("right", -1.0)):
            ref = inst[side]
            if ref["distance_m"] is None:
                continue
            centre = np.array(ref["point"][:2]) + sign * ref["distance_m"] * np.array(inst["right_dir"][:2])
            assert np.allclose(centre, p[:2], atol=0.005), (side, inst)
        assert inst["floor_z"] + inst["height_m"] == pytest.approx(p[2])
        assert np.allclose(inst["wall_normal"], n, atol=1e-6) and inst["edge_down"] == "caption"
    assert [i["wall"] for i in installs] == ["south", "east", "north"]
    assert [i["facing"] for i in installs] == ["north", "west", "south"]


def test_installer_view_labels_never_overlap(caster):
    """Tags near corners (the along-the-wall label used to hide under the height label): every
    label is inside the image, clear of the others and of the tag, and really drawn there
    (white box with coloured text in the rendered pixels)."""
    from markerplace.geometry import world_from_marker_pose
    from markerplace.markers import Marker
    from markerplace.report.installer import render_installer_views

    scene = furnished_room()
    tags = [(np.array([0.0, 3.7, 1.5]), np.array([1.0, 0.0, 0.0])),  # 0.3 m from the stub's corner
            (np.array([5.75, 4.5, 1.5]), np.array([0.0, -1.0, 0.0])),  # 0.25 m from the north-east corner
            (np.array([6.0, 1.2, 1.5]), np.array([-1.0, 0.0, 0.0]))]  # 0.3 m from the door edge
    markers = [Marker(i, 0.2, world_from_marker_pose(p, n)) for i, (p, n) in enumerate(tags)]
    places = [describe_tag(caster, p, n, 0.0) for p, n in tags]
    views = render_installer_views(scene, markers, places, caster, lambda i: None, (0, 0), 0.1,
                                   [f"#{i + 1} id {i}" for i in range(3)])
    for v in views:
        for img, labels, n_expected in ((v.close, v.close_labels, 1), (v.wide, v.wide_labels, 3)):
            assert len(labels) == n_expected, labels
            boxes = [lab.box for lab in labels]
            for k, (x0, y0, x1, y1) in enumerate(boxes):
                assert 0 <= x0 < x1 <= img.shape[1] and 0 <= y0 < y1 <= img.shape[0]
                for a0, b0, a1, b1 in boxes[k + 1:]:
                    assert x1 <= a0 or a1 <= x0 or y1 <= b0 or b1 <= y0, (labels, "overlap")
                patch = img[y0:y1, x0:x1].astype(int)
                white = (patch.min(axis=2) >= 250).mean()
                coloured = ((patch.max(axis=2) - patch.min(axis=2)) > 100).mean()
                assert white > 0.4 and coloured > 0.05, (labels[k].text, white, coloured)
        assert any("m to the" in lab.text for lab in v.wide_labels)


# ---------------------------------------------------------------- a real plan, followed literally

@pytest.fixture(scope="module")
def room_plan(run_plan):
    return run_plan(4, scene="room", options=FAST, folder="instructions")


def test_placement_csv_is_a_checklist_that_matches_placement_json(room_plan):
    from markerplace.report.instructions import CHECKLIST_COLUMNS

    doc = json.loads((room_plan / "placement.json").read_text())
    rows = list(csv.DictReader((room_plan / "placement.csv").open()))
    assert list(rows[0]) == CHECKLIST_COLUMNS and "centre_height_above_floor_m" in rows[0]
    page = 1
    for r, m in zip(rows, doc["markers"]):
        inst = m["install"]
        assert int(r["order"]) == m["order"] and int(r["tag_id"]) == m["tag_id"] and int(r["storey"]) == 0
        assert float(r["centre_height_above_floor_m"]) == pytest.approx(1.5)  # the plan's eye level, never furniture
        assert r["wall"] in ("north", "south", "east", "west") and r["faces"] != r["wall"]
        for side in ("left", "right"):
            assert r[f"{side}_reference"] == inst[side]["reference"] in ("corner", "door edge", "wall end")
            assert float(r[f"{side}_reference_to_centre_m"]) == pytest.approx(inst[side]["distance_m"], abs=5e-4)
        assert inst["pages"] == list(range(page, page + 13)) and inst["tiles"] == [3, 4]  # 0.4 m on A4
        assert r["tags_pdf_pages"] == f"{page}-{page + 12}"
        page += 13
        # followed literally: the nearer reference, the distance along the wall, the height
        side = inst["measure_from"]
        ref = inst[side]
        centre = np.array(ref["point"][:2]) + (1 if side == "left" else -1) * ref["distance_m"] * np.array(inst["right_dir"][:2])
        hung = np.array([*centre, inst["floor_z"] + inst["height_m"]])
        assert np.linalg.norm(hung - np.array(m["position"])) < 0.01, (hung, m["position"])
        assert np.dot(inst["wall_normal"], m["normal"]) > 0.999


def test_the_reference_is_real_geometry(room_plan):
    """Each named corner is a real corner of the room model: a wall crosses the tag's wall there
    (a ray from just in front of the reference, along the wall away from the tag, stops at once)."""
    from markerplace.scene import load_scene

    rc = RayCaster(*load_scene("room").geometry())
    for m in json.loads((room_plan / "placement.json").read_text())["markers"]:
        inst = m["install"]
        for side, away in (("left", -1.0), ("right", 1.0)):
            ref = inst[side]
            if ref["reference"] != "corner":
                continue
            o = np.array(ref["point"]) + 0.05 * np.array(inst["wall_normal"]) - away * 0.02 * np.array(inst["right_dir"])
            t, _ = rc.first_hits(o[None], (away * np.array(inst["right_dir"]))[None], max_t=1.0)
            assert t[0] < 0.05, (m["order"], side, t[0])


def test_every_tags_pdf_page_names_its_tag_and_tile(room_plan):
    assert shutil.which("pdftotext"), "pdftotext missing: scripts/setup.sh installs poppler-utils"
    doc = json.loads((room_plan / "placement.json").read_text())
    pdf = room_plan / "tags.pdf"
    for m in doc["markers"]:
        rows, cols = m["install"]["tiles"]
        for k, page in enumerate(m["install"]["pages"]):
            text = subprocess.run(["pdftotext", "-f", str(page), "-l", str(page), "-layout", str(pdf), "-"],
                                  check=True, capture_output=True, text=True).stdout
            assert f"tag #{m['order']}, id {m['tag_id']}" in text, (page, text)
            if k == 0:
                assert "Page map" in text and f"{rows} x {cols} tiles" in text and "this edge down" in text
            else:
                r, c = divmod(k - 1, cols)
                assert f"row {r + 1} of {rows}, column {c + 1} of {cols}" in text, (page, text)
                assert ("this edge down" in text) == (r == rows - 1)


def test_sheets_are_said_before_writing_and_a_warning_offers_alternatives(tmp_path, caplog):
    from markerplace.report.pdf import write_tags_pdf
    from markerplace.report.sheets import sheet_advice, sheet_plan

    rec = {"order": 1, "tag_id": 3, "family": "tag36h11", "size": 0.4, "position": [1.0, 2.0, 1.5], "yaw_deg": 90.0}
    recs = [{**rec, "order": i + 1, "tag_id": i} for i in range(20)]
    plan = sheet_plan(recs, "a4")
    assert [t.count for t in plan] == [13] * 20 and plan[-1].pages[-1] == 260
    summary, warning = sheet_advice(recs, "a4")
    assert "13 A4 sheets (a page map and 3 x 4 tiles to tape) each; 260 sheet(s) in all" in summary
    assert "--paper a3 (7 sheets per tag, 140 in all)" in warning and "--paper none" in warning
    assert "--tag-size" in warning and "detection range" in warning
    assert sheet_advice([{**rec, "size": 0.1}], "a4")[1] is None  # one sheet: no warning
    assert sheet_advice(recs[:1], "none")[1] is None
    with caplog.at_level(logging.INFO, logger="markerplace.report.pdf"):
        assert write_tags_pdf(tmp_path / "t.pdf", recs[:2], "a4") == 26
    assert "26 sheet(s) in all" in caplog.text and "fewer sheets" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="markerplace"):  # --quiet: advice, not a warning (issue 50)
        write_tags_pdf(tmp_path / "t.pdf", recs[:2], "a4")
    assert "fewer sheets" not in caplog.text


def floats_in(obj):
    if isinstance(obj, float):
        yield obj
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from floats_in(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from floats_in(v)


def test_every_json_of_the_plan_has_clean_numbers(room_plan):
    """No -0.0 in any JSON file of the run, and no float with more than 12 significant digits
    (binary noise such as 11.100000000000001) but in the tag maps (exact on purpose: robots read
    them back to the last bit)."""
    import math

    files = sorted(room_plan.glob("*.json")) + sorted(room_plan.glob("tagmaps/*.json"))
    assert {p.name for p in files} >= {"placement.json", "config.json", "discretization.npz.meta.json",
                                       "wpilib_field_layout.json"}
    for path in files:
        if path.name.startswith("."):  # the run folder's own marker and manifest
            continue
        values = list(floats_in(json.loads(path.read_text())))
        assert values or path.name.endswith("meta.json")
        for v in values:
            assert not (v == 0 and math.copysign(1.0, v) < 0), (path.name, "-0.0")
            assert path.parent.name == "tagmaps" or not math.isfinite(v) or float(f"{v:.12g}") == v, (path.name, v)
    for path in room_plan.glob("tagmaps/*.yaml"):
        assert not negative_zeros(path.read_text()), path.name
