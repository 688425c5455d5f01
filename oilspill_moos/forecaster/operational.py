"""The operational forecaster: latest observations -> boundaries 3/7/11/15 h ahead -> pPathAssign.

Observations come from a directory of polygon files (GeoJSON or ESRI shapefiles, one observation per
file, its time from a ``time`` property or the file name), re-read every ``--interval`` seconds; a
new latest observation triggers a forecast and a push of one boundary line per horizon. Without
``--observations`` the loop replays a held-out scenario of the shipped dataset, one hour per
interval, so the process runs anywhere out of the box.

Forcing that the files do not carry (wind, current, sea temperature) is taken as the training mean
unless given with ``--wind``/``--current``/``--sea-temp``.
"""
from __future__ import annotations

import argparse
import asyncio
import math
import sys
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import torch

from . import features as F
from .assimilate import ingest, read_feedback
from .boundary import outline, rebuild_boundary
from .evaluate import make_targets_consistent
from .models import KINDS
from .push import DEFAULT_HOST, DEFAULT_PORT, BoundaryPusher, PushRejected, PushUnreachable, boundary_line
from .train import WEIGHTS_DIR, DeltaScaler, load_checkpoint

# Fused: unconditionally stable, so irregular (hours to days) gaps between observations cannot blow it up.
DEFAULT_MODEL = "ltc-fused"
POLYGON_SUFFIXES = (".geojson", ".json", ".shp")


@dataclass
class Forecast:
    horizon_h: float
    geometry: object             # EPSG:4326
    uncertainty_m: float
    source: str
    valid_time: datetime

    def line(self) -> bytes:
        return boundary_line(outline(self.geometry), self.horizon_h, time=self.valid_time.timestamp(),
                             uncertainty_m=self.uncertainty_m, source=self.source)


class Forecaster:
    """Shipped weights + their scalers: geometries and times in, one Forecast per horizon out."""

    def __init__(self, weights_dir: Path = WEIGHTS_DIR, kind: str = DEFAULT_MODEL):
        if kind not in KINDS:
            raise ValueError(f"--model must be one of {KINDS}, not {kind!r}")
        self.kind = kind
        self.model, blob = load_checkpoint(Path(weights_dir) / f"{kind}.pt")
        extra = blob["extra"]
        self.feature_scaler = F.FeatureScaler.from_dict(extra["feature_scaler"])
        self.delta_scaler = DeltaScaler.from_dict(extra["delta_scaler"])
        self.target_names = tuple(extra["target_names"])
        self.horizons_h = tuple(extra["horizons_h"])
        self.multipolygon = extra.get("multipolygon", "largest")
        self.split = extra["split"]
        self.target_cols = [F.FEATURE_INDEX[n] for n in self.target_names]

    def mean_environment(self) -> F.Environment:
        return F.Environment(*(float(self.feature_scaler.mean[F.FEATURE_INDEX[n]]) for n in F.ENVIRONMENT_FEATURES))

    @torch.no_grad()
    def forecast(self, geometries, times, environments=None, release_time: datetime | None = None) -> list[Forecast]:
        """Forecast from observations in time order (at least two: shorter windows are trend-padded)."""
        if len(geometries) == 0:
            raise ValueError("no observations to forecast from")
        if len(geometries) != len(times):
            raise ValueError(f"{len(geometries)} geometries but {len(times)} times")
        if len(geometries) < 2:
            raise ValueError("one observation gives no trend to pad the 16-step window with; need at least 2")
        if environments is None:
            environments = [self.mean_environment()] * len(geometries)
        release_time = release_time or times[0]
        feats = F.feature_matrix(geometries, times, environments, release_time=release_time,
                                 multipolygon=self.multipolygon)
        times_h = np.array([(t - release_time).total_seconds() / 3600 for t in times])
        window, elapsed, _ = F.latest_window(times_h, feats)
        x = torch.as_tensor(self.feature_scaler.transform(window)[None], dtype=torch.float32)
        dt = torch.as_tensor(elapsed[None], dtype=torch.float32)
        mean, sigma = (t.numpy() for t in self.model(x, dt))
        if not (np.isfinite(mean).all() and np.isfinite(sigma).all()):
            raise ValueError(f"{self.kind} diverged on this window (steps of up to {elapsed.max():g} h between "
                             "observations, integrated in a fixed number of sub-steps); the fused solver stays "
                             "bounded for any step: use --model ltc-fused")
        last = window[-1:, self.target_cols]
        targets = make_targets_consistent(self.delta_scaler.inverse_transform(last, mean), self.target_cols)[0]
        spread_km = sigma[0] * self.delta_scaler.std                                  # [H, K] in target units
        ix, iy = self.target_names.index("centroid_x_km"), self.target_names.index("centroid_y_km")
        return [Forecast(horizon_h=float(h), geometry=rebuild_boundary(geometries[-1], targets[j], names=self.target_names,
                                                                       multipolygon=self.multipolygon),
                         uncertainty_m=1e3 * math.hypot(spread_km[j, ix], spread_km[j, iy]), source=self.kind,
                         valid_time=times[-1] + timedelta(hours=float(h)))
                for j, h in enumerate(self.horizons_h)]


# ---------------------------------------------------------------------------------------------------
# Observation sources

def read_observation_dir(directory: Path):
    """(geometries, times) of every polygon file in ``directory``, in time order."""
    from .readers import PolygonFileError, read_polygons

    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"{directory}: observation directory does not exist")
    observations = []
    for path in sorted(p for p in directory.iterdir() if p.suffix.lower() in POLYGON_SUFFIXES):
        observation = read_polygons(path)
        if observation.time is None:
            raise PolygonFileError(path, "no observation time (give a 'time' property or a date in the file name)")
        observations.append((observation.time, observation.geometry))
    observations.sort(key=lambda o: o[0])
    return [g for _, g in observations], [t for t, _ in observations]


