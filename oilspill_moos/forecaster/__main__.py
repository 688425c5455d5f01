"""``python -m oilspill_moos.forecaster`` (console script ``oilspill-forecaster``).

No subcommand runs the operational loop (``--once`` for a single forecast and push); the
subcommands are simulate, train, evaluate, forecast and push.
"""
from __future__ import annotations

import argparse
import os
import sys
from datetime import datetime
from pathlib import Path

from moosdb_py.formats import print_page, version_page

SUBCOMMANDS = ("simulate", "train", "evaluate", "forecast", "push")

DESCRIPTION = """\
The oil-spill boundary forecaster: a physics prior (the observed footprint drifted by current +
windage x wind and spread by diffusion) with a learned LTC correction. Without a subcommand it runs
the operational loop: it reads the latest observation(s), forecasts the spill 3, 7, 11 and 15 h
ahead, and pushes one line per horizon to pPathAssign over TCP (127.0.0.1:9100 by default),
reconnecting when pPathAssign restarts. Naive times are UTC.

subcommands (each has its own --help):
  simulate   generate OpenOil scenarios over the northern Gulf (needs the [drift] extra)
  train      train the learned corrections (LTC RK4/Euler/fused, LSTM) and calibrate every kind
  evaluate   score every kind on the out-of-distribution split; write docs/forecaster-report.md
  forecast   forecast from polygon files; print the boundary lines (JSON, one per horizon)
  push       send boundary lines or polygon files to pPathAssign
"""

EXAMPLE = """\
# The forecaster is an external process, not a MOOS app: it has no ProcessConfig block.
# Its settings are command-line flags, every one shown with its default:
#   --host 127.0.0.1            pPathAssign's boundary server
#   --port 9100
#   --model {model:<19} ltc-fused | ltc-rk4 | ltc-euler | lstm | physics | physics-corrected
#                               | persistence | constant-velocity | constant-velocity-growth
#   --weights oilspill_moos/forecaster/weights
#   --interval 60               seconds between polls of the observations
#   --connect-timeout 30        seconds to keep retrying pPathAssign
#   --observations DIR          polygon files to watch (default: replay a held-out shipped scenario)
#   --once                      forecast and push once, then exit
#   --forcing FILE              CSV/JSON of time,wind_u,wind_v,current_u,current_v (default: none)
#   --wind U,V  --current U,V   constant forcing instead of --forcing (default: none: no drift)
#   --feedback FILE             uFldOilFusion's observations: re-anchor on the fleet's readings (default: none)
python -m oilspill_moos.forecaster --host 127.0.0.1 --port 9100 --model {model} --interval 60
"""

INTERFACE = """\
oilspill-forecaster: interface
  INPUT   polygon files (GeoJSON / ESRI shapefile, EPSG:4326 or with a .prj), one observation each,
          time from a 'time' property or the file name (e.g. slick_20100424T1643.geojson)
  OUTPUT  TCP to pPathAssign (default 127.0.0.1:9100), one UTF-8 line per horizon:
          {"type":"boundary","time":<valid epoch s>,"horizon_h":3|7|11|15,"crs":"EPSG:4326",
           "polygon":[[lon,lat],...],"uncertainty_m":<calibrated 1-sigma centroid error>,"source":"<kind>"}
          (a multi-part forecast is pushed as the outline enclosing every part over 5 % of its area)
  REPLY   OK <seq> | ERR <reason>   (a rejected line is logged; the others still go)
  MOOS    none directly: pPathAssign posts OILSPILL_BOUNDARY and drives the fleet
"""


