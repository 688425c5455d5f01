"""The shipped forecaster through its public API: every kind on a replayed scenario, and the real DWH
composites (17 + 19 May -> 20 May)."""
from datetime import timedelta

import numpy as np
import pytest
from shapely.geometry import MultiPolygon

from oilspill_moos.forecaster import features as F
from oilspill_moos.forecaster.dataset import load_dataset
from oilspill_moos.forecaster.kinds import DEFAULT_MODEL, KINDS
from oilspill_moos.forecaster.operational import WEIGHTS_DIR, Forecaster
from oilspill_moos.forecaster.readers import read_polygons

from helpers import DWH, requires_shared



@pytest.fixture(scope="module")
def replayed():
    scenario = max(load_dataset(), key=len)
    return scenario, (scenario.geometries[:16], scenario.times()[:16], scenario.environments()[:16])


@pytest.mark.parametrize("kind", KINDS)
def test_every_shipped_kind_forecasts_every_horizon(kind, replayed):
    scenario, history = replayed
    forecasts = Forecaster(WEIGHTS_DIR, kind).forecast(*history, scenario.release_time)
    assert [f.horizon_h for f in forecasts] == [3, 7, 11, 15] and {f.source for f in forecasts} == {kind}
    last = F.to_plane(history[0][-1])
    for f in forecasts:
        plane = F.to_plane(f.geometry)
        assert isinstance(f.geometry, MultiPolygon) and f.geometry.is_valid
        assert 0.1 < plane.area / last.area < 10
        assert f.valid_time == F.as_utc(history[1][-1]) + timedelta(hours=f.horizon_h)
        # P >= 50 % may be nowhere when the calibrated spread exceeds the slick; the 90 % envelope never is
        assert F.to_plane(f.contour_90).area >= max(F.to_plane(f.contour_50).area, 0.5 * plane.area) > 0
        assert f.uncertainty_m > 0 and f.line().startswith(b'{"type":"boundary"')
    assert forecasts[-1].uncertainty_m > forecasts[0].uncertainty_m


def test_the_weights_record_what_was_held_out():
    forecaster = Forecaster()
    split = forecaster.split
    assert split["train"] and not set(split["train"]) & set(split["test"])
    assert {s.scenario_id for s in load_dataset()} <= set(split["test"])      # the DWH-site set was never trained on


@requires_shared("data/dwh")
def test_real_dwh_17_and_19_may_forecast_20_may_plausibly():
    history = [read_polygons(DWH / f"dwh-2010-05-{d}.geojson") for d in ("17", "19")]
    truth = read_polygons(DWH / "dwh-2010-05-20.geojson")
    plane = F.SpillPlane.about(F.repaired(truth.geometry))
    last = plane.to_plane(F.repaired(history[-1].geometry))
    for kind in (DEFAULT_MODEL, "persistence", "physics"):
        forecasts = Forecaster(WEIGHTS_DIR, kind).forecast([o.geometry for o in history], [o.time for o in history])
        for f in forecasts:
            g = plane.to_plane(f.geometry)
            assert f.geometry.is_valid and not f.geometry.is_empty, kind
            assert 0.5 < g.area / last.area < 2.0, kind                  # no doubling in 15 h
            assert g.centroid.distance(last.centroid) < 100_000, kind
            assert g.intersection(plane.to_plane(F.repaired(truth.geometry))).area > 0, kind
