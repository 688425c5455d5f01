"""Feedback off vs on, on the out-of-distribution held-out split: does the fleet's oil sensing make the
next forecast better?

    python benchmarks/feedback_bench.py [--model KIND] [--scenarios N] [--standoff M] [--range M] [--samples N]

For each held-out Gulf scenario the satellite sees (noisy) observations up to hour 17 and then nothing;
the forecaster is given the scenario's erroneous forcing. Forecast cycles are valid at hours 20, 24, 28,
32 (3/7/11/15 h from hour 17). At each cycle the fleet circles the forecast's stand-off loop an hour
after its valid time and samples the truth (uFldOilSensor's model: oil within ``--range`` m, 2 % false
positives, 5 % false negatives, seed 0), ``--samples`` readings evenly along the loop.

* feedback off: every cycle is the satellite-only forecast (horizon 3, 7, 11, 15 h);
* feedback on: the readings re-anchor the forecast the fleet circled (forecaster/assimilate.py, as the
  operational loop does: ``RESCALE``), the anchor is appended to the history, and the next cycle is a
  3 h forecast from it.

Printed per cycle: mean IoU with the truth off and on, the gain (on - off) with a paired bootstrap 95 %
CI over scenarios, and the centroid errors. Geometry is on each scenario's own equal-area plane.
"""
from __future__ import annotations

import argparse
import sys
import time
from datetime import timedelta

import numpy as np
import shapely

from oilspill_moos.forecaster import features as F
from oilspill_moos.forecaster.assimilate import SensorReadings, reanchored_history
from oilspill_moos.forecaster.dataset import GULF_STEM, load_dataset, split_scenarios
from oilspill_moos.forecaster.evaluate import bootstrap_ci, iou
from oilspill_moos.forecaster.kinds import DEFAULT_MODEL, KINDS
from oilspill_moos.forecaster.operational import Forecaster
from oilspill_moos.response.oil_sensor import SensorModel
from oilspill_moos.response.planner import containment_region

LAST_SATELLITE_H = 17
CYCLES_H = (20, 24, 28, 32)


def run_scenario(forecaster: Forecaster, scenario, args) -> dict[str, list[tuple[float, float]]]:
    """(IoU, centroid km) per cycle, off and on."""
    index, observed = scenario.observed(seed=0)
    keep = scenario.times_h[index] <= LAST_SATELLITE_H
    times_all = scenario.times()
    geometries = [g for g, k in zip(observed, keep) if k]
    times = [times_all[i] for i, k in zip(index, keep) if k]
    release = scenario.release_time

    def env(hour: float) -> F.Environment:
        return F.Environment(*map(float, scenario.hourly_given[int(hour)]))

    def ahead(hour: float):
        return [(release + timedelta(hours=hour + k), env(hour + k)) for k in range(1, 16)]

    def hour_of(t):
        return (t - release).total_seconds() / 3600

    envs = [env(hour_of(t)) for t in times]
    plane = F.SpillPlane.about(scenario.geometries[0])
    satellite_only = forecaster.forecast(geometries, times, envs, horizon_forcing=ahead(hour_of(times[-1])))
    sensor = SensorModel(range_m=args.range, false_positive=0.02, false_negative=0.05, seed=0)
    rows: dict[str, list] = {"off": [], "on": []}
    for cycle, valid_h in enumerate(CYCLES_H):
        truth = plane.to_plane(scenario.geometries[int(np.searchsorted(scenario.times_h, valid_h))])
        off = satellite_only[cycle]
        on = off if cycle == 0 else forecaster.forecast(geometries, times, envs, horizon_forcing=ahead(hour_of(times[-1])))[0]
        for mode, f in (("off", off), ("on", on)):
            g = plane.to_plane(f.geometry)
            rows[mode].append((iou(g, truth), g.centroid.distance(truth.centroid) / 1e3))
        seen_h = valid_h + 1                      # the fleet is on the loop an hour after the valid time
        seen = plane.to_plane(scenario.geometries[int(np.searchsorted(scenario.times_h, seen_h))])
        loop = containment_region(plane.to_plane(on.geometry), args.standoff).exterior
        xy = np.array([loop.interpolate(d).coords[0] for d in np.linspace(0, loop.length, args.samples, endpoint=False)])
        oil = np.array([sensor.sense(seen, x, y)[0] for x, y in xy])
        lonlat = shapely.get_coordinates(plane.to_lonlat(shapely.MultiPoint(xy)))
        readings = SensorReadings(lonlat[:, 0], lonlat[:, 1], oil, np.full(args.samples, sensor.range_m),
                                  np.full(args.samples, release.timestamp() + 3600 * seen_h))
        prior = forecaster.forecast(geometries, times, envs, horizon_forcing=ahead(hour_of(times[-1])),
                                    horizons_h=(seen_h - hour_of(times[-1]),))[0]
        geometries = reanchored_history(geometries, prior.geometry, readings)
        times = [*times, readings.time()]
        envs = [*envs, env(seen_h)]
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", choices=KINDS, default=DEFAULT_MODEL)
    parser.add_argument("--scenarios", type=int, default=0, help="held-out scenarios to run (default: all)")
    parser.add_argument("--standoff", type=float, default=500.0, help="loop stand-off, m (default 500)")
    parser.add_argument("--range", type=float, default=750.0, help="sensor range, m (default 750)")
    parser.add_argument("--samples", type=int, default=90, help="readings per pass of the loop (default 90)")
    args = parser.parse_args(argv)
    started = time.monotonic()
    forecaster = Forecaster(kind=args.model)
    held_out = [s for s in split_scenarios(load_dataset(GULF_STEM)).test if s.times_h[-1] >= CYCLES_H[-1] + 1]
    held_out = held_out[:args.scenarios] if args.scenarios > 0 else held_out
    results = [run_scenario(forecaster, s, args) for s in held_out]
    print(f"{len(held_out)} out-of-distribution held-out scenarios, model {forecaster.kind}, stand-off "
          f"{args.standoff:g} m, sensor range {args.range:g} m, {args.samples} readings per loop")
    print(f"{'valid h':>7} {'IoU off':>8} {'IoU on':>8} {'gain [95 % CI]':>26} {'centroid km off':>16} {'on':>6}  on better")
    for cycle, valid_h in enumerate(CYCLES_H):
        off = np.array([r["off"][cycle] for r in results])
        on = np.array([r["on"][cycle] for r in results])
        gain, lo, hi = bootstrap_ci(on[:, 0] - off[:, 0])
        wins = int((on[:, 0] > off[:, 0] + 1e-9).sum())
        print(f"{valid_h:>7} {off[:, 0].mean():>8.3f} {on[:, 0].mean():>8.3f} {f'{gain:+.3f} [{lo:+.3f}, {hi:+.3f}]':>26} "
              f"{off[:, 1].mean():>16.2f} {on[:, 1].mean():>6.2f}  {wins}/{len(results)}")
    print(f"done in {time.monotonic() - started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
