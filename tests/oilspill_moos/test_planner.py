"""Planner properties: start points on the stand-off perimeter, optimal bottleneck, even closed loops."""
import itertools
import math

import numpy as np
import pytest
import shapely
from hypothesis import example, given, settings
from hypothesis import strategies as st
from shapely.geometry import MultiPolygon, Polygon

from oilspill_moos.response.planner import (
    PlanError,
    bottleneck_assignment,
    choose_forecast,
    containment_loop,
    containment_region,
    greedy_assignment,
    plan_arcs,
    plan_containment,
    reshare,
    transit_route,
)

coordinate = st.floats(-2000, 2000, allow_nan=False, allow_infinity=False)
point = st.tuples(coordinate, coordinate)


@st.composite
def spill_polygons(draw):
    """Star-shaped polygons (random radii about a centre), which is what forecasts look like."""
    k = draw(st.integers(3, 12))
    radii = draw(st.lists(st.floats(50, 800), min_size=k, max_size=k))
    cx, cy = draw(point)
    angles = np.linspace(0, 2 * np.pi, k, endpoint=False)
    return [(cx + r * np.cos(a), cy + r * np.sin(a)) for r, a in zip(radii, angles)]


fleets = st.dictionaries(st.sampled_from(["abe", "ben", "cal", "deb", "eve", "fin"]), point, min_size=1, max_size=6)


def brute_force_bottleneck(cost):
    n = len(cost)
    return min(max(cost[r, c] for r, c in enumerate(perm)) for perm in itertools.permutations(range(n)))


@settings(max_examples=40, deadline=None)
@given(spill_polygons(), st.floats(0, 300), fleets)
@example([(332.0, 0.0), (257.0, 43.30127018922194), (257.0, -43.30127018922192)], 3.33334497432315e-163,
         {"abe": (0.0, 0.0)})   # GEOS buffered this to an empty polygon
def test_start_points_lie_on_the_standoff_perimeter(vertices, standoff, positions):
    spill = Polygon(vertices)
    region = containment_region(vertices, standoff)
    plan = plan_containment(region, positions, rotations=8)
    assert set(plan.starts) == set(positions)
    for start in plan.starts.values():
        p = shapely.Point(start)
        assert region.exterior.distance(p) < 1e-6
        # quad_segs=4 rounds corners within cos(pi/8) of the radius; simplify may cut 0.5 m more
        assert spill.distance(p) >= standoff * np.cos(np.pi / 8) - 0.51
        if standoff > 1:
            assert not spill.contains(p)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 6).flatmap(lambda n: st.lists(st.integers(0, 50), min_size=n * n, max_size=n * n)))
def test_bottleneck_assignment_is_optimal_against_brute_force(flat):
    n = int(round(len(flat) ** 0.5))
    cost = np.asarray(flat, dtype=float).reshape(n, n)
    columns, worst = bottleneck_assignment(cost)
    assert sorted(columns) == list(range(n))
    assert worst == cost[np.arange(n), columns].max()
    assert worst == brute_force_bottleneck(cost)
    greedy = greedy_assignment(cost)
    assert worst <= cost[np.arange(n), greedy].max()


def test_greedy_can_be_strictly_worse():
    # vehicle 0 grabs the point vehicle 1 needs; vehicle 1 must then cross the whole field
    cost = np.array([[1.0, 2.0], [1.5, 100.0]])
    columns, worst = bottleneck_assignment(cost)
    greedy = greedy_assignment(cost)
    assert worst == 2.0
    assert cost[np.arange(2), greedy].max() == 100.0


@settings(max_examples=25, deadline=None)
@given(spill_polygons(), st.dictionaries(st.sampled_from(["abe", "ben", "cal", "deb"]), point, min_size=2, max_size=4))
def test_plan_is_optimal_for_its_rotation(vertices, positions):
    region = containment_region(vertices, 100.0)
    plan = plan_containment(region, positions, rotations=8)
    names = list(positions)
    starts = sorted(plan.starts.values())
    cost = np.array([[np.hypot(x - positions[v][0], y - positions[v][1]) for x, y in starts] for v in names])
    assert plan.bottleneck == pytest.approx(brute_force_bottleneck(cost), rel=1e-9)


