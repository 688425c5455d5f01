"""uFldOilSensor's sensor model and truth replay: detection rates, thickness classes, bad requests."""
import numpy as np
import pytest
from shapely.geometry import Point, box

from oilspill_moos.forecaster.dataset import load_dataset
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.messages import parse_request
from oilspill_moos.response.oil_sensor import OilSensor, SensorModel, TruthSpill
from oilspill_moos.response.scenario_map import ScenarioMap

SLICK = box(0, 0, 100, 100)
N = 4000


def rate(model, x, y):
    return np.mean([model.sense(SLICK, x, y)[0] for _ in range(N)])


def test_perfect_sensor_sees_oil_exactly_within_its_range():
    model = SensorModel(range_m=10)
    assert model.sense(SLICK, 50, 50)[0] and model.sense(SLICK, 109, 50)[0]
    assert not model.sense(SLICK, 111, 50)[0]


@pytest.mark.parametrize("fp, fn", [(0.1, 0.0), (0.0, 0.2), (0.05, 0.3)])
def test_error_rates_match_the_configuration(fp, fn):
    model = SensorModel(range_m=5, false_positive=fp, false_negative=fn, seed=3)
    # binomial standard error at N=4000 is below 0.008; 0.03 is about four of them
    assert abs(rate(model, 50, 50) - (1 - fn)) < 0.03
    assert abs(rate(model, 300, 300) - fp) < 0.03


def test_same_seed_same_noise():
    a, b = (SensorModel(false_positive=0.5, seed=7) for _ in range(2))
    assert [a.sense(SLICK, 500, 500)[0] for _ in range(50)] == [b.sense(SLICK, 500, 500)[0] for _ in range(50)]


def test_thickness_class_by_depth_inside_the_slick():
    model = SensorModel(range_m=5, thickness_depth=20)
    assert model.sense(SLICK, 50, 50) == (True, "thick")
    assert model.sense(SLICK, 5, 50) == (True, "sheen")
    assert model.sense(SLICK, 103, 50) == (True, "sheen")     # in range of the edge, outside it
    assert model.sense(SLICK, 200, 50) == (False, "")


def test_bad_rates_are_refused():
    with pytest.raises(ValueError, match="false_negative"):
        SensorModel(false_negative=1.5)


def test_requests_are_parsed_or_refused_with_a_reason():
    assert parse_request("vname=Abe,id=3,x=1.5,y=-2") == ("abe", 3, 1.5, -2.0)
    with pytest.raises(ValueError, match="lacks y"):
        parse_request("vname=abe,id=3,x=1")
    with pytest.raises(ValueError, match="numbers"):
        parse_request("vname=abe,id=three,x=1,y=2")
    with pytest.raises(ValueError, match="non-finite"):
        parse_request("vname=abe,id=3,x=nan,y=2")


def test_truth_replays_hourly_polygons_shrunk_about_the_origin():
    scenario = next(s for s in load_dataset() if s.scenario_id == "steady_growth-2111")
    full = TruthSpill.from_scenario(scenario, ScenarioMap(LocalGrid(28.736667, -88.387222), 1.0))
    small = TruthSpill.from_scenario(scenario, ScenarioMap(LocalGrid(28.736667, -88.387222), 0.02))
    assert small.at(20.4).area == pytest.approx(full.at(20.4).area * 0.02 ** 2, rel=1e-6)
    assert small.at(20.4) is small.at(20.0) and small.at(21.0) is not small.at(20.0)
    assert small.at(1e6) is small.geometries[-1] and small.at(-5) is small.geometries[0]
    assert small.utc(1.0) - small.utc(0.0) == 3600.0
    assert small.at(20).distance(Point(0, 0)) < 400     # the slick stays near the wellhead at this scale


def test_app_pages():
    assert OilSensor.main(["--example"]) == 0 and OilSensor.main(["--interface"]) == 0