def forecast_main(argv) -> int:
    from . import operational
    from .readers import PolygonFileError, read_forcing, read_polygons

    parser = argparse.ArgumentParser(prog="oilspill-forecaster forecast",
                                     description="Forecast from polygon files (any order; naive times are UTC) and "
                                                 "print one boundary line per horizon.")
    parser.add_argument("files", nargs="+", type=Path, help="observations: .geojson/.json/.shp")
    parser.add_argument("--model", choices=operational.KINDS, default=operational.DEFAULT_MODEL)
    parser.add_argument("--weights", type=Path, default=operational.WEIGHTS_DIR)
    parser.add_argument("--forcing", type=Path, help="CSV or JSON of time,wind_u,wind_v,current_u,current_v: "
                        "forcing at each observation and over the horizon")
    args = parser.parse_args(argv)
    try:
        observations = sorted((read_polygons(p) for p in args.files), key=lambda o: o.time or datetime.min)
        undated = [str(o.path) for o in observations if o.time is None]
        if undated:
            parser.error(f"no observation time in {', '.join(undated)} (a 'time' property or a date in the name)")
        forcing = operational.Forcing(rows=read_forcing(args.forcing) if args.forcing else None)
        times = [o.time for o in observations]
        forecaster = operational.Forecaster(args.weights, args.model)
        forecasts = forecaster.forecast([o.geometry for o in observations], times, forcing.at(times),
                                        horizon_forcing=forcing.after(times[-1]))
    except (PolygonFileError, OSError, ValueError) as exc:
        print(f"oilspill-forecaster forecast: {exc}", file=sys.stderr)
        return 1
    try:
        for f in forecasts:
            sys.stdout.write(f.line().decode())
        sys.stdout.flush()
    except BrokenPipeError:           # `forecast ... | head -1`: the reader has all it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


def push_main(argv) -> int:
    from . import operational
    from oilspill_moos.messages import boundary_line

    from .push import PushRejected, PushUnreachable, push_lines
    from .readers import read_polygons
    from .boundary import outline

    parser = argparse.ArgumentParser(prog="oilspill-forecaster push",
                                     description="Send boundaries to pPathAssign: polygon files (as they are, "
                                                 "with --horizon) or '-' for lines from stdin, sent verbatim "
                                                 "(JSON or pts={x,y:...}).")
    parser.add_argument("sources", nargs="+", help="polygon files, or '-' for stdin lines")
    parser.add_argument("--host", default=operational.DEFAULT_HOST)
    parser.add_argument("--port", type=int, default=operational.DEFAULT_PORT)
    parser.add_argument("--horizon", type=float, default=0.0, help="horizon_h for polygon files (default 0)")
    parser.add_argument("--connect-timeout", type=float, default=10.0)
    args = parser.parse_args(argv)
    lines = []
    for source in args.sources:
        if source == "-":
            lines += [(line.rstrip("\n") + "\n").encode() for line in sys.stdin if line.strip()]
        else:
            lines.append(boundary_line(outline(read_polygons(source).geometry), args.horizon, source=Path(source).name))
    try:
        for seq in push_lines(lines, args.host, args.port, connect_timeout=args.connect_timeout):
            print(f"OK {seq}")
    except (PushRejected, PushUnreachable) as exc:
        print(f"oilspill-forecaster push: {exc}", file=sys.stderr)
        return 1
    return 0


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] in SUBCOMMANDS:
        command, rest = argv[0], argv[1:]
        if command == "simulate":
            from .simulate import main as simulate_main
            return simulate_main(rest)
        if command == "train":
            from .train import main as train_main
            return train_main(rest)
        if command == "evaluate":
            from .evaluate import main as evaluate_main
            return evaluate_main(rest)
        return forecast_main(rest) if command == "forecast" else push_main(rest)
    if "--version" in argv:
        print_page(version_page("oilspill-forecaster"))
        return 0
    if "--example" in argv or "--interface" in argv:
        from .kinds import DEFAULT_MODEL

        print_page(EXAMPLE.format(model=DEFAULT_MODEL) if "--example" in argv else INTERFACE)
        return 0
    from . import operational

    parser = operational.build_parser(argparse.ArgumentParser(
        prog="python -m oilspill_moos.forecaster", description=DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter))
    parser.add_argument("--example", action="store_true", help="print the settings with their defaults")
    parser.add_argument("--interface", action="store_true", help="print what goes in and out")
    parser.add_argument("--version", action="store_true", help="print the release")
    return operational.main(args=parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