@settings(max_examples=30, deadline=None)
@given(spill_polygons(), st.floats(10, 200), fleets)
def test_loops_are_closed_whole_perimeters_evenly_phased(vertices, standoff, positions):
    region = containment_region(vertices, standoff)
    plan = plan_containment(region, positions, rotations=4)
    perimeter = region.exterior.length
    n = len(positions)
    for name in plan.vehicles:
        loop = plan.loop(name)
        closed = np.vstack([loop, loop[:1]])
        assert np.allclose(loop[0], plan.starts[name])
        assert np.hypot(*np.diff(closed, axis=0).T).sum() == pytest.approx(perimeter, rel=1e-9)
        assert shapely.LineString(closed).hausdorff_distance(region.exterior) < 1e-6
    phases = np.sort(np.asarray(list(plan.start_arcs.values())))
    gaps = np.diff(np.append(phases, phases[0] + perimeter))
    assert np.allclose(gaps, perimeter / n)


def test_loops_run_the_same_direction():
    region = containment_region([(0, 0), (1000, 0), (1000, 1000), (0, 1000)], 50)
    plan = plan_containment(region, {"abe": (-500, -500), "ben": (1500, 1500)})
    for name in plan.vehicles:
        loop = plan.loop(name)
        assert shapely.LinearRing(loop).is_ccw


def test_loop_from_a_vertex_does_not_repeat_it():
    region = containment_region([(0, 0), (100, 0), (100, 100), (0, 100)], 0)
    loop = containment_loop(region, 0.0)
    assert len(loop) == 4
    assert len({tuple(p) for p in loop}) == 4


@pytest.mark.parametrize(
    "vertices, reason",
    [
        ([(0, 0), (1, 1)], "at least 3 distinct points"),
        ([(0, 0), (1, 1), (0, 0), (1, 1)], "at least 3 distinct points"),
        ([(0, 0), (1, 1), (2, 2)], "no area"),
        ([(0, 0), (1, float("nan")), (2, 0)], "non-finite"),
        ([(0, 0, 1), (1, 1, 1), (2, 0, 1)], "[x, y] pairs"),
        ([("a", 0), (1, 1), (2, 0)], "not numbers"),
    ],
)
def test_bad_polygons_are_rejected_with_a_reason(vertices, reason):
    with pytest.raises(PlanError, match=reason.replace("[", r"\[").replace("]", r"\]")):
        containment_region(vertices, 10)


def test_negative_standoff_is_rejected():
    with pytest.raises(PlanError, match="stand-off"):
        containment_region([(0, 0), (10, 0), (0, 10)], -1)


def test_self_intersecting_bowtie_is_repaired_into_one_loop():
    bowtie = [(0, 0), (1000, 1000), (1000, 0), (0, 1000)]
    region = containment_region(bowtie, 20)
    assert region.is_valid and region.area > 0
    assert region.contains(shapely.Point(100, 500)) and region.contains(shapely.Point(900, 500))


def test_holes_are_dropped():
    ring = Polygon([(0, 0), (1000, 0), (1000, 1000), (0, 1000)], holes=[[(400, 400), (600, 400), (600, 600), (400, 600)]])
    region = containment_region(ring, 10)
    assert len(region.interiors) == 0
    assert region.contains(shapely.Point(500, 500))


def test_separate_patches_are_enclosed_by_one_loop():
    patches = MultiPolygon([Polygon([(0, 0), (100, 0), (100, 100)]), Polygon([(5000, 0), (5100, 0), (5100, 100)])])
    region = containment_region(patches, 30)
    assert region.contains(patches)
    assert isinstance(region, Polygon)


