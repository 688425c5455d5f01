"""The forecaster on the founding OpenOil set, through the public API, as an outside evaluator would.

    python benchmarks/forecaster_regime_bench.py [--kinds K,K,...] [--every N] [--weights DIR]

That set (`forecaster/data/openoil_scenarios`, 60 scenarios) was never trained on: releases at the
Deepwater Horizon wellhead, the paper's five regimes (initial release, steady growth, dispersal,
multi-lobe, strong forcing), HDR-KDE footprints, constant forcing per observation and no forcing over
the horizon (the forecaster holds the last). Each case is `Forecaster(kind).forecast()` on up to 16
hourly observations, scored against the true footprint 3/7/11/15 h on. It prints, per kind, the mean
IoU and centroid error over scenarios with a bootstrap 95 % CI, ltc-fused minus every other kind (paired CI), the mean
log area ratio forecast/truth (how much each kind over- or under-grows the slick) and the 15 h IoU per
regime. Asserts nothing; the figures are in docs/forecaster.md.
"""
from __future__ import annotations

import argparse
import math
import warnings
from pathlib import Path

import numpy as np
import shapely
from shapely.ops import transform

from oilspill_moos.forecaster import dataset as D
from oilspill_moos.forecaster.evaluate import bootstrap_ci, paired_ci
from oilspill_moos.forecaster.operational import Forecaster
from oilspill_moos.forecaster.train import WEIGHTS_DIR

HORIZONS_H = (3, 7, 11, 15)
DEFAULT_KINDS = ("ltc-fused", "ltc-rk4", "ltc-euler", "lstm", "persistence", "constant-velocity",
                 "constant-velocity-growth", "physics", "physics-corrected")


def to_plane(geometry, lon0: float, lat0: float):
    """Metres about (lon0, lat0) on a local equirectangular plane: enough for the ratio of two areas."""
    scale_x = 111_320.0 * math.cos(math.radians(lat0))
    return transform(lambda x, y, z=None: ((np.asarray(x) - lon0) * scale_x, (np.asarray(y) - lat0) * 110_540.0),
                     shapely.make_valid(geometry))


def score_scenario(scenario, forecasters: dict, every: int) -> dict:
    """kind -> [cases, horizons, (IoU, log area ratio, centroid error km)] for the anchors of one scenario."""
    hours = np.asarray(scenario.times_h, float)
    times, environments = scenario.times(), scenario.environments()
    origin = scenario.geometries[0].centroid
    out = {kind: [] for kind in forecasters}
    for anchor in range(6, len(hours), every):
        truth = {}
        for h in HORIZONS_H:
            match = np.flatnonzero(np.isclose(hours, hours[anchor] + h))
            if match.size:
                truth[h] = to_plane(scenario.geometries[match[0]], origin.x, origin.y)
        if len(truth) < len(HORIZONS_H):
            continue
        first = max(0, anchor - 15)
        for kind, forecaster in forecasters.items():
            row = []
            for forecast in forecaster.forecast(scenario.geometries[first:anchor + 1], times[first:anchor + 1],
                                                environments[first:anchor + 1]):
                true, guess = truth[round(forecast.horizon_h)], to_plane(forecast.geometry, origin.x, origin.y)
                union = guess.union(true).area
                row.append((guess.intersection(true).area / union if union > 0 else 0.0,
                            math.log(max(guess.area, 1.0) / max(true.area, 1.0)),
                            guess.centroid.distance(true.centroid) / 1e3))
            out[kind].append(row)
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kinds", default=",".join(DEFAULT_KINDS), help="comma-separated kinds; ltc-fused first")
    parser.add_argument("--every", type=int, default=5, help="an anchor every N observations (default 5)")
    parser.add_argument("--weights", type=Path, default=WEIGHTS_DIR, help="weights directory (default: shipped)")
    args = parser.parse_args(argv)
    warnings.filterwarnings("ignore")
    kinds = args.kinds.split(",")
    forecasters = {kind: Forecaster(args.weights, kind) for kind in kinds}
    scenarios = D.load_dataset(D.DEFAULT_STEM)
    per_case = {kind: {} for kind in kinds}
    for number, scenario in enumerate(scenarios, 1):
        for kind, rows in score_scenario(scenario, forecasters, args.every).items():
            if rows:
                per_case[kind][scenario.scenario_id] = np.asarray(rows)
        print(f"\r{number}/{len(scenarios)} scenarios", end="", flush=True)
    ids = sorted(per_case[kinds[0]])
    means = {kind: np.array([per_case[kind][i].mean(axis=0) for i in ids]) for kind in kinds}   # [S, H, 3]
    cases = sum(len(per_case[kinds[0]][i]) for i in ids)
    print(f"\n{len(ids)} scenarios, {cases} cases per horizon; IoU at {' / '.join(map(str, HORIZONS_H))} h, "
          "mean over scenarios [bootstrap 95 % CI]")
    for kind in kinds:
        cells = (bootstrap_ci(means[kind][:, h, 0]) for h in range(len(HORIZONS_H)))
        print(f"  {kind:26s}", "  ".join(f"{m:.3f} [{lo:.3f}, {hi:.3f}]" for m, lo, hi in cells))
    print(f"{kinds[0]} minus each kind, IoU (paired 95 % CI over scenarios)")
    for kind in kinds[1:]:
        cells = (paired_ci(means[kinds[0]][:, h, 0], means[kind][:, h, 0]) for h in range(len(HORIZONS_H)))
        print(f"  {kind:26s}", "  ".join(f"{m:+.3f} [{lo:+.3f}, {hi:+.3f}]" for m, lo, hi in cells))
    print("centroid error (km), mean over scenarios [bootstrap 95 % CI]")
    for kind in kinds:
        cells = (bootstrap_ci(means[kind][:, h, 2]) for h in range(len(HORIZONS_H)))
        print(f"  {kind:26s}", "  ".join(f"{m:.2f} [{lo:.2f}, {hi:.2f}]" for m, lo, hi in cells))
    print("mean log area ratio forecast/truth (0 = right size, +0.69 = twice the area)")
    for kind in kinds:
        print(f"  {kind:26s}", " / ".join(f"{means[kind][:, h, 1].mean():+.2f}" for h in range(len(HORIZONS_H))))
    print(f"IoU at {HORIZONS_H[-1]} h per regime")
    for regime in sorted({i.rsplit("-", 1)[0] for i in ids}):
        rows = [n for n, i in enumerate(ids) if i.rsplit("-", 1)[0] == regime]
        print(f"  {regime:16s}", "  ".join(f"{kind} {means[kind][rows, -1, 0].mean():.2f}" for kind in kinds))


if __name__ == "__main__":
    main()
