"""`make demo`: the oil-spill mission end to end, headless, with time warp.

By default a spill response at real scale (oilspill_moos/response_demo.py): 8 vessels, a truth
spill (a held-out scenario moving on the mission clock), three forecast cycles two mission hours
apart, each re-planned by pPathAssign from where the vessels are with an arc of the stand-off loop
per vessel; the measures printed as it goes and a summary at the end; report.html with its PNGs in
a folder of its own, demo-output/<UTC time>/ (demo-output/latest names the newest).
`--source shipped` runs the small demo instead: the two outlines shipped with the mission, three
vehicles on whole loops, tracks.png and timeline.json. `--feedback` runs the closed loop.

    python -m oilspill_moos.demo [--vehicles N] [--warp W] [--cycles C] [--cycle-hours H] [--out DIR]
"""
from __future__ import annotations

import argparse
import asyncio
import json
import os
import sys
import time
from pathlib import Path

import shapely

from moosdb_py.formats import FormatError, parse_number, parse_pairs
from moosdb_py.source import MissionFileError
from oilspill_moos.forecaster.push import BoundaryPusher
from oilspill_moos.oilspill_mission import MISSION_DIR, Observer, OilspillMission, wait_for
from oilspill_moos.response.path_assign import (
    OIL_PATH,
    STARTING_POSITION,
    STATION_KEEPING,
)
from oilspill_moos.viewer.app import viewer_beside

SHIPPED_BOUNDARIES = MISSION_DIR / "demo_boundaries.jsonl"
RESPONSE_VEHICLES = 8
RESPONSE_WARP = 30.0    # what this shared 2-core machine keeps up with for 8 vessels (docs/demo.md)
RESPONSE_VESSELS_PER_PROCESS = 4   # vessels hosted in one pAntler (--with): they wake together, costing less CPU


def shipped_boundaries() -> list[bytes]:
    return [line.encode() + b"\n" for line in SHIPPED_BOUNDARIES.read_text().splitlines() if line.strip()]


async def run_demo(out: Path, vehicles: int, warp: float, loop_time: float, timeout: float,
                   viewer_port: int | None = None) -> dict:
    """The small demo: the two outlines shipped with the mission, the fleet on a start line south of them,
    each vessel running the whole loop (PATROL=loop), `loop_time` mission seconds watched per boundary."""
    cycles = [[line] for line in shipped_boundaries()]
    mission = OilspillMission(out / "run", vehicles=vehicles, warp=warp, extra={"PATROL": "loop"})
    report: dict = {"vehicles": vehicles, "warp": warp, "boundary_source": SHIPPED_BOUNDARIES.name, "cycles": []}
    with mission, viewer_beside(mission.folder / mission.shoreside.moos_file, viewer_port):
        observer = Observer("127.0.0.1", mission.shoreside.moos_port, warp)
        client_task = asyncio.create_task(observer.client.run())
        try:
            await observer.client.wait_connected(timeout)
            observer.note("start", f"{vehicles} vehicles, time warp {warp:g}, boundary from {SHIPPED_BOUNDARIES.name}")
            await wait_for(lambda: observer.vehicles_seen() >= set(mission.fleet), timeout,
                           "every vehicle's NODE_REPORT on the shoreside", mission)
            observer.note("online", ":".join(sorted(mission.fleet)))
            await observer.deploy(mission.fleet, timeout, mission)
            observer.note("deployed", "DEPLOY_ALL=true, MOOS_MANUAL_OVERRIDE_ALL=false")
            pusher = BoundaryPusher("127.0.0.1", mission.boundary_port, connect_timeout=timeout)
            for number, lines in enumerate(cycles[:2], start=1):
                report["cycles"].append(await one_cycle(number, lines, pusher, observer, mission, loop_time, timeout))
            await pusher.close()
        finally:
            observer.client.close()
            client_task.cancel()
    report["events"] = observer.events
    problems = timeline_problems(report, observer.client.moos_time() - observer.t0)
    if problems:
        raise RuntimeError("the timeline makes no sense: " + "; ".join(problems))
    write_report(out, observer, report)
    return report