def test_speeds_send_the_slow_vehicle_to_the_near_point():
    region = containment_region([(0, 0), (100, 0), (100, 100), (0, 100)], 0)
    positions = {"slow": (50, -10), "fast": (50, -20)}
    plan = plan_containment(region, positions, speeds={"slow": 0.5, "fast": 5.0})
    assert plan.starts["slow"][1] == pytest.approx(0.0, abs=1.0)
    assert plan.transit["slow"] == pytest.approx(20.0, abs=2.0)


def test_reshare_spreads_the_same_loop_over_the_survivors():
    region = containment_region([(0, 0), (1000, 0), (1000, 1000), (0, 1000)], 50)
    plan = plan_containment(region, {"abe": (0, -100), "ben": (1100, 500), "cal": (0, 1100)})
    survivors = {name: plan.starts[name] for name in ("abe", "ben")}
    again = reshare(plan, survivors)
    assert again.region.equals(plan.region)
    assert set(again.starts) == {"abe", "ben"}
    arcs = sorted(again.start_arcs.values())
    assert arcs[1] - arcs[0] == pytest.approx(region.exterior.length / 2)
    with pytest.raises(PlanError, match="dropped out"):
        reshare(plan, {})


def test_choose_forecast_matches_horizon_to_arrival_time():
    square = [(0, 0), (2000, 0), (2000, 2000), (0, 2000)]
    forecasts = {3: square, 7: square, 15: square}
    speeds = {"abe": 1.0}
    near = choose_forecast(forecasts, {"abe": (-100, -100)}, speeds, standoff=0)
    assert near.horizon_h == 3
    far = choose_forecast(forecasts, {"abe": (-16000, -16000)}, speeds, standoff=0)  # about 6.3 h away
    assert far.horizon_h == 7
    assert far.arrival_h == pytest.approx(far.plan.bottleneck / 3600)
    stale = choose_forecast(forecasts, {"abe": (-100, -100)}, speeds, standoff=0, age_h=12)
    assert stale.horizon_h == 15
    with pytest.raises(PlanError):
        choose_forecast({}, {"abe": (0, 0)}, speeds, standoff=0)


def path_of(position, route):
    return shapely.LineString([tuple(position), *route])


def test_transit_route_is_straight_when_clear_and_goes_round_when_not():
    region = containment_region([(0, 0), (100, 0), (100, 100), (0, 100)], 10)
    assert transit_route(region, (50, -50), (50, -10)) == [(50.0, -10.0)]
    route = transit_route(region, (50, -50), (50, 110))   # straight across the spill: round the east side
    assert len(route) > 1 and route[-1] == pytest.approx((50, 110))
    assert not path_of((50, -50), route).intersects(region.buffer(-1e-3))
    assert all(x >= 50 for x, _ in route)
    # the shorter way round: 110 m up the east side is shorter than going west from x=80
    assert transit_route(region, (80, -10), (80, 110))[-1] == pytest.approx((80, 110))
    assert min(x for x, _ in transit_route(region, (80, -10), (80, 110))) >= 80
    inside = transit_route(region, (50, 95), (50, -10))   # a vehicle inside leaves by the nearest way out
    assert inside[0] == pytest.approx((50, 110)) and inside[-1] == pytest.approx((50, -10))


@settings(max_examples=40, deadline=None)
@given(spill_polygons(), st.floats(0, 200), point, st.floats(0, 1))
def test_transit_route_never_enters_the_standoff_polygon(vertices, standoff, position, fraction):
    region = containment_region(vertices, standoff)
    here = shapely.Point(position)
    if region.buffer(-1e-3).contains(here):
        return   # starts inside: covered by the unit test above
    goal = tuple(shapely.get_coordinates(region.exterior.interpolate(fraction, normalized=True))[0])
    route = transit_route(region, position, goal)
    assert route[-1] == pytest.approx(goal)
    path = path_of(position, route)
    assert path.intersection(region.buffer(-1e-2)).length < 1e-6
    # at most the straight line to where it meets the ring, then the shorter way along the ring
    assert path.length <= here.distance(shapely.Point(goal)) + region.exterior.length / 2 + 1e-6


