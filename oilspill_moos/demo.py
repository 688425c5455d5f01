"""`make demo`: the oil-spill mission end to end, headless, with time warp.

Launches missions/oilspill (a shoreside and N vehicle communities, one pAntler
each), pushes a predicted boundary to pPathAssign over TCP (from the forecaster
when its trained weights are present, else the outline shipped with the
mission), follows the fleet through STATION-KEEPING -> STARTING-POSITION ->
OIL-PATH, pushes a second boundary that re-plans, and leaves a report in
demo-output/: tracks.png (tracks, boundaries and loops) and timeline.json.

    python -m oilspill_moos.demo [--vehicles N] [--warp W] [--out DIR] [--loop-time S]
"""
from __future__ import annotations

import argparse
import asyncio
import json
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import shapely

from moosdb_py.client import MOOSClient
from moosdb_py.ports import free_port
from moosdb_py.nsplug import preprocess
from moosdb_py.source import MissionFileError
from oilspill_moos.forecaster.push import BoundaryPusher
from oilspill_moos.geodesy import LocalGrid
from oilspill_moos.response.path_assign import (
    OIL_PATH,
    STARTING_POSITION,
    STATION_KEEPING,
    parse_boundary_line,
    parse_polygon_spec,
    parse_report,
)
from oilspill_moos.response.planner import containment_region
from oilspill_moos.viewer.app import viewer_beside

REPO = Path(__file__).resolve().parents[1]
MISSION_DIR = REPO / "missions" / "oilspill"
SHIPPED_BOUNDARIES = MISSION_DIR / "demo_boundaries.jsonl"
NAMES = ("abe", "ben", "cal", "deb", "eve", "fin", "gil", "hal", "ike", "jan", "kim", "lou")
VEHICLE_SPACING = 30.0  # metres between vehicles on the start line south of the spill
ORIGIN = (28.736667, -88.387222)  # LatOrigin/LongOrigin of missions/oilspill/plugs.moos
STANDOFF = 30.0


def vehicle_names(count: int) -> list[str]:
    if count < 1:
        raise ValueError(f"need at least one vehicle, got {count}")
    return list(NAMES[:count]) if count <= len(NAMES) else [f"v{i:02d}" for i in range(1, count + 1)]


@dataclass
class Community:
    name: str
    moos_port: int
    defines: dict[str, str]
    process: subprocess.Popen | None = None

    @property
    def moos_file(self) -> str:
        return f"targ_{self.name}.moos"