async def one_cycle(number: int, lines: list[bytes], pusher, observer: Observer, mission: OilspillMission,
                    loop_time: float, timeout: float) -> dict:
    """Push one boundary (one line per forecast horizon) and follow the fleet until it has looped
    for `loop_time` mission seconds."""
    index = len(observer.events)
    pushed = observer.note("push", f"boundary {number}: {len(lines)} line(s)")
    for line in lines:
        seq = await pusher.push(line)
    observer.note("accepted", f"boundary {number}: OK up to seq {seq}")
    marks = {}
    for phase in (STATION_KEEPING, STARTING_POSITION, OIL_PATH):   # each after the one before, in this cycle
        await wait_for(lambda: observer.phase_event(phase, index) is not None, timeout, f"cycle {number}: {phase}",
                       mission, progress=lambda: observer.say(*waiting_line(observer, phase)))
        index = observer.phase_event(phase, index)
        marks[phase] = observer.events[index]["moos_s"]
    horizon = status_horizon(observer.status)
    on_loop = observer.moos_now
    await wait_for(lambda: observer.moos_now - on_loop >= loop_time, timeout, f"cycle {number}: looping", mission,
                   progress=lambda: observer.say("looping", f"{observer.moos_now - on_loop:.0f} of {loop_time:g} s "
                                                            "of containment loops watched"))
    looped = observer.note("looping", f"{loop_time:g} s of containment loops")
    return {"boundary": number, "lines": len(lines), "seq": seq, "horizon_h": horizon,
            "pushed_moos_s": pushed["moos_s"], **{f"{phase.lower().replace('-', '_')}_moos_s": mark
                                                  for phase, mark in marks.items()},
            "looped_moos_s": looped["moos_s"],
            "station_keeping_s": round(marks[STARTING_POSITION] - marks[STATION_KEEPING], 2),
            "transit_s": round(marks[OIL_PATH] - marks[STARTING_POSITION], 2),
            "push_to_loop_s": round(marks[OIL_PATH] - pushed["moos_s"], 2)}


def status_horizon(status: str) -> float | None:
    """The forecast horizon (hours) of pPathAssign's OILSPILL_STATUS, a number; None before any forecast
    (horizon=-1) or without one."""
    try:
        horizon = parse_number(parse_pairs(status).get("horizon", "-1"))
    except FormatError:
        return None
    return horizon if horizon >= 0 else None


def transit_line(positions: dict[str, tuple[float, float]], routes: dict[str, list[tuple[float, float]]],
                 speeds: dict[str, float], arrived: set[str]) -> str | None:
    """How far the fleet has still to go along its routes to the starting positions and when the last
    vehicle should get there (mission seconds at its reported speed); None before any route. The
    `arrived` vehicles hold station at their starting positions, waiting for the others."""
    left = {}
    for name, route in routes.items():
        if name in positions and route:
            here = shapely.Point(positions[name])
            line = shapely.LineString(route) if len(route) > 1 else None
            left[name] = (line.length - line.project(here) + line.distance(here) if line is not None
                          and line.length > 1e-6 else here.distance(shapely.Point(route[-1])))
    if not left:
        return None
    going = {name: metres for name, metres in left.items() if name not in arrived}
    arrived = f"{len(left) - len(going)} of {len(left)} at their starting positions"
    if not going:
        return arrived
    farthest = max(going, key=going.get)
    etas = [going[n] / speeds[n] for n in going if speeds.get(n, 0.0) > 0.1]
    eta = f"ETA {max(etas):.0f} s mission time" if len(etas) == len(going) else "ETA unknown (a vehicle is stopped)"
    return f"{going[farthest]:.0f} m to go ({farthest} farthest; {arrived}), {eta}"


def waiting_line(observer: Observer, phase: str) -> tuple[str, str]:
    """The progress line while the demo waits for `phase`: distance and ETA while the fleet transits."""
    if phase == OIL_PATH:
        positions = {name: track[-1][1:] for name, track in observer.tracks.items()}
        holding = {name for name, mode in observer.modes.items() if mode.endswith(STATION_KEEPING)}
        line = transit_line(positions, observer.routes, observer.speeds, holding)
        if line is not None:
            return "transit", line
    return "waiting", f"for {phase} (fleet phase {observer.phase or 'none yet'})"


