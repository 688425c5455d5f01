"""The default demo's pieces that need no running mission: the truth on the mission clock, the
forecaster's cycles, forecast skill and the manning bound, each against a case worked out by hand."""
import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from oilspill_moos.forecaster.train import WEIGHTS_DIR
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.oilspill_mission import ORIGIN, Observer
from oilspill_moos.response.oil_sensor import TruthSpill
from oilspill_moos.messages import parse_boundary_line
from oilspill_moos.response_demo import BOUND_FACTOR, Truth, forecast_cycles, forecast_skill, load_truth, transit_bound

SQUARE = Polygon([(0, 0), (1000, 0), (1000, 1000), (0, 1000)])


def hand_truth(start_hour=17.0) -> Truth:
    """Hourly squares moving 100 m east per hour, hours 0..29."""
    hours = np.arange(30, dtype=float)
    spill = TruthSpill(hours, [shapely.affinity.translate(SQUARE, 100 * h) for h in hours], 0.0)
    return Truth(None, spill, start_hour)


def test_the_truth_runs_on_the_mission_clock_from_its_start_hour():
    truth = hand_truth()
    assert truth.at(0).bounds[0] == 1700                    # hour 17 at mission second 0
    assert truth.at(2.5 * 3600).bounds[0] == 1900           # the latest hourly outline: hour 19
    assert truth.observed(17.0) == 18 and truth.observed(19.5) == 20   # hours 0..17, 0..19


def test_forecast_skill_is_overlap_and_centroid_distance_at_the_valid_hour():
    truth = hand_truth()
    exact = [list(p) for p in shapely.affinity.translate(SQUARE, 2000).exterior.coords[:-1]]
    half = [list(p) for p in shapely.affinity.translate(SQUARE, 2500).exterior.coords[:-1]]
    skill = forecast_skill(truth, {3: {"polygon": exact, "uncertainty_m": 0, "valid_hour": 20.0},
                                   7: {"polygon": half, "uncertainty_m": 0, "valid_hour": 20.0}})
    assert skill["3"] == {"iou": 1.0, "centroid_error_km": 0.0, "valid_hour": 20.0}
    assert skill["7"]["iou"] == pytest.approx(1 / 3, abs=1e-3)     # half overlaps: 0.5 / 1.5
    assert skill["7"]["centroid_error_km"] == pytest.approx(0.5)


def test_the_manning_bound_is_the_longest_route_from_where_each_vessel_was():
    observer = Observer("127.0.0.1", 1, warp=10.0)
    observer.t0 = 1000.0
    observer.tracks = {"abe": [(1000.0, 0.0, 0.0), (1100.0, 0.0, 0.0)], "ben": [(1000.0, 0.0, 0.0), (1100.0, 0.0, 0.0)]}
    observer.routes = {"abe": [(3000.0, 0.0), (3000.0, 4000.0)], "ben": [(0.0, 500.0)]}
    longest, bound = transit_bound(observer, 50.0, top_speed=4.0)
    assert longest == pytest.approx(7000.0)
    assert bound == pytest.approx(7000.0 / 4.0 * BOUND_FACTOR)


@pytest.mark.skipif(not any(WEIGHTS_DIR.glob("ltc-fused.pt")), reason="no shipped ltc-fused weights")
def test_each_cycle_is_a_new_forecast_of_every_horizon_from_the_truth_seen_so_far():
    truth = load_truth()
    cycles = forecast_cycles(truth, 2, 2.0, None, "ltc-fused")
    grid = LocalGrid(*ORIGIN)
    issued = []
    for k, cycle in enumerate(cycles):
        boundaries = [parse_boundary_line(line.decode(), grid) for line in cycle.lines]
        assert sorted(b.horizon_h for b in boundaries) == sorted(cycle.horizons) == [3, 7, 11, 15]
        assert {b.issued for b in boundaries} == {boundaries[0].issued}      # one forecast: one issue time
        issued.append(boundaries[0].issued)
        assert cycle.issued_hour == truth.start_hour + 2 * k and cycle.push_s == k * 7200
    assert issued[1] - issued[0] == pytest.approx(7200)      # a new cycle for pPathAssign: it re-plans
