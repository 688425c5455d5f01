"""Scenario generator: parameter draws, forcing and forcing errors, the footprint methods, one real OpenOil run."""
import numpy as np
import pytest
import shapely
from shapely.geometry import MultiPolygon

from oilspill_moos.forecaster.dataset import HELD_OUT_METHOD, HELD_OUT_REGIONS
from oilspill_moos.forecaster.simulate import (FOOTPRINT_METHODS, REGIONS, STEADY_REGIMES, STEADY_TRAINING_DRAWS,
                                               TRAIN_METHODS, VARYING_DRAWS, footprint, forcing_series,
                                               generation_plan, given_forcing, main,
                                               particles_to_polygon, scenario_params)


def open_sea(lons, lats):
    """Land test for a world of open water (the generator's real test needs the 60 MB GSHHG mask)."""
    return np.zeros(np.shape(lons), bool)


def test_parameters_are_deterministic_per_seed_and_the_split_is_by_construction():
    p = scenario_params("central", 7, land=open_sea)
    assert p == scenario_params("central", 7, land=open_sea) != scenario_params("central", 8, land=open_sea)
    assert REGIONS["central"][0] <= p["lon"] <= REGIONS["central"][1] and p["method"] in TRAIN_METHODS
    for region in HELD_OUT_REGIONS:
        assert scenario_params(region, 3, land=open_sea)["method"] == HELD_OUT_METHOD
    with pytest.raises(ValueError, match="unknown region"):
        scenario_params("atlantis", 1, land=open_sea)


def test_steady_regimes_have_constant_forcing_training_regions_first_then_held_out_ones():
    plan = generation_plan(VARYING_DRAWS + STEADY_TRAINING_DRAWS + 2 * len(STEADY_REGIMES), 20260, land=open_sea)
    assert all(p.get("regime", "varying") == "varying" for p in plan[:VARYING_DRAWS])
    training, held_out = plan[VARYING_DRAWS:VARYING_DRAWS + STEADY_TRAINING_DRAWS], plan[VARYING_DRAWS + STEADY_TRAINING_DRAWS:]
    assert [p["regime"] for p in training] == STEADY_TRAINING_DRAWS // len(STEADY_REGIMES) * list(STEADY_REGIMES)
    assert all(p["region"] not in HELD_OUT_REGIONS and p["method"] in TRAIN_METHODS for p in training)
    assert [p["regime"] for p in held_out] == 2 * list(STEADY_REGIMES)
    assert {p["region"] for p in held_out} == set(HELD_OUT_REGIONS)
    assert all(p["method"] == HELD_OUT_METHOD for p in held_out)
    steady = training[:2 * len(STEADY_REGIMES)] + held_out
    for p in steady:
        f = forcing_series(p)
        assert p["inertial_amp"] == p["tidal_amp"] == p["wind_gust"] == 0.0 and p["wind_shift_h"] is None
        assert np.allclose(f[:, 2:4], f[0, 2:4])                          # a steady current
        assert np.allclose(np.hypot(f[:, 0], f[:, 1]), p["wind_speed"])   # steady wind speed (a slow veer at most)
        if p["wind_pattern"] == "constant":
            assert np.allclose(f[:, :2], f[0, :2])
        assert abs(p["wind_veer_deg"]) <= 20.0
        lobes = p["lobes_km"]
        assert (2 <= len(lobes) <= 3) if p["regime"] == "multi_lobe" else len(lobes) == 1
        assert lobes[0][0] == 0.0 and all(3.0 <= d <= 12.0 for d, _ in lobes[1:])
    strong = [p for p in steady if p["regime"] == "strong_forcing"]
    assert all(p["wind_speed"] >= 10.0 and p["current_speed"] >= 0.3 for p in strong)
    assert all(p["release_h"] == 44.0 for p in steady if p["regime"] == "initial_release")
    assert all(p["vertical_mixing"] and p["diffusivity"] >= 30.0 for p in steady if p["regime"] == "dispersal")
    with pytest.raises(ValueError, match="unknown regime"):
        scenario_params("central", 1, land=open_sea, regime="tsunami")


def test_release_points_avoid_land():
    land_west_of_minus_90 = lambda lons, lats: np.asarray(lons) < -90.0  # noqa: E731
    for seed in range(5):
        assert scenario_params("central", seed, land=land_west_of_minus_90)["lon"] > -90.0 + 0.3


def test_wind_shift_turns_the_forcing_and_the_inertial_current_rotates():
    p = next(q for q in (scenario_params("east", s, land=open_sea) for s in range(40)) if q["wind_pattern"] == "shift")
    p = p | {"wind_gust": 0.0, "inertial_amp": 0.2, "current_speed": 0.0, "tidal_amp": 0.0}
    f = forcing_series(p)
    k = int(p["wind_shift_h"])
    before, after = f[k - 1, :2], f[k + 2, :2]
    turn = np.degrees(np.arccos(np.clip(before @ after / np.linalg.norm(before) / np.linalg.norm(after), -1, 1)))
    assert turn == pytest.approx(min(abs(p["wind_shift_deg"]), 360 - abs(p["wind_shift_deg"])), abs=1.0)
    assert f.shape == (p["duration_h"] + 18, 5)
    assert np.allclose(np.hypot(f[:, 2], f[:, 3]), 0.2)        # a pure inertial circle


def test_given_forcing_differs_from_the_truth_by_model_sized_errors():
    p = scenario_params("central", 11, land=open_sea)
    true = forcing_series(p)
    errors = [np.abs(given_forcing(true, seed)[:, :4] - true[:, :4]).mean() for seed in range(20)]
    assert 0.01 < np.mean(errors) < 2.0
    assert np.array_equal(given_forcing(true, 3), given_forcing(true, 3))


def test_every_footprint_method_holds_most_particles_and_splits_lobes():
    rng = np.random.default_rng(0)
    a = rng.normal([0, 0], [2_000, 800], (1500, 2))
    b = rng.normal([20_000, 5_000], 700, (500, 2))
    cloud = np.vstack([a, b])
    for method in FOOTPRINT_METHODS:
        poly = footprint(method, cloud[:, 0], cloud[:, 1])
        assert isinstance(poly, MultiPolygon) and poly.is_valid, method
        big_two = sorted(poly.geoms, key=lambda g: g.area)[-2:]      # buffer-union may keep a stray particle's disc
        assert {g.contains(shapely.Point(0, 0)) for g in big_two} == {True, False}, method
        assert any(g.contains(shapely.Point(20_000, 5_000)) for g in big_two), method
        inside = shapely.covers(poly, shapely.points(cloud)).mean()
        assert 0.85 <= inside <= 1.0, method
    assert particles_to_polygon(cloud[:10, 0], cloud[:10, 1]) is None


def test_bad_arguments_are_usage_errors(capsys):
    with pytest.raises(SystemExit):
        main(["--count", "0"])
    assert "--count" in capsys.readouterr().err


def test_one_short_openoil_run_gives_hourly_footprints():
    pytest.importorskip("opendrift")
    from oilspill_moos.forecaster.simulate import run_scenario

    params = scenario_params("central", 5, method="hdr-kde", land=open_sea) | {"duration_h": 4, "release_h": 0.0}
    scenario = run_scenario(params, particles=200)
    assert len(scenario) in (3, 4) and np.all(np.diff(scenario.times_h) == 1.0)
    assert scenario.hourly_given.shape == scenario.hourly_true.shape == (4 + 18, 5)