def timeline_problems(report: dict, mission_s: float) -> list[str]:
    """What is wrong with a timeline: per cycle push <= STATION-KEEPING <= STARTING-POSITION <= OIL-PATH
    <= end of the loops, each cycle after the one before, every stamp inside the `mission_s` the run
    lasted, durations that add up; pPathAssign's phase changes in time order."""
    problems = []
    end = 0.0
    for cycle in report["cycles"]:
        name = f"boundary {cycle['boundary']}"
        marks = [("push", cycle["pushed_moos_s"]), (STATION_KEEPING, cycle["station_keeping_moos_s"]),
                 (STARTING_POSITION, cycle["starting_position_moos_s"]), (OIL_PATH, cycle["oil_path_moos_s"]),
                 ("loops watched", cycle["looped_moos_s"])]
        for (before, t0), (after, t1) in zip([("previous cycle", end)] + marks, marks):
            if not t0 <= t1:
                problems.append(f"{name}: {after} at {t1} s mission comes before {before} at {t0} s")
        if not 0 <= marks[-1][1] <= mission_s:
            problems.append(f"{name}: stamp {marks[-1][1]} s outside the run's 0..{mission_s:.0f} s")
        total = cycle["oil_path_moos_s"] - cycle["pushed_moos_s"]
        if abs(cycle["push_to_loop_s"] - total) > 0.05 or cycle["station_keeping_s"] + cycle["transit_s"] > total + 0.05:
            problems.append(f"{name}: durations do not add up: {cycle}")
        end = marks[-1][1]
    phases = [e["moos_s"] for e in report["events"] if e["event"] == "phase"]
    if any(b < a for a, b in zip(phases, phases[1:])):
        problems.append(f"phase changes out of time order: {phases}")
    walls = [e["wall_s"] for e in report["events"]]
    if any(b < a for a, b in zip(walls, walls[1:])):
        problems.append("wall-clock stamps out of order")
    return problems


def metre_axes(ax) -> None:
    """Axes in m, or km past 5 km across (forecast outlines are tens of km wide), with few enough
    ticks that their labels never run into each other."""
    from matplotlib.ticker import FuncFormatter, MaxNLocator

    span = max(hi - lo for lo, hi in (ax.get_xlim(), ax.get_ylim()))
    unit, scale = ("km", 1000.0) if span >= 5000 else ("m", 1.0)
    for axis, what in ((ax.xaxis, f"x ({unit} east of LongOrigin)"), (ax.yaxis, f"y ({unit} north of LatOrigin)")):
        axis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 2.5, 5, 10]))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / scale:g}"))
        axis.set_label_text(what)


