"""uFldOilFusion's pure parts and the forecaster's re-anchoring: boundary estimate, skill, bad input."""
import math

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import Point, box

from oilspill_moos.forecaster.assimilate import fit_similarity, read_feedback
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.messages import Observation, ObservationRejected, format_observation, parse_observation
from oilspill_moos.response.oil_fusion import ObservationCollector, flip_points, skill
from oilspill_moos.response.scenario_map import ScenarioMap

SPILL = box(0, 0, 100, 100)


def along(vname, xs, y, spill=SPILL, r=0.0, t0=0.0):
    """A vehicle driving east along y, sampling with a point sensor (range r)."""
    return [Observation(vname, i, t0 + i, x, y, bool(spill.distance(Point(x, y)) <= r), r) for i, x in enumerate(xs)]


def test_observation_round_trip_and_refusals():
    obs = Observation("abe", 4, 1272067200.5, 12.3, -4.5, True, 15.0, "thick")
    assert parse_observation(format_observation(obs)) == obs
    for text, reason in [("vname=abe,id=1,utc=1,x=2,y=3", "lacks oil"), ("vname=abe,id=1,utc=1,x=2,y=3,oil=maybe", "oil 0 or 1"),
                         ("vname=abe,id=1,utc=1,x=inf,y=3,oil=1", "non-finite"), ("garbage", "malformed")]:
        with pytest.raises(ObservationRejected, match=reason):
            parse_observation(text)


def test_flips_lie_half_way_across_the_edge():
    track = along("abe", np.arange(-50, 151, 10.0), 50)
    points = flip_points(track)
    assert [(x, y) for x, y, _ in points] == [(-5.0, 50.0), (105.0, 50.0)]
    assert flip_points(track, max_gap_m=5) == []          # samples too far apart to place an edge
    assert flip_points(along("abe", [200, 210, 220], 50)) == []


def test_skill_is_perfect_for_the_truth_and_measures_a_shifted_forecast():
    track = along("abe", np.arange(-50, 151, 2.0), 50) + along("ben", np.arange(-50, 151, 2.0), 20, t0=500)
    right = skill(SPILL, track)
    assert right["agreement"] == 1.0 and right["flips"] == 4 and right["boundary_error_m"] <= 1.0
    wrong = skill(affinity.translate(SPILL, 30, 0), track)
    assert wrong["agreement"] < 0.9 and wrong["boundary_error_m"] == pytest.approx(30, abs=1.5)
    assert math.isnan(skill(SPILL, [])["agreement"])


def test_collector_rejects_unknown_out_of_area_out_of_order_and_drops_duplicates():
    c = ObservationCollector(fleet=frozenset({"abe", "ben"}), area=box(-500, -500, 500, 500))
    first = Observation("abe", 1, 10.0, 0, 0, True)
    assert c.offer(first) and not c.offer(first) and c.duplicates == 1
    with pytest.raises(ObservationRejected, match="unknown vehicle 'zed'"):
        c.offer(Observation("zed", 1, 11.0, 0, 0, True))
    with pytest.raises(ObservationRejected, match="outside the operating area"):
        c.offer(Observation("abe", 2, 11.0, 9000, 0, True))
    with pytest.raises(ObservationRejected, match="older than"):
        c.offer(Observation("abe", 3, 9.0, 0, 0, True))
    assert c.offer(Observation("ben", 1, 9.0, 0, 0, False))   # another vehicle's clock is its own
    assert c.rejected == {"unknown vehicle": 1, "out of area": 1, "out of order": 1}
    assert len(c.begin_cycle("oilspill_2")) == 2 and c.observations == [] and c.cycle == "oilspill_2"
    assert not c.offer(first)                              # still a duplicate in the next cycle


@pytest.mark.parametrize("r", [0.0, 15.0])
def test_similarity_fit_recovers_a_shift_and_scale(r):
    truth = shapely.Polygon([(0, 0), (120, 10), (140, 90), (40, 130), (-20, 60)])
    prior = affinity.scale(affinity.translate(truth, 25, -15), 1.15, 1.15)
    loop = prior.buffer(10).exterior
    xy = np.array([loop.interpolate(d).coords[0] for d in np.linspace(0, loop.length, 240, endpoint=False)])
    oil = shapely.dwithin(truth, shapely.points(xy), r)
    dx, dy, s, misfit = fit_similarity(prior, xy, oil, np.full(len(xy), r))
    fitted = affinity.translate(affinity.scale(prior, s, s, origin=prior.centroid), dx, dy)
    iou = lambda a: a.intersection(truth).area / a.union(truth).area
    # one loop of readings cannot tell every shift from a scale (the far side is unseen), so the
    # fit is closer, not exact
    assert iou(fitted) > iou(prior) + 0.1, (iou(prior), iou(fitted))


def test_similarity_fit_leaves_a_forecast_the_readings_agree_with():
    xy = np.array([(-20.0, 50.0), (120.0, 50.0), (50.0, 50.0)])
    dx, dy, s, misfit = fit_similarity(SPILL, xy, np.array([False, False, True]), np.zeros(3))
    assert misfit < 0.05 and math.hypot(dx, dy) < 2 and abs(s - 1) < 0.05


def test_feedback_file_errors_name_the_line(tmp_path):
    path = tmp_path / "fb.jsonl"
    path.write_text('{"utc": 1, "lon": -88.3, "lat": 28.7, "oil": true, "range_m": 500}\nnot json\n')
    with pytest.raises(ValueError, match="fb.jsonl:2"):
        read_feedback(path)
    path.write_text('{"utc": 1, "lon": -88.3, "oil": true, "range_m": 500}\n')
    with pytest.raises(ValueError, match="bad observation"):
        read_feedback(path)
    assert len(read_feedback(tmp_path / "absent.jsonl")) == 0


def test_scenario_map_round_trip():
    world = ScenarioMap(LocalGrid(28.736667, -88.387222), 0.02)
    lon, lat = world.to_lonlat([100.0], [-50.0])
    back = world.to_local(shapely.Point(lon[0], lat[0]))
    assert back.x == pytest.approx(100.0, abs=1e-6) and back.y == pytest.approx(-50.0, abs=1e-6)
    assert world.real_metres(15) == pytest.approx(750)
    with pytest.raises(ValueError, match="map_scale"):
        ScenarioMap(world.grid, 0.0)


from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

_coord = st.floats(-1e5, 1e5, allow_nan=False).map(lambda v: round(v, 2))


@settings(max_examples=60, deadline=None)
@given(vname=st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True), ident=st.integers(0, 10**6),
       utc=st.floats(0, 2e9, allow_nan=False).map(lambda v: round(v, 2)), x=_coord, y=_coord, oil=st.booleans(),
       range_m=st.floats(0, 1e4, allow_nan=False).map(lambda v: round(v, 2)),
       thickness=st.sampled_from(["", "sheen", "thick"]))
def test_observation_format_parse_round_trip(vname, ident, utc, x, y, oil, range_m, thickness):
    obs = Observation(vname, ident, utc, x, y, oil, range_m, thickness)
    assert parse_observation(format_observation(obs)) == obs


@settings(max_examples=80, deadline=None)
@given(st.text(max_size=80))
def test_any_text_gives_a_sound_observation_or_a_reason(text):
    try:
        obs = parse_observation(text)
    except ObservationRejected as exc:
        assert str(exc)
    else:
        assert all(map(math.isfinite, (obs.x, obs.y, obs.utc))) and obs.range_m >= 0 and obs.vname == obs.vname.lower()
