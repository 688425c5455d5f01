"""The committed scenario sets (the DWH-site set the demos replay, the Gulf set the forecaster is trained
and scored on): contents, provenance, round trip, observation noise, and the out-of-distribution split."""
from datetime import datetime, timezone

import numpy as np
import pytest
from shapely import make_valid
from shapely.geometry import MultiPolygon, Point, Polygon

from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from oilspill_moos.forecaster.dataset import (COORD_STEP_DEG, DEFAULT_STEM, GULF_STEM, HELD_OUT_METHOD, HELD_OUT_REGIONS,
                                              REGIMES, Scenario, dataset_metadata, load_dataset, pack_coords, save_dataset,
                                              split_scenarios, unpack_coords)
from oilspill_moos.forecaster.features import to_lonlat
from oilspill_moos.forecaster.simulate import STEADY_REGIMES


@pytest.fixture(scope="module")
def scenarios():
    return load_dataset()


def test_committed_dataset_is_compact_and_covers_every_regime(scenarios):
    size = sum(DEFAULT_STEM.with_suffix(s).stat().st_size for s in (".npz", ".json"))
    assert size < 5_000_000
    counts = {r: sum(s.regime == r for s in scenarios) for r in REGIMES}
    assert all(n >= 2 for n in counts.values()), counts
    for s in scenarios:
        assert len(s) >= 32 and s.forcing.shape == (len(s), 5)
        assert np.all(np.diff(s.times_h) == 1.0), s.scenario_id  # hourly, no gaps
        assert all(isinstance(g, MultiPolygon) and not g.is_empty for g in s.geometries)


def test_generation_parameters_and_seeds_are_recorded(scenarios):
    meta = dataset_metadata()
    assert meta["polygon_method"]["name"] == "hdr-kde" and "opendrift_version" in meta
    recorded = {m["scenario_id"]: m for m in meta["scenarios"]}
    for s in scenarios:
        info = recorded[s.scenario_id]
        assert info["seed"] == s.seed == s.params["seed"]
        for key in ("wind_speed", "current_speed", "diffusivity", "oil_type", "pulses_h"):
            assert key in info["params"]


@pytest.fixture(scope="module")
def gulf():
    return load_dataset(GULF_STEM)


def test_gulf_set_is_compact_spread_and_records_both_forcings(gulf):
    size = sum(GULF_STEM.with_suffix(s).stat().st_size for s in (".npz", ".json"))
    # compact: under 75 kB a scenario (the 66-scenario set's 58 kB with room) and 15 MB in all
    assert size < 15_000_000 and size < 75_000 * len(gulf) and len(gulf) >= 150
    meta = dataset_metadata(GULF_STEM)
    assert "opendrift_version" in meta and meta["forcing_errors"]["wind_dir_deg"] > 0
    assert {s.params["region"] for s in gulf} == set(meta["regions"])
    assert {s.params["release"] for s in gulf} == {"instantaneous", "continuous"}
    assert {s.params["wind_pattern"] for s in gulf} == {"constant", "veer", "shift"}
    for s in gulf:
        assert s.hourly_given.shape == s.hourly_true.shape and len(s.hourly_given) >= s.times_h[-1] + 15
        assert not np.allclose(s.hourly_given[:, :4], s.hourly_true[:, :4])     # the forecaster is never told the truth
        assert np.allclose(s.forcing, s.hourly_given[s.times_h.astype(int)])


def test_split_is_out_of_distribution_by_construction(gulf):
    split = split_scenarios(gulf, seed=3)
    ids = split.ids()
    assert sorted(sum(ids.values(), [])) == sorted(s.scenario_id for s in gulf)
    assert split.test and all(s.params["region"] in HELD_OUT_REGIONS and s.params["method"] == HELD_OUT_METHOD
                              for s in split.test)
    for s in split.train + split.val:
        assert s.params["region"] not in HELD_OUT_REGIONS and s.params["method"] != HELD_OUT_METHOD
    assert split_scenarios(gulf, seed=3).ids() == ids and split_scenarios(gulf, seed=4).ids() != ids


def test_observation_noise_is_deterministic_with_gaps_and_jitter(gulf):
    s = gulf[0]
    index, observed = s.observed(seed=1)
    again, same = s.observed(seed=1)
    assert np.array_equal(index, again) and all(a.equals(b) for a, b in zip(observed, same))
    assert index[0] == 0 and index[-1] == len(s) - 1 and all(g.is_valid for g in observed)
    gaps = [np.diff(g.observed(seed)[0]).max() for g in gulf[:4] for seed in range(2)]
    assert max(gaps) >= 2                                  # missing hours: irregular intervals
    assert not observed[0].equals(s.geometries[0])        # boundary jitter
    clean_index, clean = s.observed(noise=False)
    assert len(clean_index) == len(s) and clean[3].equals(s.geometries[3])