def draw_tracks(observer: Observer, report: dict):
    """tracks.png's figure: the boundaries in force, the stand-off loops, each vehicle's track."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 8))
    ax = fig.subplots()
    boundaries = list(dict.fromkeys(tuple(poly) for poly in observer.boundaries))  # repeats drawn once
    horizons = [c.get("horizon_h") for c in report["cycles"]] if len(boundaries) == len(report["cycles"]) else []
    shades = ("dimgray", "tab:purple", "tab:olive", "tab:cyan")
    for i, poly in enumerate(boundaries):
        xs, ys = zip(*(poly + poly[:1]))
        what = f" ({horizons[i]:g} h forecast)" if horizons and horizons[i] is not None else ""
        ax.fill(xs, ys, color=shades[i % len(shades)], alpha=0.2, label=f"boundary in force {i + 1}{what}")
    for i, poly in enumerate(dict.fromkeys(tuple(poly) for poly in observer.regions)):
        poly = list(poly)
        xs, ys = zip(*(poly + poly[:1]))
        ax.plot(xs, ys, "--", color=shades[i % len(shades)], lw=1, label=f"stand-off loop {i + 1}")
    for name, track in sorted(observer.tracks.items()):
        _, xs, ys = zip(*track)
        (line,) = ax.plot(xs, ys, lw=1.2, label=f"{name} track")
        ax.plot(xs[0], ys[0], "o", color=line.get_color())
        if name in observer.loops:
            lx, ly = zip(*observer.loops[name][:1])
            ax.plot(lx, ly, "*", ms=12, color=line.get_color())
    ax.set_aspect("equal")
    metre_axes(ax)
    ax.set_title("oil-spill containment: tracks (o = start), boundaries in force\nand loops (* = last loop start)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    return fig


def write_report(out: Path, observer: Observer, report: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    draw_tracks(observer, report).savefig(out / "tracks.png", dpi=110, bbox_inches="tight")
    (out / "timeline.json").write_text(json.dumps(report, indent=2))


def new_run_folder(base: Path, stamp: str | None = None) -> Path:
    """A fresh folder for one run, `base/<UTC time>` (`-2`, `-3`... if that exists), and `base/latest`
    pointed at it: a report never lies beside an older run's files."""
    stamp = stamp or time.strftime("%Y-%m-%dT%H-%M-%SZ", time.gmtime())
    base.mkdir(parents=True, exist_ok=True)
    run, n = base / stamp, 1
    while True:
        try:
            run.mkdir()
            break
        except FileExistsError:
            n += 1
            run = base / f"{stamp}-{n}"
    link = base / f".latest-{os.getpid()}"
    link.unlink(missing_ok=True)
    link.symlink_to(run.name, target_is_directory=True)
    os.replace(link, base / "latest")   # atomic: `latest` always names a whole run
    return run


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oilspill_moos.demo", description=__doc__.split("\n\n")[0],
                                     epilog=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--vehicles", type=int, default=None,
                        help=f"fleet size (default {RESPONSE_VEHICLES}; 3 with --source shipped)")
    parser.add_argument("--warp", type=float, default=None,
                        help=f"MOOSTimeWarp (default {RESPONSE_WARP:g}; 10 with --source shipped)")
    parser.add_argument("--vessels-per-process", type=int, default=RESPONSE_VESSELS_PER_PROCESS,
                        help="the response: vessels' communities hosted in one pAntler process (default "
                             f"{RESPONSE_VESSELS_PER_PROCESS}; 1 = a process each)")
    parser.add_argument("--out", type=Path, default=Path("demo-output"),
                        help="reports go to OUT/<UTC time of the run>/, OUT/latest names the newest "
                             "(default demo-output)")
    parser.add_argument("--cycles", type=int, default=3, help="forecast cycles (default 3)")
    parser.add_argument("--cycle-hours", type=float, default=2.0,
                        help="mission hours between forecast cycles, each patrolled until the next (default 2)")
    parser.add_argument("--reach", type=float, default=1000.0,
                        help="metres within which a patrolling vessel covers the true perimeter (default 1000)")
    parser.add_argument("--loop-time", type=float, default=120.0,
                        help="--source shipped: mission seconds to watch the loops before the next boundary "
                             "(default 120)")
    parser.add_argument("--timeout", type=float, default=180.0, help="wall seconds allowed per step (default 180)")
    parser.add_argument("--source", choices=("forecaster", "shipped"), default="forecaster",
                        help="forecaster: the real-scale response against a truth spill (default); shipped: the "
                             "two small outlines shipped with the mission, whole loops")
    parser.add_argument("--weights", type=Path, default=None,
                        help="forecaster weights folder (default: the ones shipped with the forecaster)")
    parser.add_argument("--viewer", type=int, nargs="?", const=8080, default=None, metavar="PORT",
                        help="watch it live: pMarineViewer on http://127.0.0.1:PORT/ (default 8080)")
    parser.add_argument("--feedback", action="store_true",
                        help="the closed loop instead: truth spill, fleet sensing, corrected forecast (docs/feedback.md)")
    args = parser.parse_args(argv)
    shipped = args.source == "shipped" or args.feedback
    vehicles = args.vehicles or (3 if shipped else RESPONSE_VEHICLES)
    warp = args.warp or (10.0 if shipped else RESPONSE_WARP)
    if warp <= 0 or vehicles < 1 or args.cycles < 1 or args.cycle_hours <= 0 or args.vessels_per_process < 1:
        parser.error("--warp and --cycle-hours must be > 0, --vehicles, --cycles and --vessels-per-process >= 1")
    out = new_run_folder(args.out)
    print(f"demo: this run's report goes to {out}/ ({args.out / 'latest'} names it)", flush=True)
    started = time.monotonic()
    try:
        if args.feedback:
            from oilspill_moos import feedback_demo

            return feedback_demo.main(out, vehicles, warp, args.loop_time, args.timeout)
        if shipped:
            report = asyncio.run(run_demo(out, vehicles, warp, args.loop_time, args.timeout, args.viewer))
            for cycle in report["cycles"]:
                print(f"boundary {cycle['boundary']}: push -> all on the loop in {cycle['push_to_loop_s']:.1f} "
                      f"mission s (station-keeping {cycle['station_keeping_s']:.1f} s, "
                      f"transit {cycle['transit_s']:.1f} s)")
            print(f"demo: done in {time.monotonic() - started:.0f} s; report in {out}/ (tracks.png, timeline.json)")
        else:
            from oilspill_moos.response_demo import run_response, summary_lines
            from oilspill_moos.response_report import write_response_report

            record = asyncio.run(run_response(out, vehicles, warp, args.cycles, args.cycle_hours, args.timeout,
                                              args.weights, reach=args.reach, viewer_port=args.viewer,
                                              vessels_per_process=args.vessels_per_process))
            page = write_response_report(out, record)
            print("summary:")
            for line in summary_lines(record):
                print("  " + line)
            print(f"demo: done in {time.monotonic() - started:.0f} s; report: {page}")
    except (TimeoutError, RuntimeError, MissionFileError, ConnectionError) as exc:
        print(f"demo: {exc}", file=sys.stderr)
        return 1
    run = out / "run"
    print(f"replay it in the browser: pMarineViewer {run / 'targ_shoreside.moos'} "
          f"--replay={run / 'logs' / 'LOG_SHORESIDE' / 'LOG_SHORESIDE.alog'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
