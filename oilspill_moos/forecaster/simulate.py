"""OpenDrift/OpenOil scenario generator: idealised forcing at the DWH site -> hourly spill polygons.

Each scenario draws its wind, current, horizontal diffusivity, oil type and release schedule from the
ranges of its regime (``REGIME_RANGES``) with its own seed, runs OpenOil offline (spatially uniform
forcing from ``reader_timeseries``, no downloads), and turns the surface particles of every hourly
output into a polygon with ``particles_to_polygon``: the highest-density region holding
``mass_fraction`` of the surface particles, from a Gaussian-smoothed particle histogram on the
equal-area plane. Multi-lobe slicks come out as MultiPolygons. OpenDrift is the optional ``[drift]``
extra; nothing else in the forecaster needs it.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time as clock
from datetime import datetime, timedelta, timezone
from pathlib import Path

import contourpy
import numpy as np
import shapely
from scipy.ndimage import gaussian_filter
from shapely.geometry import MultiPolygon, Polygon

from .dataset import DEFAULT_STEM, REGIMES, Scenario, save_dataset
from .features import DWH_LAT, DWH_LON, lonlat_to_plane, to_lonlat

# Polygon method parameters (recorded in the dataset JSON).
POLYGON_METHOD = {
    "name": "hdr-kde",
    "description": ("highest-density region of surface particles: 2-D histogram on the equal-area plane "
                    "(cell = max(min_cell_m, extent / grid_cells)), Gaussian smoothing of smoothing_cells, "
                    "filled contour at the density level enclosing mass_fraction of the particles "
                    "(contourpy), parts under min_part_fraction of the area dropped, simplified to half "
                    "a cell"),
    "mass_fraction": 0.9, "grid_cells": 80, "min_cell_m": 150.0, "smoothing_cells": 1.5,
    "min_part_fraction": 0.02, "surface_depth_m": 0.5, "min_particles": 40,
}

# Uniform ranges per regime. Directions are where wind/current blow *towards*, degrees clockwise from
# north. release: hours of continuous release, one pulse unless "second_pulse" is set.
REGIME_RANGES = {
    "initial_release": {"duration_h": (48, 48), "release_h": (48, 48), "wind_speed": (2.0, 7.0),
                        "current_speed": (0.02, 0.15), "diffusivity": (5.0, 20.0), "wind_veer_deg": (-20, 20)},
    "steady_growth": {"duration_h": (72, 72), "release_h": (24, 72), "wind_speed": (3.0, 7.0),
                      "current_speed": (0.05, 0.2), "diffusivity": (5.0, 20.0), "wind_veer_deg": (-15, 15)},
    "strong_forcing": {"duration_h": (60, 60), "release_h": (12, 36), "wind_speed": (10.0, 16.0),
                       "current_speed": (0.3, 0.7), "diffusivity": (10.0, 30.0), "wind_veer_deg": (-40, 40)},
    "multi_lobe": {"duration_h": (72, 72), "release_h": (6, 10), "second_pulse": (18, 30),
                   "wind_speed": (4.0, 9.0), "current_speed": (0.05, 0.25), "diffusivity": (5.0, 15.0),
                   "wind_shift_deg": (90, 180), "wind_veer_deg": (0, 0)},
    "dispersal": {"duration_h": (72, 72), "release_h": (2, 6), "wind_speed": (7.0, 12.0),
                  "current_speed": (0.05, 0.3), "diffusivity": (30.0, 80.0), "wind_veer_deg": (-30, 30),
                  "vertical_mixing": True},
}
OIL_TYPES = ("GENERIC LIGHT CRUDE", "GENERIC MEDIUM CRUDE", "SOUTH LOUISIANA", "GENERIC HEAVY CRUDE")
# Releases start between these dates (the spring of the real spill) at any hour.
RELEASE_WINDOW = (datetime(2010, 4, 20, tzinfo=timezone.utc), datetime(2010, 5, 31, tzinfo=timezone.utc))


def scenario_params(regime: str, seed: int) -> dict:
    """Draw one scenario's parameters from its regime's ranges (deterministic in ``seed``)."""
    if regime not in REGIME_RANGES:
        raise ValueError(f"unknown regime {regime!r}; known: {', '.join(REGIMES)}")
    ranges = REGIME_RANGES[regime]
    rng = np.random.default_rng(seed)

    def draw(key):
        lo, hi = ranges[key]
        return float(rng.uniform(lo, hi))

    span_h = (RELEASE_WINDOW[1] - RELEASE_WINDOW[0]).total_seconds() / 3600
    release = RELEASE_WINDOW[0] + timedelta(hours=int(rng.integers(0, int(span_h))))
    duration = int(draw("duration_h"))
    release_h = round(draw("release_h"), 1)
    pulses = [[0.0, release_h]]
    if "second_pulse" in ranges:
        start = round(draw("second_pulse"), 1)
        pulses.append([start, start + release_h])
    wind_dir = float(rng.uniform(0, 360))
    return {
        "regime": regime, "seed": seed, "release_time": release.isoformat().replace("+00:00", "Z"),
        "duration_h": duration, "pulses_h": pulses, "oil_type": str(rng.choice(OIL_TYPES)),
        "wind_speed": round(draw("wind_speed"), 2), "wind_dir_deg": round(wind_dir, 1),
        "wind_veer_deg": round(draw("wind_veer_deg"), 1),
        "wind_shift_deg": round(draw("wind_shift_deg"), 1) if "wind_shift_deg" in ranges else 0.0,
        "wind_shift_h": pulses[-1][0] - 2.0 if "second_pulse" in ranges else None,
        "wind_noise": 0.15,
        "current_speed": round(draw("current_speed"), 3), "current_dir_deg": round(float(rng.uniform(0, 360)), 1),
        "diffusivity": round(draw("diffusivity"), 1), "sea_temp_c": round(float(rng.uniform(25.0, 29.0)), 2),
        "vertical_mixing": bool(ranges.get("vertical_mixing", False)),
    }


def forcing_series(params: dict) -> np.ndarray:
    """Hourly [duration+2, 5] forcing (wind u/v, current u/v, temperature) of a scenario.

    Wind turns linearly by ``wind_veer_deg`` over the run, jumps by ``wind_shift_deg`` at
    ``wind_shift_h`` and carries AR(1) gusts of relative size ``wind_noise``.
    """
    hours = np.arange(params["duration_h"] + 2, dtype=float)
    rng = np.random.default_rng(params["seed"] + 7919)
    direction = params["wind_dir_deg"] + params["wind_veer_deg"] * hours / max(1, params["duration_h"])
    if params.get("wind_shift_h") is not None:
        direction = direction + np.where(hours >= params["wind_shift_h"], params["wind_shift_deg"], 0.0)
    gust = np.zeros_like(hours)
    for k in range(1, len(hours)):
        gust[k] = 0.8 * gust[k - 1] + rng.normal(0.0, params["wind_noise"])
    speed = params["wind_speed"] * np.clip(1.0 + gust, 0.3, None)
    rad, crad = np.radians(direction), math.radians(params["current_dir_deg"])
    return np.column_stack([
        speed * np.sin(rad), speed * np.cos(rad),
        np.full_like(hours, params["current_speed"] * math.sin(crad)),
        np.full_like(hours, params["current_speed"] * math.cos(crad)),
        np.full_like(hours, params["sea_temp_c"]),
    ])


def particles_to_polygon(x_m: np.ndarray, y_m: np.ndarray, method: dict = POLYGON_METHOD):
    """Highest-density-region polygon (equal-area metres) of one particle cloud, or None if too few."""
    x_m, y_m = np.asarray(x_m, float), np.asarray(y_m, float)
    if len(x_m) < method["min_particles"]:
        return None
    pad = 4 * method["smoothing_cells"]
    extent = max(np.ptp(x_m), np.ptp(y_m))
    cell = max(method["min_cell_m"], extent / method["grid_cells"])
    x_edges = np.arange(x_m.min() - pad * cell, x_m.max() + (pad + 1) * cell, cell)
    y_edges = np.arange(y_m.min() - pad * cell, y_m.max() + (pad + 1) * cell, cell)
    counts, _, _ = np.histogram2d(x_m, y_m, bins=[x_edges, y_edges])
    density = gaussian_filter(counts, method["smoothing_cells"])
    ordered = np.sort(density.ravel())[::-1]
    level = ordered[np.searchsorted(np.cumsum(ordered), method["mass_fraction"] * ordered.sum())]
    centres_x, centres_y = (x_edges[:-1] + x_edges[1:]) / 2, (y_edges[:-1] + y_edges[1:]) / 2
    generator = contourpy.contour_generator(centres_x, centres_y, density.T,
                                            fill_type=contourpy.FillType.OuterOffset)
    points, offsets = generator.filled(level, np.inf)
    parts = []
    for pts, offs in zip(points, offsets):
        rings = [pts[offs[i]:offs[i + 1]] for i in range(len(offs) - 1)]
        poly = shapely.make_valid(Polygon(rings[0], rings[1:]))
        parts.extend(p for p in shapely.get_parts(poly) if isinstance(p, Polygon))
    if not parts:
        return None
    largest = max(p.area for p in parts)
    parts = [p for p in parts if p.area >= method["min_part_fraction"] * largest]
    merged = shapely.union_all(parts).simplify(cell / 2)
    polys = [p for p in shapely.get_parts(merged) if isinstance(p, Polygon) and not p.is_empty]
    return MultiPolygon(polys) if polys else None


def run_scenario(params: dict, particles: int = 2000) -> Scenario:
    """Run OpenOil for one parameter set and convert each hourly output to a polygon."""
    from opendrift.models.openoil import OpenOil
    from opendrift.readers.reader_timeseries import Reader as TimeSeriesReader

    release = datetime.fromisoformat(params["release_time"].replace("Z", "+00:00"))
    naive_release = release.replace(tzinfo=None)  # OpenDrift works in naive UTC
    forcing = forcing_series(params)
    times = [naive_release + timedelta(hours=h) for h in range(len(forcing))]
    np.random.seed(params["seed"])  # OpenDrift draws from numpy's global generator
    model = OpenOil(loglevel=50, weathering_model="noaa")
    model.add_reader(TimeSeriesReader({
        "time": times, "x_wind": forcing[:, 0], "y_wind": forcing[:, 1],
        "x_sea_water_velocity": forcing[:, 2], "y_sea_water_velocity": forcing[:, 3],
        "sea_water_temperature": forcing[:, 4]}))
    model.set_config("environment:constant:horizontal_diffusivity", params["diffusivity"])
    model.set_config("drift:vertical_mixing", params["vertical_mixing"])
    per_pulse = particles // len(params["pulses_h"])
    for start_h, end_h in params["pulses_h"]:
        model.seed_elements(lon=DWH_LON, lat=DWH_LAT, z=0.0, radius=300.0, number=per_pulse,
                            time=[naive_release + timedelta(hours=start_h), naive_release + timedelta(hours=end_h)],
                            oil_type=params["oil_type"])
    model.run(duration=timedelta(hours=params["duration_h"]), time_step=900, time_step_output=3600)
    result = model.result
    lon, lat = result.lon.values, result.lat.values  # [particle, time]
    status, depth = result.status.values, result.z.values
    out_times = (result.time.values - np.datetime64(naive_release)) / np.timedelta64(1, "h")
    times_h, geometries, rows = [], [], []
    for k, hour in enumerate(out_times):
        surface = (status[:, k] == 0) & np.isfinite(lon[:, k]) & (depth[:, k] > -POLYGON_METHOD["surface_depth_m"])
        x, y = lonlat_to_plane(lon[surface, k], lat[surface, k])
        polygon = particles_to_polygon(np.asarray(x), np.asarray(y))
        if polygon is None:
            if geometries:
                break  # the slick has gone (weathered, dispersed or stranded): the sequence ends
            continue
        times_h.append(float(hour))
        geometries.append(to_lonlat(polygon))
        rows.append(forcing[int(round(hour))])
    return Scenario(scenario_id=f"{params['regime']}-{params['seed']}", regime=params["regime"],
                    seed=params["seed"], release_time=release, params=params,
                    times_h=np.asarray(times_h), geometries=geometries, forcing=np.asarray(rows))


def generation_plan(per_regime: int, base_seed: int, regimes=REGIMES) -> list[dict]:
    """Parameter sets in round-robin regime order, so any prefix covers every regime."""
    return [scenario_params(regime, base_seed + 100 * r + i)
            for i in range(per_regime) for r, regime in enumerate(REGIMES) if regime in regimes]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        prog="oilspill-forecaster simulate",
        description="Generate OpenDrift/OpenOil spill scenarios at the DWH site as hourly polygon sequences.")
    parser.add_argument("--output", type=Path, default=DEFAULT_STEM,
                        help="dataset path stem; writes STEM.npz and STEM.json (default: the packaged set)")
    parser.add_argument("--per-regime", type=int, default=12, help="scenarios per regime (default 12)")
    parser.add_argument("--particles", type=int, default=2000, help="particles per scenario (default 2000)")
    parser.add_argument("--seed", type=int, default=2010, help="base seed (default 2010)")
    parser.add_argument("--regimes", default=",".join(REGIMES), help="comma-separated subset of regimes")
    parser.add_argument("--min-observations", type=int, default=32,
                        help="drop scenarios with fewer hourly polygons than this (default 32)")
    args = parser.parse_args(argv)
    regimes = [r.strip() for r in args.regimes.split(",") if r.strip()]
    unknown = sorted(set(regimes) - set(REGIMES))
    if unknown:
        parser.error(f"unknown regime(s) {', '.join(unknown)}; known: {', '.join(REGIMES)}")
    try:
        import opendrift
    except ImportError:
        print("simulate needs OpenDrift: pip install 'oilspill-moos[drift]'", file=sys.stderr)
        return 2
    plan = generation_plan(args.per_regime, args.seed, regimes)
    generation = {"generator": "oilspill_moos.forecaster.simulate", "opendrift_version": opendrift.__version__,
                  "command": ["simulate", *(argv if argv is not None else sys.argv[1:])],
                  "base_seed": args.seed, "particles": args.particles, "per_regime": args.per_regime,
                  "polygon_method": POLYGON_METHOD, "regime_ranges": REGIME_RANGES, "oil_types": list(OIL_TYPES),
                  "dropped": []}
    scenarios = []
    for n, params in enumerate(plan, 1):
        started = clock.monotonic()
        scenario = run_scenario(params, args.particles)
        took = clock.monotonic() - started
        kept = len(scenario) >= args.min_observations
        if kept:
            scenarios.append(scenario)
        else:
            generation["dropped"].append({"scenario_id": scenario.scenario_id, "observations": len(scenario)})
        print(f"[{n}/{len(plan)}] {scenario.scenario_id}: {len(scenario)} hourly polygons, {took:.1f} s"
              f"{'' if kept else ' (dropped: too short)'}", flush=True)
        save_dataset(scenarios, args.output, generation)
    print(json.dumps({"scenarios": len(scenarios), "dropped": len(generation["dropped"]),
                      "output": str(args.output)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