def test_save_and_load_round_trip(tmp_path):
    geoms = [to_lonlat(MultiPolygon([Point(100.0 * h, 0).buffer(1_000 + 50 * h)])) for h in range(3)]
    s = Scenario(scenario_id="toy-1", regime="steady_growth", seed=1,
                 release_time=datetime(2010, 4, 22, 5, tzinfo=timezone.utc), params={"seed": 1},
                 times_h=np.array([1.0, 2.0, 3.0]), geometries=geoms, forcing=np.ones((3, 5)))
    save_dataset([s], tmp_path / "toy", {"generator": "test"})
    (back,) = load_dataset(tmp_path / "toy")
    assert back.scenario_id == "toy-1" and back.release_time == s.release_time
    assert np.allclose(back.times_h, s.times_h) and back.geometries[2].equals_exact(geoms[2], 1e-4)
    with pytest.raises(FileNotFoundError, match="absent.npz: dataset file missing"):
        load_dataset(tmp_path / "absent")


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(0, 40), st.just(2)),
              elements=st.floats(-180.0, 180.0, allow_nan=False)))
def test_packed_vertices_round_trip_within_half_a_step(coords):
    """Any vertices (jumps of any size included) come back within half a quantisation step."""
    back = unpack_coords(pack_coords(coords))
    assert back.shape == coords.shape
    assert np.all(np.abs(back - coords) <= COORD_STEP_DEG / 2 + 1e-9)


def test_stored_footprints_match_the_truth_far_below_the_iou_scale(tmp_path):
    """A 1-3 km slick with a ragged boundary, stored and read back: IoU with the unquantised footprint
    over 0.99 (the committed set's worst case is 0.987, docs/forecaster-data.md)."""
    rng = np.random.default_rng(0)
    angles = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    geoms = []
    for radius in (1_000.0, 3_000.0):
        ring = radius * (1 + 0.1 * rng.standard_normal(200))
        geoms.append(to_lonlat(MultiPolygon([Polygon(np.column_stack([ring * np.cos(angles), ring * np.sin(angles)]))
                                             .buffer(0)])))
    s = Scenario(scenario_id="ragged-1", regime="steady", seed=1, release_time=datetime(2010, 4, 22, tzinfo=timezone.utc),
                 params={"seed": 1}, times_h=np.array([1.0, 2.0]), geometries=geoms, forcing=np.zeros((2, 5)))
    save_dataset([s], tmp_path / "ragged")
    (back,) = load_dataset(tmp_path / "ragged")
    for a, b in zip(geoms, back.geometries):
        b = make_valid(b)
        assert a.intersection(b).area / a.union(b).area > 0.99


def test_gulf_set_holds_steady_forcing_regimes_in_training_and_test(gulf):
    """Steady forcing in both parts of the split: the test split must hold what an outside evaluator's
    scenarios have, and training what the networks should learn from."""
    steady = [s for s in gulf if s.params.get("regime", "varying") != "varying"]
    held_out = [s for s in steady if s.params["region"] in HELD_OUT_REGIONS]
    training = [s for s in steady if s.params["region"] not in HELD_OUT_REGIONS]
    for part in (training, held_out):
        assert {s.regime for s in part} == set(STEADY_REGIMES) and len(part) >= 30
    assert all(s.params["method"] == HELD_OUT_METHOD for s in held_out)
    for s in steady:
        assert np.allclose(s.hourly_true[:, 2:4], s.hourly_true[0, 2:4])


def test_held_forcing_cases_are_what_the_public_api_builds_without_horizon_forcing(gulf):
    """``scenario_cases(held=True)``: the same observations and forcing rows, no forcing over the horizon,
    exactly the ``Observations`` that ``engine.prepare`` makes when no ``horizon_forcing`` is passed."""
    from oilspill_moos.forecaster import engine as E
    from oilspill_moos.forecaster.windows import scenario_cases

    s = gulf[0]
    ahead, held = (scenario_cases(s, stride=7, held=h) for h in (False, True))
    assert len(ahead) == len(held) > 0
    for a, h in zip(ahead, held):
        assert a.obs.forcing_ahead and not h.obs.forcing_ahead
        assert np.array_equal(a.obs.environments, h.obs.environments) and np.array_equal(a.obs.times_s, h.obs.times_s)
        assert np.array_equal(h.obs.track.times_s, h.obs.times_s) and np.array_equal(h.obs.track.values, h.obs.environments)
        assert np.allclose(h.obs.track.at(3600.0 * np.array([3, 15])), h.obs.environments[-1])
    case = held[0]
    public = E.prepare([case.obs.plane.to_lonlat(g) for g in case.obs.geometries],
                       [datetime(2026, 1, 1, tzinfo=timezone.utc).fromtimestamp(t + 1e9, timezone.utc) for t in case.obs.times_s],
                       case.obs.environments)
    assert not public.forcing_ahead
    assert np.array_equal(public.track.values, case.obs.track.values)
