"""``--where`` files (markerplace.plan.where): every error path of the parser, and the weights of
zones, routes (with and without heading) and listed poses on a tiny hand-made set of poses."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from markerplace.errors import UserError
from markerplace.plan.where import disc_pose_weights, load_where, parse_where, pose_weights, raw_pose_weights


def feature(geometry: str, coordinates, **properties) -> dict:
    return {"type": "Feature", "properties": properties, "geometry": {"type": geometry, "coordinates": coordinates}}


def collection(*features, **top) -> dict:
    return {"type": "FeatureCollection", "features": list(features), **top}


SQUARE = [[[0, 0], [2, 0], [2, 2], [0, 2], [0, 0]]]
ROUTE = [[0, 5], [10, 5]]


def grid_poses():
    """Poses on a 1 m lattice x, y in 0.5..9.5 with 4 yaws (0, 90, 180, 270 deg), all on storey
    0 at z = 1.5: (N, 3) positions, (N,) yaws, (N,) storeys."""
    xs = np.arange(0.5, 10.0, 1.0)
    xy = np.array([(x, y) for x in xs for y in xs])
    yaws = np.radians([0.0, 90.0, 180.0, 270.0])
    xyz = np.repeat(np.column_stack([xy, np.full(len(xy), 1.5)]), 4, axis=0)
    return xyz, np.tile(yaws, len(xy)), np.zeros(len(xyz), int)


@pytest.mark.parametrize("doc, words", [
    ([], "FeatureCollection"),
    ({"type": "Feature"}, "FeatureCollection"),
    (collection(), "non-empty list"),
    (collection(feature("Point", [1, 1]), default_wieght=1), "unknown key(s) 'default_wieght'"),
    (collection({"type": "Thing"}), '"type": "Feature"'),
    (collection({**feature("Point", [1, 1]), "extra": 1}), "unknown key(s) 'extra'"),
    (collection({"type": "Feature", "properties": [], "geometry": {"type": "Point", "coordinates": [1, 1]}}),
     '"properties" must be a JSON object'),
    (collection(feature("MultiPolygon", [])), "geometry 'MultiPolygon' is not one of"),
    (collection({"type": "Feature", "properties": {}}), "geometry None is not one of"),
    (collection(feature("Polygon", [[[0, 0], [1, 0], [0, 0]]])), "2 distinct position(s); it needs at least 3"),
    (collection(feature("Polygon", [])), "list of rings"),
    (collection(feature("Polygon", "square")), "list of rings"),
    (collection(feature("Polygon", [[[0, 0], [1, "a"], [1, 1]]])), "y must be a finite number"),
    (collection(feature("Polygon", [[[0, 0], [1], [1, 1]]])), "must be a position [x, y]"),
    (collection(feature("Polygon", SQUARE, weight=-1)), "weight = -1 must be at least 0"),
    (collection(feature("Polygon", SQUARE, weight="high")), "weight must be a finite number"),
    (collection(feature("Polygon", SQUARE, weight=True)), "weight must be a finite number"),
    (collection(feature("Polygon", SQUARE, width=1)), "Polygon has unknown properties 'width'"),
    (collection(feature("LineString", ROUTE)), "needs a width property"),
    (collection(feature("LineString", ROUTE, width=0)), "width = 0 must be above 0"),
    (collection(feature("LineString", ROUTE, width=-2)), "width = -2 must be above 0"),
    (collection(feature("LineString", [[0, 5]], width=1)), "1 distinct position(s); it needs at least 2"),
    (collection(feature("LineString", ROUTE, width=1, heading="backwards")), "heading 'backwards' is not one of"),
    (collection(feature("LineString", ROUTE, width=1, heading_tolerance_deg=0)), "heading_tolerance_deg = 0"),
    (collection(feature("Point", [1])), "must be a position [x, y]"),
    (collection(feature("Point", [1, 1], radius=0)), "radius = 0 must be above 0"),
    (collection(feature("Point", [1, 1], yaw_deg=[])), "yaw_deg is an empty list"),
    (collection(feature("Point", [1, 1], yaw_deg="north")), "yaw_deg must be a finite number"),
    (collection(feature("Point", [1, 1], storey=-1)), "storey must be a storey index"),
    (collection(feature("Point", [1, 1], storey=1.5)), "storey must be a storey index"),
    (collection(feature("Point", [1, 1], z="high")), "z must be a finite number"),
    (collection(feature("Point", [1e9, 1])), "is not a value in metres"),
    (collection(feature("Point", [1, 1]), default_weight=-0.5), "default_weight = -0.5 must be at least 0"),
    (collection(feature("Point", [1, 1], weight=0)), "every weight is 0"),
])
def test_every_malformed_file_is_one_line(doc, words):
    with pytest.raises(UserError) as err:
        parse_where(doc, "--where w.json")
    text = str(err.value)
    assert words in text and "\n" not in text and text.startswith("--where w.json")


def test_files_not_json_or_missing(tmp_path):
    with pytest.raises(UserError, match="no such file"):
        load_where(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(UserError) as err:
        load_where(bad)
    assert "--where" in str(err.value) and "\n" not in str(err.value)
    good = tmp_path / "good.json"
    good.write_text(json.dumps(collection(feature("Point", [1, 1], name="desk"))))
    where = load_where(good)
    assert len(where.features) == 1 and where.doc["features"][0]["properties"]["name"] == "desk"


def test_nothing_inside_says_where_the_poses_are():
    xyz, yaw, storey = grid_poses()
    far = parse_where(collection(feature("Polygon", [[[100, 100], [101, 100], [101, 101]]])))
    with pytest.raises(UserError) as err:
        pose_weights(far, xyz, yaw, storey)
    text = str(err.value)
    assert "no camera pose" in text and "x 0.50..9.50" in text and "model's frame" in text and "\n" not in text
    upstairs = parse_where(collection(feature("Polygon", SQUARE, storey=1)))
    with pytest.raises(UserError, match="no camera pose"):
        pose_weights(upstairs, xyz, yaw, storey)


def test_zone_weights_and_scaling():
    xyz, yaw, storey = grid_poses()
    where = parse_where(collection(feature("Polygon", SQUARE, weight=2)))
    raw = raw_pose_weights(where, xyz, yaw, storey)
    inside = (xyz[:, 0] < 2) & (xyz[:, 1] < 2)
    assert inside.sum() == 16  # 4 locations x 4 yaws
    np.testing.assert_array_equal(raw, np.where(inside, 2.0, 0.0))
    w = pose_weights(where, xyz, yaw, storey)
    assert w.sum() == pytest.approx(len(w)) and np.all(w[~inside] == 0) and np.allclose(w[inside], len(w) / 16)


def test_largest_weight_wins_holes_and_default():
    xyz, yaw, storey = grid_poses()
    big = [[[0, 0], [10, 0], [10, 10], [0, 10]]]
    hole = [[[4, 4], [6, 4], [6, 6], [4, 6]]]
    doc = collection(feature("Polygon", big, weight=1), feature("Polygon", SQUARE, weight=3),
                     feature("Polygon", [big[0], hole[0]], weight=5, storey=0), default_weight=0.25)
    raw = raw_pose_weights(parse_where(doc), xyz, yaw, storey)
    in_hole = (np.abs(xyz[:, 0] - 5) < 1) & (np.abs(xyz[:, 1] - 5) < 1)
    assert np.all(raw[in_hole] == 1.0)  # the 5-zone has a hole there; the 1-zone holds
    assert np.all(raw[~in_hole] == 5.0)  # max, not sum (3 < 5 in the corner square)
    outside = parse_where(collection(feature("Polygon", SQUARE, weight=3), default_weight=0.25))
    r2 = raw_pose_weights(outside, xyz, yaw, storey)
    assert set(np.unique(r2)) == {0.25, 3.0}
    zero_zone = parse_where(collection(feature("Polygon", SQUARE, weight=0), default_weight=1))
    assert np.all(raw_pose_weights(zero_zone, xyz, yaw, storey)[(xyz[:, 0] < 2) & (xyz[:, 1] < 2)] == 0)


def test_route_without_and_with_heading():
    xyz, yaw, storey = grid_poses()
    near = np.abs(xyz[:, 1] - 5) <= 0.75  # y = 4.5 and 5.5: within 1.5/2 of y = 5
    any_yaw = raw_pose_weights(parse_where(collection(feature("LineString", ROUTE, width=1.5))), xyz, yaw, storey)
    np.testing.assert_array_equal(any_yaw > 0, near)
    along = raw_pose_weights(parse_where(collection(feature("LineString", ROUTE, width=1.5, heading="along"))),
                             xyz, yaw, storey)
    east_west = np.isclose(np.cos(yaw) ** 2, 1.0)
    np.testing.assert_array_equal(along > 0, near & east_west)
    forward = raw_pose_weights(parse_where(collection(feature("LineString", [[10, 5], [0, 5]], width=1.5,
                                                              heading="forward"))), xyz, yaw, storey)
    np.testing.assert_array_equal(forward > 0, near & np.isclose(np.cos(yaw), -1.0))  # looking -x
    wide = raw_pose_weights(parse_where(collection(feature("LineString", ROUTE, width=1.5, heading="forward",
                                                           heading_tolerance_deg=90))), xyz, yaw, storey)
    np.testing.assert_array_equal(wide > 0, near & (np.cos(yaw) > -0.5))  # 0, 90 and 270 deg


def test_route_heading_follows_each_segment():
    xyz, yaw, storey = grid_poses()
    bend = [[0.5, 0.5], [0.5, 9.5], [9.5, 9.5]]  # north along x = 0.5, then east along y = 9.5
    w = raw_pose_weights(parse_where(collection(feature("LineString", bend, width=0.5, heading="forward"))),
                         xyz, yaw, storey)
    on_west = np.isclose(xyz[:, 0], 0.5) & (xyz[:, 1] < 9)
    on_north = np.isclose(xyz[:, 1], 9.5) & (xyz[:, 0] > 1)
    assert np.all(w[on_west & np.isclose(yaw, math.pi / 2)] == 1) and np.all(w[on_west & np.isclose(yaw, 0)] == 0)
    assert np.all(w[on_north & np.isclose(yaw, 0)] == 1) and np.all(w[on_north & np.isclose(yaw, math.pi / 2)] == 0)


def test_listed_poses_radius_yaw_and_storey():
    xyz, yaw, storey = grid_poses()
    storey[xyz[:, 0] > 5] = 1
    doc = collection(feature("Point", [2.5, 2.5], radius=0.3, yaw_deg=90, weight=4),
                     feature("Point", [7.5, 7.5], radius=1.1, yaw_deg=[0, 180], storey=1),
                     feature("Point", [7.5, 2.5, 9.0], storey=0))  # storey 0 holds nothing at x > 5
    raw = raw_pose_weights(parse_where(doc), xyz, yaw, storey)
    at = lambda x, y: np.isclose(xyz[:, 0], x) & np.isclose(xyz[:, 1], y)  # noqa: E731
    np.testing.assert_array_equal(raw[at(2.5, 2.5)], [0, 4, 0, 0])
    second = (np.hypot(xyz[:, 0] - 7.5, xyz[:, 1] - 7.5) <= 1.1) & np.isclose(np.cos(yaw) ** 2, 1.0)
    assert np.count_nonzero(raw == 1.0) == np.count_nonzero(second) == 5 * 2
    assert np.all(raw[at(7.5, 2.5)] == 0)
    by_z = parse_where(collection(feature("Point", [2.5, 2.5], z=2.4), feature("Point", [3.5, 2.5], z=2.6)))
    raw_z = raw_pose_weights(by_z, xyz, yaw, storey)
    assert np.all(raw_z[at(2.5, 2.5)] == 1) and np.all(raw_z[at(3.5, 2.5)] == 0)  # camera at 1.5 m, 1 m tolerance


def test_disc_weights_move_into_the_user_frame():
    """A discretization's poses are in the internal frame; the file is in the user's."""
    from types import SimpleNamespace

    from markerplace.geometry import world_from_cam_poses

    xyz, yaw, storey = grid_poses()
    locations = xyz[::4]
    disc = SimpleNamespace(world_from_cam=world_from_cam_poses(xyz, yaw), location_index=np.repeat(
        np.arange(len(locations)), 4), location_storey=np.zeros(len(locations), int))
    where = parse_where(collection(feature("Polygon", [[[100, 100], [102, 100], [102, 102], [100, 102]]])))
    w = disc_pose_weights(where, disc, offset=np.array([100.0, 100.0, 0.0]))
    np.testing.assert_array_equal(w > 0, (xyz[:, 0] < 2) & (xyz[:, 1] < 2))
    along = parse_where(collection(feature("LineString", ROUTE, width=1.5, heading="forward")))
    w = disc_pose_weights(along, disc)
    np.testing.assert_array_equal(w > 0, (np.abs(xyz[:, 1] - 5) <= 0.75) & np.isclose(yaw, 0))
