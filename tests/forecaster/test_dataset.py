"""The committed OpenOil scenario set: contents, provenance, round trip, and scenario-level splits."""
from datetime import datetime, timezone

import numpy as np
import pytest
from shapely.geometry import MultiPolygon, Point

from oilspill_moos.forecaster.dataset import (DEFAULT_STEM, REGIMES, Scenario, dataset_metadata, load_dataset,
                                              save_dataset, split_scenarios)
from oilspill_moos.forecaster.features import make_windows, to_lonlat


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


def test_features_and_windows_from_stored_scenarios(scenarios):
    sample = [next(s for s in scenarios if s.regime == r) for r in REGIMES]
    for s in sample:
        f = s.features()
        assert f.shape == (len(s), 25) and np.isfinite(f).all()
        assert f[:, 15] == pytest.approx(s.times_h)  # hours_since_release
    windows = make_windows([s.sequence() for s in sample], scale="hourly")
    assert len(windows) > 100 and set(windows.sequence) == set(range(len(sample)))


def test_split_is_by_scenario_with_every_regime_in_test(scenarios):
    split = split_scenarios(scenarios, seed=3)
    ids = split.ids()
    assert sorted(sum(ids.values(), [])) == sorted(s.scenario_id for s in scenarios)
    assert not (set(ids["train"]) & set(ids["test"])) and not (set(ids["val"]) & set(ids["test"]))
    assert {s.regime for s in split.test} == set(REGIMES) == {s.regime for s in split.train}
    assert split_scenarios(scenarios, seed=3).ids() == ids
    assert split_scenarios(scenarios, seed=4).ids() != ids
    with pytest.raises(ValueError):
        split_scenarios(scenarios, test_fraction=0.7, val_fraction=0.4)


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
