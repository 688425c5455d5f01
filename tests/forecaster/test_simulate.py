"""Scenario generator: parameter draws, forcing, the particle-to-polygon method, and one real OpenOil run."""
import numpy as np
import pytest
import shapely
from shapely.geometry import MultiPolygon

from oilspill_moos.forecaster.dataset import REGIMES
from oilspill_moos.forecaster.simulate import (forcing_series, generation_plan, main, particles_to_polygon,
                                               scenario_params)


def test_parameters_are_deterministic_per_seed_and_inside_regime_ranges():
    assert scenario_params("strong_forcing", 7) == scenario_params("strong_forcing", 7)
    assert scenario_params("strong_forcing", 7) != scenario_params("strong_forcing", 8)
    p = scenario_params("strong_forcing", 7)
    assert 10 <= p["wind_speed"] <= 16 and 0.3 <= p["current_speed"] <= 0.7
    assert len(scenario_params("multi_lobe", 3)["pulses_h"]) == 2
    with pytest.raises(ValueError, match="unknown regime"):
        scenario_params("tsunami", 1)


def test_plan_is_round_robin_so_any_prefix_has_every_regime():
    plan = generation_plan(3, 100)
    assert [p["regime"] for p in plan[:5]] == list(REGIMES) and len(plan) == 15
    assert len({p["seed"] for p in plan}) == 15


def test_multi_lobe_wind_shift_turns_the_forcing():
    p = scenario_params("multi_lobe", 11)
    f = forcing_series(p)
    before, after = f[int(p["wind_shift_h"]) - 1, :2], f[int(p["wind_shift_h"]) + 1, :2]
    turn = np.degrees(np.arccos(before @ after / np.linalg.norm(before) / np.linalg.norm(after)))
    assert abs(turn - min(p["wind_shift_deg"], 360 - p["wind_shift_deg"])) < 25
    assert f.shape == (p["duration_h"] + 2, 5) and np.allclose(f[:, 4], p["sea_temp_c"])


def test_particles_to_polygon_holds_most_particles_and_splits_lobes():
    rng = np.random.default_rng(0)
    a = rng.normal([0, 0], [2_000, 800], (1500, 2))
    b = rng.normal([20_000, 5_000], 700, (500, 2))
    cloud = np.vstack([a, b])
    poly = particles_to_polygon(cloud[:, 0], cloud[:, 1])
    assert isinstance(poly, MultiPolygon) and len(poly.geoms) == 2
    inside = shapely.covers(poly, shapely.points(cloud)).mean()
    assert 0.85 <= inside <= 0.97
    assert particles_to_polygon(cloud[:10, 0], cloud[:10, 1]) is None


def test_unknown_regime_is_a_usage_error(capsys):
    with pytest.raises(SystemExit):
        main(["--regimes", "tsunami"])
    assert "unknown regime" in capsys.readouterr().err


def test_one_short_openoil_run_gives_hourly_polygons():
    pytest.importorskip("opendrift")
    from oilspill_moos.forecaster.simulate import run_scenario

    params = scenario_params("steady_growth", 5) | {"duration_h": 4, "pulses_h": [[0.0, 1.0]]}
    scenario = run_scenario(params, particles=200)
    assert len(scenario) in (4, 5) and np.all(np.diff(scenario.times_h) == 1.0)
    assert scenario.features().shape == (len(scenario), 25)
