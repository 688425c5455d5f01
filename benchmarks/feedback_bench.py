"""Feedback off vs on: does the fleet's oil sensing make the next forecast better?

    python benchmarks/feedback_bench.py [--scenarios N] [--standoff M] [--range M] [--samples N]

For each held-out scenario of the shipped weights, the satellite sees hours 1-17 and then nothing.
Forecast cycles are valid at hours 20, 24, 28, 32 (the model's 3/7/11/15 h horizons from hour
17). At each cycle the fleet circles the forecast's stand-off loop and samples the truth an hour
after the valid time (uFldOilSensor's model: oil within `--range` m, 2 % false positives, 5 % false
negatives, seed 0), `--samples` readings evenly along the loop.

* feedback off: every cycle is the satellite-only forecast (horizon 3, 7, 11, 15 h);
* feedback on: the readings re-anchor the forecast the fleet circled (forecaster/assimilate.py),
  the anchor is appended to the history, and the next cycle is a 3 h forecast from it.

Printed per cycle (means over scenarios): forecast IoU with the truth at its valid time, centroid
error (km), and the fraction of the true spill's perimeter that lies inside the fleet's loop.
Geometry is on the forecaster's equal-area plane in real metres (no map scale).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from oilspill_moos.forecaster.assimilate import SensorReadings, reanchor
from oilspill_moos.forecaster.dataset import load_dataset
from oilspill_moos.forecaster.features import plane_to_lonlat, to_plane
from oilspill_moos.forecaster.operational import Forecaster
from oilspill_moos.response.oil_sensor import SensorModel
from oilspill_moos.response.planner import containment_region

LAST_SATELLITE_H = 17
CYCLES_H = (20, 24, 28, 32)


def at_hour(scenario, hour: float):
    return scenario.geometries[int(np.searchsorted(scenario.times_h, hour))]


def figures(forecast, truth, standoff: float) -> dict[str, float]:
    f, t = to_plane(forecast), to_plane(truth)
    loop = containment_region(f, standoff)
    edge = t.boundary
    return {"iou": f.intersection(t).area / f.union(t).area,
            "centroid_km": f.centroid.distance(t.centroid) / 1e3,
            "perimeter_in_loop": edge.intersection(loop).length / edge.length}


def sample_loop(forecast, truth, standoff: float, sensor: SensorModel, samples: int, utc: float) -> SensorReadings:
    """The fleet's readings on one pass of the stand-off loop around `forecast` (truth: `truth`)."""
    loop = containment_region(to_plane(forecast), standoff).exterior
    xy = np.array([loop.interpolate(d).coords[0] for d in np.linspace(0, loop.length, samples, endpoint=False)])
    spill = to_plane(truth)
    oil = np.array([sensor.sense(spill, x, y)[0] for x, y in xy])
    lon, lat = plane_to_lonlat(xy[:, 0], xy[:, 1])
    return SensorReadings(np.asarray(lon), np.asarray(lat), oil, np.full(samples, sensor.range_m), np.full(samples, utc))


def run_scenario(forecaster: Forecaster, scenario, args) -> dict[str, list[dict]]:
    k = int(np.searchsorted(scenario.times_h, LAST_SATELLITE_H, side="right"))
    geometries, times, envs = scenario.geometries[:k], scenario.times()[:k], scenario.environments()[:k]
    satellite_only = forecaster.forecast(geometries, times, envs, scenario.release_time)
    sensor = SensorModel(range_m=args.range, false_positive=0.02, false_negative=0.05, seed=0)
    rows: dict[str, list[dict]] = {"off": [], "on": []}
    for cycle, valid_h in enumerate(CYCLES_H):
        truth = at_hour(scenario, valid_h)
        off = satellite_only[cycle]
        assert off.horizon_h == valid_h - LAST_SATELLITE_H
        rows["off"].append(figures(off.geometry, truth, args.standoff))
        on = off if cycle == 0 else forecaster.forecast(geometries, times, envs, scenario.release_time)[0]
        rows["on"].append(figures(on.geometry, truth, args.standoff))
        seen_h = valid_h + 1                      # the fleet is on the loop an hour after the valid time
        readings = sample_loop(on.geometry, at_hour(scenario, seen_h), args.standoff, sensor, args.samples,
                               scenario.release_time.timestamp() + 3600 * seen_h)
        geometries = [*geometries, reanchor(on.geometry, readings)]
        times = [*times, readings.time()]
        envs = [*envs, envs[-1]]
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", type=int, default=0, help="held-out scenarios to run (default: all)")
    parser.add_argument("--standoff", type=float, default=500.0, help="loop stand-off, m (default 500)")
    parser.add_argument("--range", type=float, default=750.0, help="sensor range, m (default 750)")
    parser.add_argument("--samples", type=int, default=90, help="readings per pass of the loop (default 90)")
    args = parser.parse_args(argv)
    started = time.monotonic()
    forecaster = Forecaster()
    held_out = [s for s in load_dataset() if s.scenario_id in forecaster.split["test"]
                and s.times_h[-1] >= CYCLES_H[-1] + 1]
    held_out = held_out[:args.scenarios] if args.scenarios > 0 else held_out
    results = [run_scenario(forecaster, s, args) for s in held_out]
    print(f"{len(held_out)} held-out scenarios, model {forecaster.kind}, stand-off {args.standoff:g} m, "
          f"sensor range {args.range:g} m, {args.samples} readings per loop")
    print(f"{'valid h':>7} {'IoU off':>8} {'IoU on':>8} {'centroid km off':>16} {'on':>6} "
          f"{'perimeter in loop off':>22} {'on':>6}  on better (IoU)")
    for cycle, valid_h in enumerate(CYCLES_H):
        mean = {mode: {key: statistics.fmean(r[mode][cycle][key] for r in results) for key in results[0][mode][0]}
                for mode in ("off", "on")}
        wins = sum(r["on"][cycle]["iou"] > r["off"][cycle]["iou"] + 1e-9 for r in results)
        print(f"{valid_h:>7} {mean['off']['iou']:>8.3f} {mean['on']['iou']:>8.3f} {mean['off']['centroid_km']:>16.2f} "
              f"{mean['on']['centroid_km']:>6.2f} {mean['off']['perimeter_in_loop']:>22.2f} "
              f"{mean['on']['perimeter_in_loop']:>6.2f}  {wins}/{len(results)}")
    print(f"done in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
