"""oilspill_moos.messages: every mission message read back by its receiver's codec as the sender wrote it."""
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from shapely.geometry import Polygon

from behaviors.geometry import parse_seglist as helm_parse_seglist
from moosdb_py.formats import parse_pairs, parse_seglist
from oilspill_moos.messages import (Boundary, BoundaryError, Observation, ObservationRejected, boundary_line,
                                    coordinates_report, format_forecast, format_observation, format_request, parse_forecast,
                                    parse_boundary_line, parse_observation, parse_points_update,
                                    parse_polygon_string, parse_report, parse_request, points_update, polygon_string)

coord = st.floats(min_value=-1e5, max_value=1e5, allow_nan=False)
points = st.lists(st.tuples(coord, coord), min_size=3, max_size=20)
names = st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True)


def close(a, b, tol):
    return len(a) == len(b) and all(math.isclose(p, q, abs_tol=tol) for u, v in zip(a, b) for p, q in zip(u, v))


@given(points, st.floats(0, 48), st.floats(0, 1e4), st.floats(0, 2e9), names)
def test_boundary_line_round_trip(polygon, horizon, uncertainty, stamp, source):
    line = boundary_line(polygon, horizon, time=stamp, crs="local", uncertainty_m=uncertainty, source=source)
    back = parse_boundary_line(line.decode())
    assert close(back.polygon, polygon, 1e-9)
    assert (back.horizon_h, back.uncertainty_m, back.time, back.source) == (horizon, uncertainty, stamp, source)


def test_boundary_line_refuses_what_it_cannot_carry():
    with pytest.raises(ValueError, match="at least 3 vertices"):
        boundary_line([(0, 0), (1, 1)], 3)
    with pytest.raises(BoundaryError, match="expected a JSON object or pts="):
        parse_boundary_line("hello")


@given(st.lists(st.tuples(coord, coord), min_size=1, max_size=20), st.sampled_from([{}, {"repeat": "forever"},
                                                                                    {"repeat": "forever", "speed": 1.5}]))
def test_waypoint_updates_read_by_the_helm_as_written(route, extra):
    text = points_update(route, **extra)
    back, fields = parse_points_update(text)
    assert close(back, route, 0.051)
    assert fields == {k: (str(v) if isinstance(v, str) else f"{v:g}") for k, v in extra.items()}
    assert close(helm_parse_seglist(parse_pairs(text, sep="#")["points"]).tolist(), back, 1e-9)


def test_update_strings_keep_their_form():
    assert points_update([(0, 0), (400, 12.25)]) == "points=0.0,0.0:400.0,12.2"
    assert points_update([(1, 2)], repeat="forever", speed=2.0) == "points=1.0,2.0#repeat=forever#speed=2"


@given(points, names, st.sampled_from([{}, {"edge_color": "orange"}]))
def test_polygon_strings_round_trip(vertices, label, extra):
    back, fields = parse_polygon_string(polygon_string(vertices, label, **extra))
    assert close(back, vertices, 0.051) and fields == {"label": label, **extra}


def test_polygon_string_of_a_shapely_polygon_leaves_out_the_closing_vertex():
    assert polygon_string(Polygon([(0, 0), (4, 0), (0, 4)]), "a") == "pts={0.0,0.0:4.0,0.0:0.0,4.0},label=a"


@given(names, coord, coord, st.floats(0, 2e9))
def test_coordinates_report_round_trip(vname, x, y, utc):
    fields = parse_report(coordinates_report(vname, x, y, utc))
    assert fields["vname"] == vname and math.isclose(float(fields["x"]), x, abs_tol=0.006)
    assert math.isclose(float(fields["utc"]), utc, abs_tol=0.006) and math.isclose(float(fields["y"]), y, abs_tol=0.006)


@given(names, st.integers(0, 10**6), coord, coord)
def test_sensor_request_round_trip(vname, ident, x, y):
    back = parse_request(format_request(vname, ident, x, y))
    assert back[:2] == (vname, ident) and math.isclose(back[2], x, abs_tol=0.006) and math.isclose(back[3], y, abs_tol=0.006)


@given(names, st.integers(0, 10**6), st.floats(0, 2e9), coord, coord, st.booleans(), st.floats(0, 1e3),
       st.sampled_from(["", "sheen", "thick"]))
def test_observation_round_trip(vname, ident, utc, x, y, oil, range_m, thickness):
    obs = Observation(vname, ident, utc, x, y, oil, range_m, thickness)
    back = parse_observation(format_observation(obs))
    assert (back.vname, back.id, back.oil, back.thickness) == (vname, ident, oil, thickness)
    assert all(math.isclose(a, b, abs_tol=0.006) for a, b in ((back.utc, utc), (back.x, x), (back.y, y),
                                                               (back.range_m, range_m)))


@pytest.mark.parametrize("oil, value", [("1", True), ("0", False), ("true", True), ("off", False)])
def test_observation_flags_are_moos_booleans(oil, value):
    assert parse_observation(f"vname=abe,id=1,utc=1,x=2,y=3,oil={oil}").oil is value
    with pytest.raises(ObservationRejected, match="oil 0 or 1"):
        parse_observation("vname=abe,id=1,utc=1,x=2,y=3,oil=yes")


@given(points, st.integers(1, 99), st.floats(0, 48), st.floats(0, 1e4), names)
def test_forecast_post_reads_back(vertices, cycle, horizon, uncertainty, source):
    text = format_forecast(Boundary(tuple(vertices), 1.7e9, horizon, uncertainty, source), cycle)
    fields = parse_pairs(text)
    assert int(fields["cycle"]) == cycle and math.isclose(float(fields["horizon"]), horizon, abs_tol=6e-4)
    assert fields["source"] == source and close(parse_seglist(text), vertices, 0.051)
    boundary, read_cycle = parse_forecast(text)
    assert read_cycle == cycle and boundary.source == source and boundary.time == 1.7e9
    assert close(boundary.polygon, vertices, 0.051)


@pytest.mark.parametrize("text, says", [("horizon=3,pts={0,0:1,0:0,1}", "needs cycle="),
                                         ("cycle=1.5,horizon=3,pts={0,0:1,0:0,1}", "whole cycle"),
                                         ("cycle=1,horizon=3,valid=noon,pts={0,0:1,0:0,1}", "valid"),
                                         ("cycle=1,horizon=3,pts={0,0:1,0}", "3 points")])
def test_bad_forecast_posts_say_what_is_wrong(text, says):
    with pytest.raises(BoundaryError, match=says):
        parse_forecast(text)