@dataclass
class OilspillMission:
    """missions/oilspill expanded into `folder` on free loopback ports, one pAntler per community."""

    folder: Path
    vehicles: int = 3
    warp: float = 10.0
    one_process: bool = True
    standoff: float = STANDOFF
    node_timeout: float = 30.0
    starts: list[tuple[float, float]] | None = None  # vehicle start positions; default: a line south of 0,0
    operating_radius: float = 20000.0
    extra: dict[str, str] = field(default_factory=dict)  # more nsplug macros for every community

    def __post_init__(self):
        self.folder = Path(self.folder).resolve()
        self.boundary_port = free_port()
        shore_pshare = free_port(socket.SOCK_DGRAM)
        names = vehicle_names(self.vehicles)
        common = {"WARP": f"{self.warp:g}", "LOG_PATH": str(self.folder / "logs") + "/", **self.extra}
        self.shoreside = Community("shoreside", free_port(), {
            **common, "PSHARE_PORT": str(shore_pshare), "BOUNDARY_PORT": str(self.boundary_port),
            "FLEET": ":".join(names), "STANDOFF": f"{self.standoff:g}", "NODE_TIMEOUT": f"{self.node_timeout:g}",
            "OPERATING_RADIUS": f"{self.operating_radius:g}"})
        self.shoreside.defines["MOOS_PORT"] = str(self.shoreside.moos_port)
        self.fleet: dict[str, Community] = {}
        for i, name in enumerate(names):
            x, y = self.starts[i] if self.starts else ((i - (len(names) - 1) / 2) * VEHICLE_SPACING, 0.0)
            port = free_port()
            self.fleet[name] = Community(name, port, {
                **common, "VNAME": name, "MOOS_PORT": str(port), "PSHARE_PORT": str(free_port(socket.SOCK_DGRAM)),
                "SHORE_IP": "localhost", "SHORE_PSHARE": str(shore_pshare), "START_POS": f"{x:.1f},{y:.1f}"})

    @property
    def communities(self) -> list[Community]:
        return [self.shoreside, *self.fleet.values()]

    def generate(self) -> list[Path]:
        """Write targ_*.moos / targ_*.bhv; raises MissionFileError naming the template line."""
        self.folder.mkdir(parents=True, exist_ok=True)
        (self.folder / "logs").mkdir(exist_ok=True)
        files = []
        for community in self.communities:
            template = "meta_shoreside.moos" if community is self.shoreside else "meta_vehicle.moos"
            _expand(MISSION_DIR / template, community.defines, self.folder / community.moos_file)
            if community is not self.shoreside:
                _expand(MISSION_DIR / "meta_vehicle.bhv", community.defines, self.folder / f"targ_{community.name}.bhv")
            files.append(self.folder / community.moos_file)
        return files

    def start(self) -> None:
        self.generate()
        for community in self.communities:
            self._launch(community)

    def _launch(self, community: Community) -> None:
        args = ["pAntler", community.moos_file, "--quiet"] + (["--one-process"] if self.one_process else [])
        log = open(self.folder / "logs" / f"antler_{community.name}.txt", "ab")
        community.process = subprocess.Popen([str(Path(sys.executable).parent / args[0]), *args[1:]],
                                             cwd=self.folder, stdout=log, stderr=subprocess.STDOUT,
                                             start_new_session=True)
        log.close()

    def stop_community(self, name: str, timeout: float = 10.0) -> None:
        """Stop one community (pAntler stops its apps): a vehicle dropping out, or the end of the run."""
        community = self.shoreside if name == "shoreside" else self.fleet[name]
        process = community.process
        if process is None or process.poll() is not None:
            return
        os.killpg(process.pid, signal.SIGTERM)
        try:
            process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()

    def restart_community(self, name: str) -> None:
        self._launch(self.shoreside if name == "shoreside" else self.fleet[name])

    def stop(self, timeout: float = 10.0) -> None:
        """Every community at once (each pAntler stops its own apps), then wait for them all."""
        running = [c.process for c in self.communities if c.process is not None and c.process.poll() is None]
        for process in running:
            os.killpg(process.pid, signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for process in running:
            try:
                process.wait(timeout=max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()

    def dead(self) -> list[str]:
        """Communities whose pAntler ended by itself (a crash the caller should report)."""
        return [c.name for c in self.communities if c.process is not None and c.process.poll() is not None]

    def alog(self, name: str) -> Path:
        return self.folder / "logs" / f"LOG_{name.upper()}" / f"LOG_{name.upper()}.alog"

    def __enter__(self):
        self.start()
        return self

    def __exit__(self, *exc):
        self.stop()


def _expand(template: Path, defines: dict[str, str], target: Path) -> None:
    target.write_text("".join(line.text + "\n" for line in preprocess(template, defines)))


# ---- watching the shoreside --------------------------------------------------------------

@dataclass
class Observer:
    """A MOOS client on the shoreside DB that keeps what the timeline and the report need."""

    host: str
    port: int
    warp: float
    events: list[dict] = field(default_factory=list)
    tracks: dict[str, list[tuple[float, float, float]]] = field(default_factory=dict)
    boundaries: list[list[tuple[float, float]]] = field(default_factory=list)
    regions: list[list[tuple[float, float]]] = field(default_factory=list)
    loops: dict[str, list[tuple[float, float]]] = field(default_factory=dict)
    phase: str = ""
    phase_count: dict[str, int] = field(default_factory=dict)
    dropped: list[str] = field(default_factory=list)
    modes: dict[str, str] = field(default_factory=dict)
    status: str = ""
    moos_now: float = 0.0
    started: float = field(default_factory=time.monotonic)

    def __post_init__(self):
        self.client = MOOSClient("uDemoObserver", self.host, self.port, on_mail=self.on_mail,
                                 on_connect=self.on_connect, time_warp=self.warp)
        self.t0 = self.client.moos_time()  # mission seconds count from here, on every process's warped clock

    def on_connect(self) -> None:
        for key in ("OILSPILL_PHASE", "OILSPILL_STATUS", "OILSPILL_BOUNDARY", "VIEW_POLYGON", "NODE_REPORT",
                    "OILSPILL_DROPPED", "OILSPILL_REJOINED", "OILSPILL_WARNING"):
            self.client.register(key)
        self.client.register_wildcard("OIL_PATH_UPDATES_*")

    def on_mail(self, mail) -> None:
        for msg in mail:
            self.moos_now = max(self.moos_now, msg.time)
            value = str(msg.value)
            if msg.key == "NODE_REPORT":
                report = parse_report(value)
                name = report.get("name", msg.community).lower()
                self.modes[name] = report.get("mode", "")
                try:
                    self.tracks.setdefault(name, []).append((msg.time, float(report["x"]), float(report["y"])))
                except (KeyError, ValueError):
                    continue
            elif msg.key == "OILSPILL_PHASE":
                self.phase = value
                self.phase_count[value] = self.phase_count.get(value, 0) + 1
                self.note("phase", value, msg.time)
            elif msg.key == "OILSPILL_STATUS":
                self.status = value
            elif msg.key == "OILSPILL_BOUNDARY":
                self.boundaries.append(parse_polygon_spec(value))
            elif msg.key == "VIEW_POLYGON" and "label=standoff" in value:
                self.regions.append(parse_polygon_spec(value))
            elif msg.key.startswith("OIL_PATH_UPDATES_"):
                points = value.split("#")[0].partition("=")[2]
                self.loops[msg.key[len("OIL_PATH_UPDATES_"):].lower()] = parse_polygon_spec(f"pts={{{points}}}")
            elif msg.key in ("OILSPILL_DROPPED", "OILSPILL_REJOINED", "OILSPILL_WARNING"):
                if msg.key == "OILSPILL_DROPPED":
                    self.dropped.append(value)
                self.note(msg.key.split("_")[1].lower(), value, msg.time)

    def note(self, kind: str, what: str, moos_time: float | None = None) -> dict:
        """An event stamped `moos_time` (a message's own stamp) or now on the observer's warped clock."""
        stamp = self.client.moos_time() if moos_time is None else moos_time
        event = {"event": kind, "what": what, "moos_s": round(stamp - self.t0, 2),
                 "wall_s": round(time.monotonic() - self.started, 2)}
        self.events.append(event)
        print(f"[{event['wall_s']:7.1f} s wall | {event['moos_s']:8.1f} s mission] {kind:<8} {what}", flush=True)
        return event

    def phase_event(self, phase: str, after: int) -> int | None:
        """Index of the first `phase` change noted after event `after`."""
        return next((i for i, e in enumerate(self.events) if i > after and e["event"] == "phase"
                     and e["what"] == phase), None)

    def vehicles_seen(self) -> set[str]:
        return set(self.tracks)

    def deployed(self) -> set[str]:
        return {name for name, mode in self.modes.items() if "ACTIVE" in mode and "INACTIVE" not in mode}

    async def deploy(self, fleet, timeout: float, mission: "OilspillMission | None" = None) -> None:
        """What pMarineViewer's DEPLOY button does, repeated until every vehicle reports an active mode
        (the shore broker sets up its bridges to a new vehicle only every few seconds)."""
        deadline = time.monotonic() + timeout
        while not self.deployed() >= set(fleet):
            self.client.notify("DEPLOY_ALL", "true")
            self.client.notify("MOOS_MANUAL_OVERRIDE_ALL", "false")
            await wait_for(lambda: self.deployed() >= set(fleet), min(1.0, max(deadline - time.monotonic(), 0.01)),
                           "every vehicle deployed", mission, quiet=time.monotonic() < deadline)


async def wait_for(predicate, timeout: float, what: str, mission: OilspillMission | None = None,
                   quiet: bool = False) -> None:
    """Poll until `predicate()` holds; fail naming `what` (and any community that died), or with
    `quiet` just return at the deadline."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if mission is not None and mission.dead():
            raise RuntimeError(f"while waiting for {what}: {', '.join(mission.dead())} stopped (see logs/antler_*.txt)")
        if time.monotonic() > deadline:
            if quiet:
                return
            raise TimeoutError(f"{what}: not within {timeout:.0f} s")
        await asyncio.sleep(0.05)


def shipped_boundaries() -> list[bytes]:
    return [line.encode() + b"\n" for line in SHIPPED_BOUNDARIES.read_text().splitlines() if line.strip()]


async def run_demo(out: Path, vehicles: int, warp: float, loop_time: float, timeout: float,
                   cycles: list[list[bytes]], origin: str, starts: list[tuple[float, float]] | None,
                   viewer_port: int | None = None) -> dict:
    forecast = origin.startswith("forecaster")
    # forecast outlines are tens of kilometres across: transits of kilometres at the helm's top speed,
    # and pPathAssign waits for them rather than start the loops without the vehicles
    mission = OilspillMission(out / "run", vehicles=vehicles, warp=warp, starts=starts,
                              operating_radius=0.0 if forecast else 20000.0,
                              extra={"TRANSIT_SPEED": "4", "ARRIVAL_TIMEOUT": "3000"} if forecast else {})
    report: dict = {"vehicles": vehicles, "warp": warp, "boundary_source": origin, "cycles": []}
    with mission, viewer_beside(mission.folder / mission.shoreside.moos_file, viewer_port):
        observer = Observer("127.0.0.1", mission.shoreside.moos_port, warp)
        client_task = asyncio.create_task(observer.client.run())
        try:
            await observer.client.wait_connected(timeout)
            observer.note("start", f"{vehicles} vehicles, time warp {warp:g}, boundary from {origin}")
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
                       mission)
        index = observer.phase_event(phase, index)
        marks[phase] = observer.events[index]["moos_s"]
    horizon = parse_report(observer.status).get("horizon")
    on_loop = observer.moos_now
    await wait_for(lambda: observer.moos_now - on_loop >= loop_time, timeout, f"cycle {number}: looping", mission)
    looped = observer.note("looping", f"{loop_time:g} s of containment loops")
    return {"boundary": number, "lines": len(lines), "seq": seq, "horizon_h": horizon,
            "pushed_moos_s": pushed["moos_s"], **{f"{phase.lower().replace('-', '_')}_moos_s": mark
                                                  for phase, mark in marks.items()},
            "looped_moos_s": looped["moos_s"],
            "station_keeping_s": round(marks[STARTING_POSITION] - marks[STATION_KEEPING], 2),
            "transit_s": round(marks[OIL_PATH] - marks[STARTING_POSITION], 2),
            "push_to_loop_s": round(marks[OIL_PATH] - pushed["moos_s"], 2)}


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


def weights_dir(given: Path | None) -> Path:
    """The forecaster's weights: `given`, else the folder it ships them in.
    Imported here: the training module pulls in torch, which the shipped-outline demo does not need."""
    from oilspill_moos.forecaster.train import WEIGHTS_DIR

    return Path(given or WEIGHTS_DIR)


def forecaster_ready(weights: Path) -> bool:
    """The forecaster can only forecast with trained weights."""
    return any(weights.glob("*.pt"))


async def forecaster_cycles(weights: Path, timeout: float, cycles: int = 2) -> list[list[bytes]]:
    """Run the forecaster's operational loop against a capturing stand-in for pPathAssign until it has
    sent `cycles` forecasts (the replay reveals one more hour of the spill per forecast), then stop it.

    The demo has to know where the forecast lies before it can put the fleet near it; the captured
    lines (one per horizon, grouped by the issue time they share) are then pushed to the real
    pPathAssign unchanged, one forecast per cycle.
    """
    forecasts: dict[float, list[bytes]] = {}
    done = asyncio.Event()

    async def capture(reader, writer):
        try:
            while not done.is_set() and (line := await reader.readline()):
                boundary = parse_boundary_line(line.decode(), LocalGrid(*ORIGIN))
                forecasts.setdefault(boundary.issued, []).append(line)
                writer.write(f"OK {sum(map(len, forecasts.values()))}\n".encode())
                await writer.drain()
                sizes = [len(lines) for lines in forecasts.values()]
                if len(sizes) > cycles or (len(sizes) == cycles and sizes[-1] == sizes[0]):
                    done.set()
        except ConnectionError:  # the forecaster stopped mid-line: what came whole is kept
            pass
        writer.close()

    server = await asyncio.start_server(capture, "127.0.0.1", 0)
    port = server.sockets[0].getsockname()[1]
    async with server:
        process = await asyncio.create_subprocess_exec(
            sys.executable, "-m", "oilspill_moos.forecaster", "--interval", "0.2", "--host", "127.0.0.1",
            "--port", str(port), "--weights", str(weights), stdout=asyncio.subprocess.PIPE,
            stderr=asyncio.subprocess.STDOUT)
        ended, captured = asyncio.create_task(process.communicate()), asyncio.create_task(done.wait())
        await asyncio.wait([ended, captured], timeout=timeout, return_when=asyncio.FIRST_COMPLETED)
        captured.cancel()
        if process.returncode is None:
            process.terminate()
        output, _ = await asyncio.wait_for(ended, timeout)
    found = [forecasts[issued] for issued in sorted(forecasts)][:cycles]
    if len(found) < cycles or len(found[-1]) != len(found[0]):
        raise RuntimeError(f"forecaster sent {len(found)} of {cycles} forecasts: "
                           f"{output.decode(errors='replace')[-400:].strip()}")
    return found


def boundary_source(weights: Path | None, timeout: float) -> tuple[list[list[bytes]], str]:
    """Per cycle, the lines to push: two successive forecasts of the forecaster (every horizon,
    one forecast per cycle) when `weights` is given, else the two outlines shipped with the mission."""
    if weights is not None:
        return asyncio.run(forecaster_cycles(weights, timeout)), f"forecaster (weights in {weights})"
    return [[line] for line in shipped_boundaries()], SHIPPED_BOUNDARIES.name


def stations_around(cycles: list[list[bytes]], vehicles: int, standoff: float) -> list[tuple[float, float]]:
    """Vehicle starts for forecasts tens of kilometres across: evenly round the stand-off loop of every
    cycle's nearest horizon together, 300 m further out (a fleet already on station around the spill
    area, outside each stand-off polygon to come), so the transits take minutes, not hours."""
    grid = LocalGrid(*ORIGIN)
    nearest = [min((parse_boundary_line(line.decode(), grid) for line in lines), key=lambda b: b.horizon_h)
               for lines in cycles]
    outlines = shapely.union_all([containment_region(b.polygon, 0.0) for b in nearest])
    ring = containment_region(outlines, standoff + 300.0).exterior
    return [tuple(ring.interpolate(ring.length * (i + 0.5) / vehicles).coords[0]) for i in range(vehicles)]


def write_report(out: Path, observer: Observer, report: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(8, 8))
    boundaries = list(dict.fromkeys(tuple(poly) for poly in observer.boundaries))  # repeats drawn once
    horizons = [c.get("horizon_h") for c in report["cycles"]] if len(boundaries) == len(report["cycles"]) else []
    shades = ("dimgray", "tab:purple", "tab:olive", "tab:cyan")
    for i, poly in enumerate(boundaries):
        xs, ys = zip(*(poly + poly[:1]))
        what = f" ({horizons[i]} h forecast)" if horizons else ""
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
    ax.set_xlabel("x (m east of LongOrigin)")
    ax.set_ylabel("y (m north of LatOrigin)")
    ax.set_title("oil-spill containment: tracks (o = start), boundaries in force and loops (* = last loop start)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    fig.savefig(out / "tracks.png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    (out / "timeline.json").write_text(json.dumps(report, indent=2))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m oilspill_moos.demo", description=__doc__.split("\n\n")[0],
                                     epilog=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--vehicles", type=int, default=3, help="fleet size (default 3)")
    parser.add_argument("--warp", type=float, default=10.0, help="MOOSTimeWarp (default 10)")
    parser.add_argument("--out", type=Path, default=Path("demo-output"), help="report folder (default demo-output)")
    parser.add_argument("--loop-time", type=float, default=120.0,
                        help="mission seconds to watch the loops before the next boundary (default 120)")
    parser.add_argument("--timeout", type=float, default=180.0, help="wall seconds allowed per step (default 180)")
    parser.add_argument("--source", choices=("auto", "forecaster", "shipped"), default="auto",
                        help="boundaries from the forecaster, the shipped outlines, or the forecaster when its "
                             "weights exist (default auto)")
    parser.add_argument("--weights", type=Path, default=None,
                        help="forecaster weights folder (default: the ones shipped with the forecaster)")
    parser.add_argument("--viewer", type=int, nargs="?", const=8080, default=None, metavar="PORT",
                        help="watch it live: pMarineViewer on http://127.0.0.1:PORT/ (default 8080)")
    parser.add_argument("--feedback", action="store_true",
                        help="the closed loop instead: truth spill, fleet sensing, corrected forecast (docs/feedback.md)")
    args = parser.parse_args(argv)
    if args.warp <= 0 or args.vehicles < 1:
        parser.error("--warp must be > 0 and --vehicles >= 1")
    if args.feedback:
        from oilspill_moos import feedback_demo

        try:
            return feedback_demo.main(args.out, args.vehicles, args.warp, args.loop_time, args.timeout)
        except (TimeoutError, RuntimeError, MissionFileError, ConnectionError) as exc:
            print(f"demo: {exc}", file=sys.stderr)
            return 1
    started = time.monotonic()
    try:
        weights = weights_dir(args.weights) if args.source != "shipped" else None
        use = args.source == "forecaster" or (weights is not None and forecaster_ready(weights))
        cycles, origin = boundary_source(weights if use else None, args.timeout)
        starts = stations_around(cycles, args.vehicles, STANDOFF) if origin.startswith("forecaster") else None
        report = asyncio.run(run_demo(args.out, args.vehicles, args.warp, args.loop_time, args.timeout,
                                      cycles, origin, starts, args.viewer))
    except (TimeoutError, RuntimeError, MissionFileError, ConnectionError) as exc:
        print(f"demo: {exc}", file=sys.stderr)
        return 1
    for cycle in report["cycles"]:
        print(f"boundary {cycle['boundary']}: push -> all on the loop in {cycle['push_to_loop_s']:.1f} mission s "
              f"(station-keeping {cycle['station_keeping_s']:.1f} s, transit {cycle['transit_s']:.1f} s)")
    print(f"demo: done in {time.monotonic() - started:.0f} s; report in {args.out}/ (tracks.png, timeline.json)")
    run = args.out / "run"
    print(f"replay it in the browser: pMarineViewer {run / 'targ_shoreside.moos'} "
          f"--replay={run / 'logs' / 'LOG_SHORESIDE' / 'LOG_SHORESIDE.alog'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