# ---- arcs: each vessel its own stretch of the perimeter ------------------------------------------------

def _arc_distance(region, point):
    return region.exterior.project(shapely.Point(point))


@settings(max_examples=40, deadline=None)
@given(spill_polygons(), st.floats(0, 300), fleets)
def test_arcs_cover_the_loop_without_overlap_and_patrols_stay_on_their_arc(vertices, standoff, positions):
    region = containment_region(vertices, standoff)
    perimeter = region.exterior.length
    plan = plan_arcs(region, positions, rotations=8, samples=16)
    assert set(plan.arcs) == set(positions)
    arcs = sorted(plan.arcs.values())
    starts = np.array([a for a, _ in arcs])
    lengths = np.array([length for _, length in arcs])
    assert lengths.sum() == pytest.approx(perimeter, rel=1e-9)
    # each arc ends where the next begins, the last wrapping round to the first: no gap, no overlap
    ends = (starts + lengths) % perimeter
    assert np.allclose(np.minimum(np.abs(ends - np.roll(starts, -1)),
                                  perimeter - np.abs(ends - np.roll(starts, -1))), 0, atol=1e-6 * perimeter)
    for name, (arc_start, length) in plan.arcs.items():
        tolerance = 1e-6 * max(perimeter, 1.0)
        entry = (plan.start_arcs[name] - arc_start) % perimeter
        assert entry <= length + tolerance or entry >= perimeter - tolerance
        assert region.exterior.distance(shapely.Point(plan.starts[name])) < 1e-6
        patrol = plan.loop(name)
        assert np.allclose(patrol[0], plan.starts[name], atol=1e-6)
        along = (np.array([_arc_distance(region, p) for p in patrol]) - arc_start) % perimeter
        on_arc = (along <= length + 1e-3) | (along >= perimeter - 1e-3)
        assert on_arc.all()
        # out and back: the patrol is twice the arc long
        closed = np.vstack([patrol, patrol[:1]])
        if len(positions) > 1:
            assert np.hypot(*np.diff(closed, axis=0).T).sum() == pytest.approx(2 * length, rel=1e-6, abs=1e-6)


@settings(max_examples=30, deadline=None)
@given(spill_polygons(), fleets)
def test_arc_transit_never_longer_than_going_to_an_evenly_spaced_point(vertices, positions):
    region = containment_region(vertices, 50)
    rotations = 16
    arcs = plan_arcs(region, positions, rotations=rotations)
    points = plan_containment(region, positions, rotations=rotations)
    step = region.exterior.length / len(positions) / rotations
    # an arc holds the evenly spaced point it starts at, and the rotation search is as fine
    assert arcs.bottleneck <= points.bottleneck + step + 1e-6
    for name, start in arcs.starts.items():
        assert math.hypot(start[0] - positions[name][0], start[1] - positions[name][1]) == pytest.approx(
            arcs.transit[name], rel=1e-9, abs=1e-9)


def test_arcs_go_to_the_nearest_vessel_and_keep_their_mode_when_reshared():
    region = containment_region([(0, 0), (10000, 0), (10000, 10000), (0, 10000)], 0)
    fleet = {"abe": (5000, -3000), "ben": (13000, 5000), "cal": (5000, 13000), "deb": (-3000, 5000)}
    plan = plan_arcs(region, fleet)
    for name, (x, y) in fleet.items():    # each sits off the middle of one side: 3000 m to its side
        assert plan.transit[name] == pytest.approx(3000, abs=2.0)
    assert reshare(plan, {k: v for k, v in fleet.items() if k != "deb"}).arcs.keys() == {"abe", "ben", "cal"}
    assert not reshare(plan_containment(region, fleet), fleet).arcs
