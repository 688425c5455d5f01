"""Each responder's measure on a hand-built case whose answer can be worked out on paper."""
import math

import pytest
import shapely
from shapely.geometry import Polygon

from oilspill_moos.response.measures import (
    largest_revisit_gap,
    manned_at,
    oil_containment,
    patrol_offsets,
    perimeter_coverage,
    positions_at,
)

SQUARE = Polygon([(0, 0), (1000, 0), (1000, 1000), (0, 1000)])   # perimeter 4000 m


def test_coverage_is_the_share_of_the_perimeter_within_reach():
    # a vessel 100 m below the middle of the bottom edge, reach 200 m: sqrt(200^2-100^2) each side
    share = perimeter_coverage(SQUARE, [(500, -100)], 200)
    assert share == pytest.approx(2 * math.sqrt(200**2 - 100**2) / 4000, rel=1e-3)
    # two vessels on opposite edges, no overlap: twice that; nobody: nothing; everything within reach: all
    assert perimeter_coverage(SQUARE, [(500, -100), (500, 1100)], 200) == pytest.approx(2 * share, rel=1e-3)
    assert perimeter_coverage(SQUARE, [], 200) == 0.0
    assert perimeter_coverage(SQUARE, [(500, 500)], 800) == pytest.approx(1.0)


def test_coverage_counts_only_the_outer_perimeter_of_every_part():
    holed = Polygon(SQUARE.exterior.coords, [[(400, 400), (600, 400), (600, 600), (400, 600)]])
    assert perimeter_coverage(holed, [(500, 500)], 150) == 0.0          # the hole's edge is inside the oil
    two = shapely.MultiPolygon([SQUARE, shapely.affinity.translate(SQUARE, 3000, 0)])
    assert perimeter_coverage(two, [(500, 500)], 800) == pytest.approx(0.5)


def test_positions_between_reports_and_stale_vehicles_left_out():
    tracks = {"abe": [(0.0, 0.0, 0.0), (10.0, 100.0, 0.0)], "ben": [(0.0, 5.0, 5.0)]}
    assert positions_at(tracks, 5.0) == {"abe": (50.0, 0.0), "ben": (5.0, 5.0)}
    assert positions_at(tracks, 100.0, stale=30) == {}


def test_manned_at_is_the_first_report_near_the_own_patrol_after_the_push():
    patrols = {"abe": [(0, -100), (1000, -100)], "ben": [(1100, 0), (1100, 1000)]}
    tracks = {"abe": [(0.0, 0.0, -100.0), (50.0, 0.0, -500.0), (100.0, 0.0, -300.0), (150.0, 0.0, -105.0)],
              "ben": [(60.0, 3000.0, 0.0), (120.0, 1105.0, 500.0)]}
    # abe was on its patrol before the push at t=40: that does not count, t=150 does
    assert manned_at(tracks, patrols, after=40.0, reach=10.0) == {"abe": 150.0, "ben": 120.0}
    assert manned_at(tracks, {"cal": [(0, 0), (1, 1)]}, after=0.0, reach=10.0) == {"cal": None}


def test_revisit_gap_of_one_vessel_going_back_and_forth_on_a_line():
    # a "loop" that is a thin rectangle 1000 m long; one vessel at 10 m/s sweeps it end to end and back
    loop = [(0, 0), (1000, 0), (1000, 1), (0, 1)]
    sweep = [(t, min(10.0 * t, 2000 - 10.0 * t), 0.5) for t in range(0, 201, 5)]
    gap, point = largest_revisit_gap(loop, {"abe": sweep}, 0.0, 200.0, reach=20.0, spacing=50.0, step=1.0)
    # the far end (x=1000) is seen around t=100 only: gaps of ~100 s before and after
    # the start end (x=0) is seen at t=0 and t=200 only: its gap is ~200 s, the largest
    assert gap == pytest.approx(200 - 2 * 20 / 10, abs=2.0)
    assert point[0] < 50
    never = largest_revisit_gap(loop, {}, 0.0, 200.0, reach=20.0)
    assert never[0] == 200.0


def test_patrol_offsets_are_signed_distances_from_the_true_boundary():
    patrols = {"out": [(0, -100), (1000, -100)],            # 100 m south of the oil all along
               "over": [(100, 500), (900, 500)],            # crossing the oil: 100..500 m inside
               "half": [(500, -200), (500, 200)]}           # half outside, half over oil
    offsets = patrol_offsets(SQUARE, patrols, spacing=10)
    assert offsets["out"].median_m == pytest.approx(100) and offsets["out"].over_oil == 0
    assert offsets["over"].nearest_m == pytest.approx(-500) and offsets["over"].farthest_m == pytest.approx(-100)
    assert offsets["over"].over_oil == 1
    assert offsets["half"].nearest_m == pytest.approx(-200) and offsets["half"].farthest_m == pytest.approx(200)
    assert offsets["half"].over_oil == pytest.approx(0.5, abs=0.03)


def test_oil_inside_and_outside_the_patrol_loop():
    loop = [(-50, -50), (600, -50), (600, 1050), (-50, 1050)]     # contains the square's western 600 m
    kept = oil_containment(SQUARE, loop)
    assert kept.inside_m2 == pytest.approx(600_000) and kept.outside_m2 == pytest.approx(400_000)
    assert kept.share_inside == pytest.approx(0.6)
    assert oil_containment(SQUARE, [(-1, -1), (1001, -1), (1001, 1001), (-1, 1001)]).share_inside == 1.0