class ScenarioReplay:
    """A held-out scenario of the shipped dataset, revealed one observation per call."""

    def __init__(self, scenario, start_index: int = 16):
        self.scenario = scenario
        self.index = min(start_index, len(scenario) - 1)

    def latest(self):
        s, k = self.scenario, self.index + 1
        self.index = min(self.index + 1, len(s) - 1)
        return s.geometries[:k], s.times()[:k], s.environments()[:k], s.release_time


def default_replay(forecaster: Forecaster) -> ScenarioReplay:
    from .dataset import load_dataset

    test_ids = forecaster.split["test"]
    scenarios = [s for s in load_dataset() if s.scenario_id in test_ids]
    if not scenarios:
        raise ValueError("the shipped dataset holds none of the weights' test scenarios")
    return ScenarioReplay(max(scenarios, key=len))


# ---------------------------------------------------------------------------------------------------
# The loop

def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(prog="python -m oilspill_moos.forecaster")
    parser.add_argument("--observations", type=Path,
                        help="directory of polygon files to watch (default: replay a held-out shipped scenario)")
    parser.add_argument("--once", action="store_true", help="forecast and push once, then exit")
    parser.add_argument("--host", default=DEFAULT_HOST, help="pPathAssign host (default: %(default)s)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="pPathAssign port (default: %(default)s)")
    parser.add_argument("--model", choices=KINDS, default=DEFAULT_MODEL, help="default: %(default)s")
    parser.add_argument("--weights", type=Path, default=WEIGHTS_DIR, help="weights directory (default: shipped)")
    parser.add_argument("--interval", type=float, default=60.0, help="seconds between polls (default: %(default)s)")
    parser.add_argument("--connect-timeout", type=float, default=30.0,
                        help="seconds to keep retrying pPathAssign (default: %(default)s)")
    parser.add_argument("--wind", type=_pair, help="u,v m/s when the files carry no forcing")
    parser.add_argument("--current", type=_pair, help="u,v m/s when the files carry no forcing")
    parser.add_argument("--sea-temp", type=float, help="sea temperature in °C when the files carry none")
    parser.add_argument("--feedback", type=Path, help="observations file of uFldOilFusion: re-anchor the last "
                        "polygon on the fleet's latest readings before each forecast (docs/feedback.md); "
                        "without it, no feedback")
    return parser


def _pair(text: str) -> tuple[float, float]:
    try:
        u, v = (float(p) for p in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected u,v (two numbers), got {text!r}") from None
    return u, v


def given_environment(args, forecaster: Forecaster) -> F.Environment | None:
    if args.wind is None and args.current is None and args.sea_temp is None:
        return None
    mean = forecaster.mean_environment()
    wind = args.wind or (mean.wind_u, mean.wind_v)
    current = args.current or (mean.current_u, mean.current_v)
    return F.Environment(*wind, *current, mean.sea_temp_c if args.sea_temp is None else args.sea_temp)


def log(text: str) -> None:
    stamp = datetime.now(timezone.utc).strftime("%H:%M:%S")
    print(f"[forecaster {stamp}] {text}", flush=True)


async def push_forecasts(pusher: BoundaryPusher, forecasts: list[Forecast]) -> None:
    """One line per horizon; a rejected line is reported and the others still go."""
    for f in forecasts:
        try:
            seq = await pusher.push(f.line())
        except PushRejected as exc:
            log(f"{f.source} +{f.horizon_h:g} h rejected by pPathAssign: {exc}")
            continue
        log(f"{f.source} +{f.horizon_h:g} h (valid {f.valid_time:%Y-%m-%d %H:%M}Z, "
            f"±{f.uncertainty_m:.0f} m) -> pPathAssign OK {seq}")


async def run(args) -> int:
    forecaster = Forecaster(args.weights, args.model)
    replay = None if args.observations else default_replay(forecaster)
    environment = given_environment(args, forecaster)
    pusher = BoundaryPusher(args.host, args.port, connect_timeout=args.connect_timeout)
    last_time = None
    try:
        while True:
            if replay is not None:
                geometries, times, environments, release = replay.latest()
            else:
                geometries, times = read_observation_dir(args.observations)
                environments = None if environment is None else [environment] * len(times)
                release = None
            if args.feedback is not None and times:
                geometries, times, environments = ingest(forecaster, geometries, times, environments,
                                                         read_feedback(args.feedback), release_time=release)
            if not times:
                if args.once:
                    raise ValueError(f"{args.observations}: no polygon files to forecast from")
                log(f"{args.observations}: no polygon files yet")
            elif times[-1] != last_time:
                forecasts = forecaster.forecast(geometries, times, environments, release)
                try:
                    await push_forecasts(pusher, forecasts)
                    last_time = times[-1]
                except PushUnreachable as exc:
                    if args.once:
                        raise
                    log(f"{exc}; trying again in {args.interval:g} s")
            if args.once:
                return 0
            await asyncio.sleep(args.interval)
    finally:
        await pusher.close()


def main(argv=None, args: argparse.Namespace | None = None) -> int:
    args = args or build_parser().parse_args(argv)
    try:
        return asyncio.run(run(args))
    except KeyboardInterrupt:
        return 0
    except (OSError, ValueError) as exc:
        print(f"oilspill-forecaster: {exc}", file=sys.stderr)
        return 1

