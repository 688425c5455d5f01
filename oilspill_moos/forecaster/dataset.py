"""The committed OpenDrift/OpenOil scenario set: storage, loading, and scenario-level splits.

One scenario is one simulated release at the Deepwater Horizon site: an hourly sequence of surface-oil
polygons (EPSG:4326) with the forcing that drove it. Polygons are stored as shapely ragged arrays in a
compressed ``.npz``; the generation parameters and seeds of every scenario sit beside it in a ``.json``
so the set can be regenerated (``oilspill-forecaster simulate``). Splits are by scenario, never by
window, so no hour of a test scenario is ever seen in training.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPolygon

from .features import Environment, feature_matrix

REGIMES = ("initial_release", "steady_growth", "strong_forcing", "multi_lobe", "dispersal")
DATA_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_STEM = DATA_DIR / "openoil_scenarios"
FORCING_COLUMNS = ("wind_u", "wind_v", "current_u", "current_v", "sea_temp_c")


@dataclass
class Scenario:
    """One simulated spill: hourly polygons (EPSG:4326), times in hours since release, forcing."""

    scenario_id: str
    regime: str
    seed: int
    release_time: datetime
    params: dict
    times_h: np.ndarray
    geometries: list
    forcing: np.ndarray  # [T, 5] FORCING_COLUMNS at each observation
    _features: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return len(self.times_h)

    def times(self) -> list[datetime]:
        return [self.release_time + timedelta(hours=float(h)) for h in self.times_h]

    def environments(self) -> list[Environment]:
        return [Environment(*map(float, row)) for row in self.forcing]

    def features(self, multipolygon: str = "largest") -> np.ndarray:
        """[T, 25] observation features (cached per multipolygon mode)."""
        if multipolygon not in self._features:
            self._features[multipolygon] = feature_matrix(
                self.geometries, self.times(), self.environments(), release_time=self.release_time,
                multipolygon=multipolygon)
        return self._features[multipolygon]

    def sequence(self, multipolygon: str = "largest") -> tuple[np.ndarray, np.ndarray]:
        """``(times_h, features)``: the form ``features.make_windows`` takes."""
        return self.times_h, self.features(multipolygon)


@dataclass
class DatasetSplit:
    train: list[Scenario]
    val: list[Scenario]
    test: list[Scenario]

    def ids(self) -> dict[str, list[str]]:
        return {name: [s.scenario_id for s in part] for name, part in
                (("train", self.train), ("val", self.val), ("test", self.test))}


def _iso(time: datetime) -> str:
    return time.astimezone(timezone.utc).isoformat().replace("+00:00", "Z")


def _parse_time(text: str) -> datetime:
    return datetime.fromisoformat(text.replace("Z", "+00:00")).astimezone(timezone.utc)


def save_dataset(scenarios: list[Scenario], stem: Path = DEFAULT_STEM, generation: dict | None = None) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` (geometry and forcing) and ``<stem>.json`` (parameters and seeds)."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    geoms = [g if isinstance(g, MultiPolygon) else MultiPolygon([g]) for s in scenarios for g in s.geometries]
    _, coords, offsets = shapely.to_ragged_array(geoms) if geoms else (None, np.empty((0, 2)), ())
    arrays = {
        "coords": np.asarray(coords, np.float32),
        "obs_scenario": np.concatenate([np.full(len(s), i, np.int32) for i, s in enumerate(scenarios)]),
        "obs_time_h": np.concatenate([np.asarray(s.times_h, np.float32) for s in scenarios]),
        "obs_forcing": np.vstack([np.asarray(s.forcing, np.float32) for s in scenarios]),
    }
    for k, off in enumerate(offsets):
        arrays[f"offsets{k}"] = np.asarray(off, np.int32)
    npz_path, json_path = stem.with_suffix(".npz"), stem.with_suffix(".json")
    np.savez_compressed(npz_path, **arrays)
    meta = dict(generation or {})
    meta["forcing_columns"] = list(FORCING_COLUMNS)
    meta["scenarios"] = [{"scenario_id": s.scenario_id, "regime": s.regime, "seed": s.seed,
                          "release_time": _iso(s.release_time), "observations": len(s),
                          "params": s.params} for s in scenarios]
    json_path.write_text(json.dumps(meta, indent=1) + "\n")
    return npz_path, json_path


def load_dataset(stem: Path | str | None = None) -> list[Scenario]:
    """The scenarios stored at ``stem`` (default: the committed set in ``forecaster/data``)."""
    stem = Path(stem) if stem is not None else DEFAULT_STEM
    npz_path, json_path = stem.with_suffix(".npz"), stem.with_suffix(".json")
    for path in (npz_path, json_path):
        if not path.exists():
            raise FileNotFoundError(f"{path}: dataset file missing (run `oilspill-forecaster simulate`)")
    meta = json.loads(json_path.read_text())
    with np.load(npz_path) as data:
        offsets = tuple(data[f"offsets{k}"] for k in range(3))
        geoms = shapely.from_ragged_array(shapely.GeometryType.MULTIPOLYGON,
                                          data["coords"].astype(float), offsets)
        obs_scenario, times_h, forcing = data["obs_scenario"], data["obs_time_h"], data["obs_forcing"]
    scenarios = []
    for i, info in enumerate(meta["scenarios"]):
        rows = np.flatnonzero(obs_scenario == i)
        if len(rows) != info["observations"]:
            raise ValueError(f"{npz_path}: scenario {info['scenario_id']} has {len(rows)} observations, "
                             f"{json_path.name} says {info['observations']}")
        scenarios.append(Scenario(
            scenario_id=info["scenario_id"], regime=info["regime"], seed=int(info["seed"]),
            release_time=_parse_time(info["release_time"]), params=info["params"],
            times_h=times_h[rows].astype(float), geometries=list(geoms[rows]),
            forcing=forcing[rows].astype(float)))
    return scenarios


def dataset_metadata(stem: Path | str | None = None) -> dict:
    """The generation record (``.json``) of a stored dataset."""
    stem = Path(stem) if stem is not None else DEFAULT_STEM
    return json.loads(stem.with_suffix(".json").read_text())


def split_scenarios(scenarios: list[Scenario], *, test_fraction: float = 0.25, val_fraction: float = 0.15,
                    seed: int = 0) -> DatasetSplit:
    """Stratified split by regime: every regime has at least one scenario in test (and, when it has
    three or more, one in validation); scenarios are shuffled with ``seed`` inside each regime."""
    if not 0 < test_fraction < 1 or not 0 <= val_fraction < 1 or test_fraction + val_fraction >= 1:
        raise ValueError("need 0 < test_fraction, 0 <= val_fraction and test + val < 1")
    rng = np.random.default_rng(seed)
    train, val, test = [], [], []
    by_regime: dict[str, list[Scenario]] = {}
    for s in scenarios:
        by_regime.setdefault(s.regime, []).append(s)
    for regime in sorted(by_regime):
        group = sorted(by_regime[regime], key=lambda s: s.scenario_id)
        group = [group[i] for i in rng.permutation(len(group))]
        n_test = max(1, round(test_fraction * len(group)))
        n_val = max(1 if len(group) >= 3 else 0, round(val_fraction * len(group)))
        n_val = min(n_val, len(group) - n_test - 1) if len(group) > n_test else 0
        test += group[:n_test]
        val += group[n_test:n_test + n_val]
        train += group[n_test + n_val:]
    return DatasetSplit(train=train, val=val, test=test)
