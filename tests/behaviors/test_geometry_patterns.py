"""Every generated seglist and polygon format of MOOS-IvP's geometry library against hand-computed
points (x east, y north; compass angles clockwise from north)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from behaviors.behavior import InfoBuffer
from behaviors.bhv_waypoint import BHV_Waypoint
from behaviors.geometry import GeometryError, are_floats, bearing, distance, parse_polygon, parse_seglist

R = math.sqrt(0.5) * 10     # 10 m at 45 degrees: 7.0711 along each axis


def same(got, expected):
    assert np.asarray(got) == pytest.approx(np.array(expected, dtype=float), abs=1e-6)


@pytest.mark.parametrize("text, expected", [
    # rows=ns, degs=90: lanes run east-west (along 90), 3 lanes 10 m apart north to south about 0,0
    ("format=lawnmower, x=0, y=0, width=20, height=10, swath=10, rows=ns, degs=90",
     [[5, 10], [-5, 10], [-5, 0], [5, 0], [5, -10], [-5, -10]]),
    # entry nearest startx,starty: the south-east lane end, so the lanes are flown south to north
    ("format=lawnmower, x=0, y=0, width=20, height=10, swath=10, rows=ns, degs=90, startx=100, starty=-100",
     [[5, -10], [-5, -10], [-5, 0], [5, 0], [5, 10], [-5, 10]]),
    ("format=lawnmower, x=0, y=0, width=20, height=10, swath=10, rows=ns, degs=90, startx=-100, starty=-100",
     [[-5, -10], [5, -10], [5, 0], [-5, 0], [-5, 10], [5, 10]]),
    # 25/10 + 1 = 3.5 lanes round up to 4, the last one past the block's edge (as MOOS-IvP); lane_width alias
    ("lawnmower: x=0, y=0, width=25, height=10, lane_width=10, rows=north-south",
     [[-12.5, 5], [-12.5, -5], [-2.5, -5], [-2.5, 5], [7.5, 5], [7.5, -5], [17.5, -5], [17.5, 5]]),
    # the default rows=ew: width and height swap and the lanes turn 90 degrees; entry nearest 0,0
    ("x=100, y=50, width=20, height=10, swath=10, format=lawnmower",
     [[90, 45], [110, 45], [110, 55], [90, 55]]),
    # centred 0.3 m east: the west ends are nearer 0,0, then snapped to whole metres
    ("format=lawnmower, x=0.3, y=0, width=20, height=10, swath=10, rows=ns, degs=90, snap=1",
     [[-5, 10], [5, 10], [5, 0], [-5, 0], [-5, -10], [5, -10]]),
])
def test_lawnmower(text, expected):
    same(parse_seglist(text), expected)


BOWTIE = "format=bowtie, x=0, y=0, height=100, wid1=10, wid2=25, wid3=30"
TOP_LEFT, TOP_MID_L, TOP_MID_R, TOP_RIGHT = (-25, 50), (-10, 50), (10, 50), (25, 50)
WAIST_L, WAIST_R = (-30, 0), (30, 0)
BOT_LEFT, BOT_MID_L, BOT_MID_R, BOT_RIGHT = (-25, -50), (-10, -50), (10, -50), (25, -50)


@pytest.mark.parametrize("start, expected", [
    ("", [BOT_MID_L, BOT_LEFT, WAIST_L, TOP_LEFT, TOP_MID_L, BOT_MID_R, BOT_RIGHT, WAIST_R, TOP_RIGHT, TOP_MID_R]),
    (", startx=50, starty=-50",    # bearing 135: south-east
     [TOP_MID_L, TOP_LEFT, WAIST_L, BOT_LEFT, BOT_MID_L, TOP_MID_R, TOP_RIGHT, WAIST_R, BOT_RIGHT, BOT_MID_R]),
    (", startx=-50, starty=-50",   # 225: south-west
     [TOP_MID_R, TOP_RIGHT, WAIST_R, BOT_RIGHT, BOT_MID_R, TOP_MID_L, TOP_LEFT, WAIST_L, BOT_LEFT, BOT_MID_L]),
    (", startx=-50, starty=50",    # 315: north-west
     [BOT_MID_R, BOT_RIGHT, WAIST_R, TOP_RIGHT, TOP_MID_R, BOT_MID_L, BOT_LEFT, WAIST_L, TOP_LEFT, TOP_MID_L]),
])
def test_bowtie(start, expected):
    same(parse_seglist(BOWTIE + start), expected)


def test_zigzag():
    # east from 0,0, period 40, amplitude 10: axis points at 10, 30, 50, 70, 90 m, left (north) first
    same(parse_seglist("zigzag: 0, 0, 90, 100, 40, 10"), [[0, 0], [10, 10], [30, -10], [50, 10], [70, -10], [90, 10]])
    same(parse_seglist("zigzag:5,5,0,30,20,4,1"), [[5, 5], [1, 10], [9, 20], [1, 30]])     # north, snap 1
    with pytest.raises(GeometryError, match="zigzag needs"):
        parse_seglist("zigzag:0,0,90,100,40")


@pytest.mark.parametrize("text, expected", [
    ("format=radial, x=10, y=20, radius=10, pts=4", [[10 + R, 20 + R], [10 + R, 20 - R], [10 - R, 20 - R],
                                                     [10 - R, 20 + R]]),
    ("radial:: x=0, y=0, radius=10, pts=4, shiftx=100", [[100 + R, R], [100 + R, -R], [100 - R, -R], [100 - R, R]]),
    ("radial: 0, 0, 10, 4, 5", [[5, 5], [5, -5], [-5, -5], [-5, 5]]),          # snapped to 5 m
    ("format=ellipse, x=0, y=0, major=20, minor=10, degs=0, pts=4", [[-10, 0], [0, -5], [10, 0], [0, 5]]),
    ("ellipse: x=0, y=0, major=20, minor=10, degs=90, pts=4", [[0, -10], [5, 0], [0, 10], [-5, 0]]),
    ("format=ellipse, x=1, y=1, major=20, minor=10, rads=0, pts=4", [[-9, 1], [1, -4], [11, 1], [1, 6]]),
    ("format=wedge, x=0, y=0, lang=0, rang=90, range=10, pts=2", [[0, 0], [0, 10], [R, R], [10, 0]]),
    ("piewedge: x=0, y=0, lang=315, rang=45, range=10, pts=2", [[0, 0], [-R, R], [0, 10], [R, R]]),
    ("format=rangewedge, x=0, y=0, lang=0, rang=90, range_min=5, range_max=10, pts=1",
     [[0, 10], [10, 0], [5, 0], [0, 5]]),
    ("format=pylon, x1=0, y1=0, x2=0, y2=10, axis_pad=2, perp_pad=3", [[-3, -2], [3, -2], [3, 12], [-3, 12]]),
    ("pylon: x1=0, y1=0, x2=10, y2=0, axis_pad=1, perp_pad=2", [[-1, 2], [-1, -2], [11, -2], [11, 2]]),
    ("pts={0,0:0,10:10,10:10,0},label=box", [[0, 0], [0, 10], [10, 10], [10, 0]]),
])
def test_polygon_formats(text, expected):
    same(parse_polygon(text), expected)


@pytest.mark.parametrize("text, message", [
    ("format=ellipse, x=0, y=0, major=20, minor=10, pts=8", "degs or rads"),
    ("format=ellipse, x=0, y=0, major=20, minor=10, degs=0, pts=3", "pts >= 4"),
    ("format=rangewedge, x=0, y=0, lang=0, rang=90, range_min=10, range_max=5", "range_min < range_max"),
    ("format=wedge, x=0, y=0, lang=0, rang=90", "wedge needs range"),
    ("format=hexagon, x=0, y=0, rad=5, pts=6", "unsupported polygon format 'hexagon'"),
    ("format=oval, x=0, y=0, rad=5", "oval needs len"),
    ("oval: rad=5, len=10", r"oval needs rad > 0 and len > 2 \* rad"),
    ("format=pylon, x1=0, y1=0, x2=0, y2=10, axis_pad=2", "pylon needs perp_pad"),
])
def test_polygon_format_errors(text, message):
    with pytest.raises(GeometryError, match=message):
        parse_polygon(text)


def test_waypoint_points_and_polygon_take_the_patterns(domain):
    wpt = BHV_Waypoint(domain, InfoBuffer())
    wpt.apply("points", "format=bowtie, x=0, y=0, height=100, wid1=10, wid2=25, wid3=30")
    assert len(wpt.points) == 10 and tuple(wpt.points[0]) == BOT_MID_L
    wpt.apply("polygon", "format=ellipse, x=0, y=0, major=20, minor=10, degs=0, pts=4")
    same(wpt.points, [[0, -5], [10, 0], [0, 5], [-10, 0]])      # ownship unknown: entered nearest 0,0


# Hand-computed: rad 5, len 20 gives end centres 5 m either side of the centre along `ang`; each end
# is a half circle of 13 vertices at 15-degree steps, from 90 left of the outward axis to 90 right.
S75, C75 = 5 * math.sin(math.radians(75)), 5 * math.cos(math.radians(75))


@pytest.mark.parametrize("text, picks", [
    ("format=oval, x=0, y=0, rad=5, len=20", {0: (-5, 5), 1: (-S75, 5 + C75), 6: (0, 10), 12: (5, 5),
                                               13: (5, -5), 19: (0, -10), 25: (-5, -5)}),
    ("oval: x=10, y=20, rad=5, len=20, ang=90, draw_degs=5, label=o",
     {0: (15, 25), 6: (20, 20), 12: (15, 15), 13: (5, 15), 19: (0, 20), 25: (5, 25)}),
])
def test_oval(text, picks):
    pts = parse_polygon(text)
    assert pts.shape == (26, 2)
    same(pts[list(picks)], list(picks.values()))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-1e5, 1e5), min_size=4, max_size=4))
def test_single_bearings_and_distances_agree_with_the_array_forms(xy):
    """Four floats take plain math, arrays numpy: the same bearing and distance to rounding."""
    x1, y1, x2, y2 = xy
    as_arrays = [np.array([v]) for v in xy]
    assert distance(x1, y1, x2, y2) == pytest.approx(float(distance(*as_arrays)[0]), rel=1e-12, abs=1e-9)
    assert 0.0 <= bearing(x1, y1, x2, y2) <= 360.0
    turn = (bearing(x1, y1, x2, y2) - float(bearing(*as_arrays)[0]) + 180.0) % 360.0 - 180.0
    assert turn == pytest.approx(0.0, abs=1e-9)


SCALARS = st.one_of(st.floats(allow_nan=False), st.integers(-5, 5), st.booleans(), st.text(max_size=3),
                    st.floats(-1e3, 1e3).map(np.float64), st.just(np.array([1.0, 2.0])))


@given(st.lists(SCALARS, max_size=5))
def test_are_floats_is_every_value_a_float(values):
    assert are_floats(*values) == all(isinstance(v, float) for v in values)


@given(st.lists(st.tuples(st.sampled_from(("A", "B")), SCALARS.filter(lambda v: not isinstance(v, np.ndarray))),
                max_size=12))
def test_the_info_buffer_keeps_numbers_as_floats_and_each_variable_its_first_type(writes):
    """InfoBuffer.set as first written: ints and numpy floats stored as floats, bools and text as they
    are, and a write of the other kind (number vs text) refused."""
    info, kept = InfoBuffer(), {}
    for t, (var, value) in enumerate(writes):
        expected = float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else value
        accepted = var not in kept or isinstance(kept[var], float) == isinstance(expected, float)
        assert info.set(var, value, float(t)) == accepted
        if accepted:
            kept[var] = expected
        assert info.get(var) == kept.get(var) and type(info.get(var)) is type(kept.get(var))
