"""The committed OpenDrift/OpenOil scenario set: storage, loading, and scenario-level splits.

One scenario is one simulated release: an hourly sequence of surface-oil polygons (EPSG:4326) with the
forcing that drove it. Polygons are stored as shapely ragged arrays in a compressed ``.npz``, vertices
quantised to ``COORD_STEP_DEG`` and delta-encoded (``pack_coords``), LZMA-compressed; the generation parameters and seeds of every scenario sit beside it in a ``.json``
so the set can be regenerated (``oilspill-forecaster simulate``). Splits are by scenario, never by
window, so no hour of a test scenario is ever seen in training.
"""
from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon

from .features import DWH_LAT, DWH_LON, Environment, local_frame

REGIMES = ("initial_release", "steady_growth", "strong_forcing", "multi_lobe", "dispersal")
DATA_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_STEM = DATA_DIR / "openoil_scenarios"      # the first set, all released at the DWH wellhead
GULF_STEM = DATA_DIR / "gulf_scenarios"            # the training/evaluation set (simulate.py)
# The out-of-distribution test split: releases in these regions, footprints by this method, never trained on.
HELD_OUT_REGIONS = ("west", "dwh")
HELD_OUT_METHOD = "alpha-shape"
FORCING_COLUMNS = ("wind_u", "wind_v", "current_u", "current_v", "sea_temp_c")
# Stored vertices are rounded to this grid (5e-5 deg: 5.6 m north-south, under 5 m east-west in the
# Gulf), far below the IoU scale of a km-sized slick (docs/forecaster-data.md gives the measured effect).
COORD_STEP_DEG = 5e-5


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
    forcing: np.ndarray  # [T, 5] FORCING_COLUMNS at each observation (the forcing a forecaster is given)
    hourly_given: np.ndarray | None = None   # [H, 5] given forcing every hour from the release (Gulf set)
    hourly_true: np.ndarray | None = None    # [H, 5] the forcing that moved the oil (Gulf set)

    def __len__(self) -> int:
        return len(self.times_h)

    def times(self) -> list[datetime]:
        return [self.release_time + timedelta(hours=float(h)) for h in self.times_h]

    def environments(self) -> list[Environment]:
        return [Environment(*map(float, row)) for row in self.forcing]

    def observed(self, seed: int = 0, noise: bool = True) -> tuple[np.ndarray, list]:
        """(indices, geometries) of what a satellite would have given: each hour missing with a
        probability drawn per scenario from 0-40 % (so intervals are irregular; first and last hours
        kept), every boundary vertex jittered by a per-scenario 0-3 % of the footprint's size, then
        repaired (``make_valid``'s "structure" method: the area the rings enclose, in a third of the
        "linework" method's time on these self-crossing rings). Deterministic in (scenario seed,
        ``seed``); ``noise=False`` gives the clean truth."""
        if not noise:
            return np.arange(len(self)), list(self.geometries)
        rng = np.random.default_rng([self.seed, seed])
        missing, jitter = rng.uniform(0.0, 0.4), rng.uniform(0.0, 0.03)
        keep = rng.random(len(self)) >= missing
        keep[0] = keep[-1] = True
        index = np.flatnonzero(keep)
        to_local, to_lonlat = local_frame(float(self.params.get("lon", DWH_LON)), float(self.params.get("lat", DWH_LAT)))
        out = []
        for i in index:
            plane = shapely.transform(self.geometries[i], lambda xy: np.column_stack(to_local(xy[:, 0], xy[:, 1])))
            size = math.sqrt(plane.area)
            jittered = MultiPolygon([_jittered(p, rng, jitter * size) for p in shapely.get_parts(plane)])
            noisy = shapely.make_valid(jittered, method="structure", keep_collapsed=False)
            noisy = MultiPolygon([p for p in shapely.get_parts(noisy) if p.geom_type == "Polygon"]
                                 or list(shapely.get_parts(plane)))
            out.append(shapely.transform(noisy, lambda xy: np.column_stack(to_lonlat(xy[:, 0], xy[:, 1]))))
        return index, out


def _jittered(polygon: Polygon, rng: np.random.Generator, sigma: float) -> Polygon:
    """``polygon`` with every vertex moved by Gaussian noise of ``sigma`` (rings kept closed)."""
    def ring(coords):
        xy = np.asarray(coords)[:-1]
        xy = xy + rng.normal(0.0, sigma, xy.shape)
        return np.vstack([xy, xy[:1]])
    return Polygon(ring(polygon.exterior.coords), [ring(r.coords) for r in polygon.interiors])


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


