"""The operational forecaster: latest observations -> boundaries 3/7/11/15 h ahead -> pPathAssign.

Observations come from a directory of polygon files (GeoJSON or ESRI shapefiles, one observation per
file, its time from a ``time`` property or the file name; naive times are UTC), re-read every
``--interval`` seconds; a new latest observation triggers a forecast and a push of one boundary line
per horizon. A file that cannot be read is skipped with a warning naming it. Without
``--observations`` the loop replays a scenario of the shipped DWH-site set, one hour per interval,
so the process runs anywhere out of the box.

Forcing: ``--forcing FILE`` (CSV or JSON of times, wind and current; ``readers.read_forcing``) gives
the forcing at each observation (the latest row at or before it) and over the horizon (the rows
after the latest observation, held between rows); ``--wind``/``--current`` give constant forcing.
Without either the physics prior only spreads the slick (no drift) and says so.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import sys
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from pathlib import Path

from . import features as F
from .boundary import outline
from .kinds import DEFAULT_MODEL, KINDS, LEARNED_KINDS
from oilspill_moos.messages import boundary_line

from .push import DEFAULT_HOST, DEFAULT_PORT, BoundaryPusher, PushRejected, PushUnreachable
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
POLYGON_SUFFIXES = (".geojson", ".json", ".shp")


@dataclass
class Forecast:
    horizon_h: float
    geometry: object             # EPSG:4326 MultiPolygon: the forecast footprint
    uncertainty_m: float         # calibrated 1-sigma centroid error per axis; 95 % radius = 2.448 x this
    source: str
    valid_time: datetime
    contour_50: object = None    # EPSG:4326: cells with P(oil) >= 50 %
    contour_90: object = None    # EPSG:4326: the 90 % envelope, cells with P(oil) >= 10 %

    def line(self) -> bytes:
        return boundary_line(outline(self.geometry), self.horizon_h, time=self.valid_time.timestamp(),
                             uncertainty_m=self.uncertainty_m, source=self.source)


class Forecaster:
    """One forecaster kind with its weights (learned kinds) and calibration: observations in, one
    ``Forecast`` per horizon out."""

    def __init__(self, weights_dir: Path = WEIGHTS_DIR, kind: str = DEFAULT_MODEL):
        if kind not in KINDS:
            raise ValueError(f"--model must be one of {KINDS}, not {kind!r}")
        self.kind = kind
        weights_dir = Path(weights_dir)
        calibration_path = weights_dir / "calibration.json"
        self.calibration = json.loads(calibration_path.read_text()) if calibration_path.is_file() else {}
        from . import engine as E

        self.corrector = None
        if kind in LEARNED_KINDS:
            from .models import Corrector            # torch only for the learned kinds

            self.corrector = Corrector.load(weights_dir / f"{kind}.pt")
        self.settings = E.Settings.from_calibration(self.calibration)
        self.horizons_h = F.HORIZONS_H
        self.split = self.calibration.get("split", {"train": [], "val": [], "test": []})

    def forecast(self, geometries, times, environments=None, release_time: datetime | None = None,
                 horizon_forcing=None, horizons_h=None) -> list[Forecast]:
        """Forecast from observations in time order (naive times are UTC). ``environments``: one
        ``features.Environment`` per observation (None: no forcing known); ``horizon_forcing``:
        (time, Environment) pairs after the latest observation; ``horizons_h``: any positive hours
        (default 3, 7, 11, 15). ``release_time`` is accepted for old callers and ignored: nothing in a
        forecast depends on when or where the spill began."""
        from . import engine as E

        horizons_h = self.horizons_h if horizons_h is None else tuple(float(h) for h in horizons_h)
        if not horizons_h or any(not h > 0 for h in horizons_h):
            raise ValueError(f"horizons must be positive hours, not {list(horizons_h)}")
        obs = E.prepare(geometries, times, environments, horizon_forcing)
        correction = self.corrector.correction(obs, self.settings.params) if self.corrector is not None else None
        latest = F.as_utc(times[-1])
        return [Forecast(horizon_h=f.horizon_h, geometry=obs.plane.to_lonlat(f.geometry), uncertainty_m=f.uncertainty_m,
                         source=self.kind, valid_time=latest + timedelta(hours=f.horizon_h),
                         contour_50=obs.plane.to_lonlat(f.contour_50), contour_90=obs.plane.to_lonlat(f.contour_90))
                for f in E.forecast_plane(self.kind, obs, horizons_h, self.settings, correction)]


# ---------------------------------------------------------------------------------------------------
# Observation sources

def read_observation_dir(directory: Path, warn=None):
    """(geometries, times) of every readable polygon file in ``directory``, in time order. A file that
    cannot be read, or has no time, is skipped and reported to ``warn(message)`` naming it."""
    from .readers import PolygonFileError, read_polygons

    directory = Path(directory)
    if not directory.is_dir():
        raise FileNotFoundError(f"{directory}: observation directory does not exist")
    observations = {}
    for path in sorted(p for p in directory.iterdir() if p.suffix.lower() in POLYGON_SUFFIXES):
        try:
            observation = read_polygons(path)
            if observation.time is None:
                raise PolygonFileError(path, "no observation time (give a 'time' property or a date in the file name)")
        except (PolygonFileError, OSError, ValueError) as exc:
            if warn is not None:
                warn(f"skipped {exc}")
            continue
        if observation.time in observations and warn is not None:
            warn(f"skipped {path}: same observation time as {observations[observation.time][0]}")
            continue
        observations[observation.time] = (path, observation.geometry)
    times = sorted(observations)
    return [observations[t][1] for t in times], times


class ScenarioReplay:
    """A scenario of the shipped DWH-site set, revealed one observation per call."""

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
        raise ValueError("the shipped DWH-site set holds none of the weights' held-out scenarios")
    return ScenarioReplay(max(scenarios, key=len))


class Forcing:
    """Forcing for the loop: a forcing file's rows (held from each row's time), or one constant value."""

    def __init__(self, rows=None, constant: F.Environment | None = None):
        self.rows = sorted(rows or [], key=lambda r: r[0])
        self.constant = constant

    def known(self) -> bool:
        return bool(self.rows) or self.constant is not None

    def at(self, times) -> list[F.Environment] | None:
        if self.constant is not None:
            return [self.constant] * len(times)
        if not self.rows:
            return None
        out = []
        for t in times:
            before = [env for when, env in self.rows if when <= F.as_utc(t)]
            out.append(before[-1] if before else self.rows[0][1])
        return out

    def after(self, time) -> list:
        return [(when, env) for when, env in self.rows if when > F.as_utc(time)]


# ---------------------------------------------------------------------------------------------------
# The loop

def build_parser(parser: argparse.ArgumentParser | None = None) -> argparse.ArgumentParser:
    parser = parser or argparse.ArgumentParser(prog="python -m oilspill_moos.forecaster")
    parser.add_argument("--observations", type=Path,
                        help="directory of polygon files to watch (default: replay a shipped DWH-site scenario)")
    parser.add_argument("--once", action="store_true", help="forecast and push once, then exit")
    parser.add_argument("--host", default=DEFAULT_HOST, help="pPathAssign host (default: %(default)s)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="pPathAssign port (default: %(default)s)")
    parser.add_argument("--model", choices=KINDS, default=DEFAULT_MODEL, help="forecaster kind (default: %(default)s)")
    parser.add_argument("--weights", type=Path, default=WEIGHTS_DIR, help="weights directory (default: shipped)")
    parser.add_argument("--interval", type=float, default=60.0, help="seconds between polls (default: %(default)s)")
    parser.add_argument("--connect-timeout", type=float, default=30.0,
                        help="seconds to keep retrying pPathAssign (default: %(default)s)")
    parser.add_argument("--forcing", type=Path, help="CSV or JSON of times with wind_u,wind_v,current_u,current_v "
                        "(m/s): forcing at each observation and over the horizon (docs/forecaster.md)")
    parser.add_argument("--wind", type=_pair, help="constant wind u,v m/s (instead of --forcing)")
    parser.add_argument("--current", type=_pair, help="constant surface current u,v m/s (instead of --forcing)")
    parser.add_argument("--sea-temp", type=float, help="sea temperature in °C (recorded; the prior does not use it)")
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


def given_forcing(args) -> Forcing:
    """The forcing the command line gives (a --forcing file, or constant --wind/--current)."""
    if args.forcing is not None:
        if args.wind is not None or args.current is not None:
            raise ValueError("give --forcing or --wind/--current, not both")
        from .readers import read_forcing

        return Forcing(rows=read_forcing(args.forcing))
    if args.wind is None and args.current is None:
        return Forcing()
    wind, current = args.wind or (0.0, 0.0), args.current or (0.0, 0.0)
    return Forcing(constant=F.Environment(*wind, *current, 0.0 if args.sea_temp is None else args.sea_temp))


def log(text: str) -> None:
    stamp = datetime.now(timezone.utc).strftime("%H:%M:%S")
    print(f"[forecaster {stamp}] {text}", flush=True)


async def push_forecasts(pusher: BoundaryPusher, forecasts: list[Forecast]) -> int:
    """One line per horizon; a rejected line is reported and the others still go. Returns how many
    were accepted."""
    accepted = 0
    for f in forecasts:
        try:
            seq = await pusher.push(f.line())
        except PushRejected as exc:
            log(f"{f.source} +{f.horizon_h:g} h rejected by pPathAssign: {exc}")
            continue
        accepted += 1
        log(f"{f.source} +{f.horizon_h:g} h (valid {f.valid_time:%Y-%m-%d %H:%M}Z, "
            f"±{f.uncertainty_m:.0f} m) -> pPathAssign OK {seq}")
    return accepted


class AllRejected(RuntimeError):
    """pPathAssign refused every horizon of a forecast."""


async def run(args) -> int:
    from .assimilate import ingest, read_feedback

    forecaster = Forecaster(args.weights, args.model)
    replay = None if args.observations else default_replay(forecaster)
    forcing = given_forcing(args)
    if args.observations and not forcing.known():
        log("no forcing given (--forcing or --wind/--current): the forecast spreads the slick but cannot drift it")
    pusher = BoundaryPusher(args.host, args.port, connect_timeout=args.connect_timeout)
    last_time = None
    warned: set[str] = set()

    def warn(message: str) -> None:
        if message not in warned:
            warned.add(message)
            log(message)

    try:
        while True:
            horizon = None
            if replay is not None:
                geometries, times, environments, _ = replay.latest()
            else:
                geometries, times = read_observation_dir(args.observations, warn)
                environments = forcing.at(times)
                horizon = forcing.after(times[-1]) if times else None
            if args.feedback is not None and times:
                geometries, times, environments = ingest(forecaster, geometries, times, environments,
                                                         read_feedback(args.feedback))
            if not times:
                if args.once:
                    raise ValueError(f"{args.observations}: no readable polygon files to forecast from")
                log(f"{args.observations}: no polygon files yet")
            elif times[-1] != last_time:
                forecasts = forecaster.forecast(geometries, times, environments, horizon_forcing=horizon)
                try:
                    accepted = await push_forecasts(pusher, forecasts)
                    last_time = times[-1]
                except PushUnreachable as exc:
                    if args.once:
                        raise
                    log(f"{exc}; trying again in {args.interval:g} s")
                else:
                    if accepted == 0 and args.once:
                        raise AllRejected(f"pPathAssign rejected every horizon of the forecast valid from {times[-1]:%Y-%m-%d %H:%M}Z")
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
    except (OSError, ValueError, AllRejected) as exc:
        print(f"oilspill-forecaster: {exc}", file=sys.stderr)
        return 1