def pack_coords(coords: np.ndarray, step: float = COORD_STEP_DEG) -> dict[str, np.ndarray]:
    """Vertices [N, 2] -> arrays that compress well: rounded to ``step``, each the difference from the
    one before, split into low and high bytes of int16 (the rare larger jumps, between scenarios, kept
    apart as int64)."""
    grid = np.round(np.asarray(coords, float) / step).astype(np.int64)
    delta = np.diff(grid, axis=0, prepend=np.zeros((1, 2), np.int64))
    large = np.abs(delta).max(axis=1) > np.iinfo(np.int16).max if len(delta) else np.zeros(0, bool)
    small = np.where(large[:, None], 0, delta).astype(np.int16).view(np.uint16)
    return {"coord_step": np.array(step), "coord_low": (small & 0xFF).astype(np.uint8),
            "coord_high": (small >> 8).astype(np.uint8), "coord_large_at": np.flatnonzero(large).astype(np.int64),
            "coord_large": delta[large]}


def unpack_coords(data) -> np.ndarray:
    """The inverse of ``pack_coords`` (to within half a step)."""
    delta = (data["coord_low"].astype(np.uint16) | (data["coord_high"].astype(np.uint16) << 8)).view(np.int16).astype(np.int64)
    delta[data["coord_large_at"]] = data["coord_large"]
    return np.cumsum(delta, axis=0) * float(data["coord_step"])


def _write_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """An ``.npz`` (readable by ``np.load``) with LZMA members: a third smaller than ``savez_compressed``."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_LZMA) as archive:
        for name, array in arrays.items():
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, np.asarray(array), allow_pickle=False)
            archive.writestr(f"{name}.npy", buffer.getvalue())


def save_dataset(scenarios: list[Scenario], stem: Path = DEFAULT_STEM, generation: dict | None = None) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` (geometry and forcing) and ``<stem>.json`` (parameters and seeds)."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    geoms = [g if isinstance(g, MultiPolygon) else MultiPolygon([g]) for s in scenarios for g in s.geometries]
    _, coords, offsets = shapely.to_ragged_array(geoms) if geoms else (None, np.empty((0, 2)), ())
    arrays = {
        **pack_coords(coords),
        "obs_scenario": np.concatenate([np.full(len(s), i, np.int32) for i, s in enumerate(scenarios)]),
        "obs_time_h": np.concatenate([np.asarray(s.times_h, np.float32) for s in scenarios]),
        "obs_forcing": np.vstack([np.asarray(s.forcing, np.float32) for s in scenarios]),
    }
    for k, off in enumerate(offsets):
        arrays[f"counts{k}"] = np.diff(np.asarray(off, np.int64)).astype(np.int32)
    if scenarios and scenarios[0].hourly_given is not None:
        arrays["hourly_scenario"] = np.concatenate([np.full(len(s.hourly_given), i, np.int32)
                                                    for i, s in enumerate(scenarios)])
        arrays["hourly_given"] = np.vstack([np.asarray(s.hourly_given, np.float32) for s in scenarios])
        arrays["hourly_true"] = np.vstack([np.asarray(s.hourly_true, np.float32) for s in scenarios])
    npz_path, json_path = stem.with_suffix(".npz"), stem.with_suffix(".json")
    _write_npz(npz_path, arrays)
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
        if "coords" in data:    # the first set's layout: float32 vertices, offsets
            coords, offsets = data["coords"].astype(float), tuple(data[f"offsets{k}"] for k in range(3))
        else:
            coords = unpack_coords(data)
            offsets = tuple(np.concatenate([[0], np.cumsum(data[f"counts{k}"], dtype=np.int64)]) for k in range(3))
        geoms = shapely.from_ragged_array(shapely.GeometryType.MULTIPOLYGON, coords, offsets)
        obs_scenario, times_h, forcing = data["obs_scenario"], data["obs_time_h"], data["obs_forcing"]
        hourly = {k: data[k] for k in ("hourly_scenario", "hourly_given", "hourly_true") if k in data}
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
            forcing=forcing[rows].astype(float),
            **({k: hourly[k][hourly["hourly_scenario"] == i].astype(float) for k in ("hourly_given", "hourly_true")}
               if hourly else {})))
    return scenarios


def dataset_metadata(stem: Path | str | None = None) -> dict:
    """The generation record (``.json``) of a stored dataset."""
    stem = Path(stem) if stem is not None else DEFAULT_STEM
    return json.loads(stem.with_suffix(".json").read_text())


def split_scenarios(scenarios: list[Scenario], *, val_fraction: float = 0.15, seed: int = 0) -> DatasetSplit:
    """Out-of-distribution split by construction: test = every scenario released in a held-out region
    or drawn with the held-out footprint method (``HELD_OUT_REGIONS``, ``HELD_OUT_METHOD``); the rest
    is shuffled with ``seed`` and ``val_fraction`` of it kept for validation and calibration."""
    if not 0 <= val_fraction < 1:
        raise ValueError("need 0 <= val_fraction < 1")
    test = [s for s in scenarios if s.params.get("region") in HELD_OUT_REGIONS or s.params.get("method") == HELD_OUT_METHOD]
    rest = sorted((s for s in scenarios if s not in test), key=lambda s: s.scenario_id)
    rest = [rest[i] for i in np.random.default_rng(seed).permutation(len(rest))]
    n_val = round(val_fraction * len(rest))
    return DatasetSplit(train=rest[n_val:], val=rest[:n_val], test=test)
