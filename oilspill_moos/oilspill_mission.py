"""missions/oilspill run headless: its communities expanded and launched with pAntler on free loopback
ports, and a MOOS client on the shoreside that keeps what a report needs. What both demos run
(`make demo`, `make demo DEMO_ARGS=--feedback`) and the end-to-end tests drive.
"""
from __future__ import annotations

import asyncio
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from moosdb_py.app import fell_behind, status_ticks
from moosdb_py.client import MOOSClient
from moosdb_py.nsplug import preprocess
from moosdb_py.ports import free_port
from oilspill_moos.messages import parse_points_update, parse_polygon_spec, parse_report

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
    vessels_per_process: int = 1   # >1: that many vessels' communities in one pAntler (--with), waking together

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

    def processes(self) -> list[list[Community]]:
        """The communities each pAntler runs: the shoreside alone, the vessels `vessels_per_process` at a
        time (each with its own MOOSDB and apps; hosted together they share one AppTicker, so a vessel
        costs less CPU: docs/pAntler.md)."""
        if self.vessels_per_process < 1:
            raise ValueError(f"vessels_per_process must be >= 1, not {self.vessels_per_process}")
        vessels = list(self.fleet.values())
        return [[self.shoreside]] + [vessels[i:i + self.vessels_per_process]
                                     for i in range(0, len(vessels), self.vessels_per_process)]

    def start(self) -> None:
        self.generate()
        for group in self.processes():
            self.launch(*group)

    def launch(self, community: Community, *hosted_with: Community) -> None:
        """One pAntler for `community` (and `hosted_with` in the same process); its log is
        logs/antler_<community>.txt."""
        if hosted_with and not self.one_process:
            raise ValueError("communities hosted together need one_process")
        args = ["pAntler", community.moos_file, "--quiet"] + (["--one-process", "--host-db"] if self.one_process else [])
        for other in hosted_with:
            args += ["--with", other.moos_file]
        log = open(self.folder / "logs" / f"antler_{community.name}.txt", "ab")
        process = subprocess.Popen([str(Path(sys.executable).parent / args[0]), *args[1:]], cwd=self.folder,
                                   stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        log.close()
        for member in (community, *hosted_with):
            member.process = process

    def stop(self, timeout: float = 10.0, names: list[str] | None = None) -> None:
        """Every community (or those `names`d: a vehicle dropping out, and with it the vessels hosted in
        its process) at once, each pAntler stopping its own apps, then wait for them all. `launch`
        starts a stopped one again."""
        running = list({id(c.process): c.process for c in self.communities
                        if c.process is not None and c.process.poll() is None
                        and (names is None or c.name in names)}.values())
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
    routes: dict[str, list[tuple[float, float]]] = field(default_factory=dict)  # to each starting position
    speeds: dict[str, float] = field(default_factory=dict)
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
        for key in ("OILSPILL_PHASE", "OILSPILL_STATUS", "OILSPILL_BOUNDARY", "OILSPILL_REGION", "NODE_REPORT",
                    "OILSPILL_DROPPED", "OILSPILL_REJOINED", "OILSPILL_WARNING"):
            self.client.register(key)
        self.client.register_wildcard("OIL_PATH_UPDATES_*")
        self.client.register_wildcard("STARTING_POSITION_UPDATES_*")

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
                    self.speeds[name] = float(report.get("spd", "nan"))
                except (KeyError, ValueError):
                    continue
            elif msg.key == "OILSPILL_PHASE":
                last = next((e for e in reversed(self.events) if e["event"] == "phase"), None)
                if last is not None and last["what"] == value and last["moos_s"] >= round(msg.time - self.t0, 2):
                    continue   # the phase in force again, as the DB sends it on a reconnection: no new phase
                self.phase = value
                self.phase_count[value] = self.phase_count.get(value, 0) + 1
                self.note("phase", value, msg.time)
            elif msg.key == "OILSPILL_STATUS":
                self.status = value
            elif msg.key in ("OILSPILL_BOUNDARY", "OILSPILL_REGION"):
                kept = self.boundaries if msg.key == "OILSPILL_BOUNDARY" else self.regions
                polygon = parse_polygon_spec(value)
                if not kept or kept[-1] != polygon:    # the DB sends the one in force again on a reconnection
                    kept.append(polygon)
            elif msg.key.startswith(("OIL_PATH_UPDATES_", "STARTING_POSITION_UPDATES_")):
                kind, _, name = msg.key.partition("_UPDATES_")
                points, _ = parse_points_update(value)
                (self.loops if kind == "OIL_PATH" else self.routes)[name.lower()] = points
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
        self.say(kind, what, event)
        return event

    def say(self, kind: str, what: str, stamps: dict | None = None) -> None:
        """Print one line stamped like the events (a progress line is printed, not kept)."""
        stamps = stamps or {"moos_s": self.client.moos_time() - self.t0, "wall_s": time.monotonic() - self.started}
        print(f"[{stamps['wall_s']:7.1f} s wall | {stamps['moos_s']:8.1f} s mission] {kind:<8} {what}", flush=True)

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


class TickWatch:
    """Which apps of each community fell behind their AppTick: every app's <NAME>_STATUS (its Iterations
    and TicksMissed, posted every 2 s), read from each community's MOOSDB; counted from the first
    status seen (so from when the watch starts, not from the launch)."""

    def __init__(self, communities: list[Community], warp: float):
        self.clients = {c.name: MOOSClient("uDemoTickWatch", port=c.moos_port, time_warp=warp,
                                           on_mail=lambda mail, name=c.name: self.on_mail(name, mail))
                        for c in communities}
        self.first: dict[tuple[str, str], tuple[int, int]] = {}   # (community, MOOSName) -> (Iterations, TicksMissed)
        self.last: dict[tuple[str, str], tuple[int, int]] = {}
        self.tasks: list[asyncio.Task] = []

    def start(self) -> None:
        for client in self.clients.values():
            client.on_connect = lambda client=client: client.register_wildcard("*_STATUS")
            self.tasks.append(asyncio.create_task(client.run()))

    def on_mail(self, community: str, mail) -> None:
        for msg in mail:
            ticks = status_ticks(msg.string) if msg.key.endswith("_STATUS") else None
            if ticks and msg.community in ("", community):   # not another community's, shared by pShare
                app = (community, ticks[0])
                self.first.setdefault(app, ticks[1:])
                self.last[app] = ticks[1:]

    def behind(self) -> list[dict]:
        """The apps that missed more than BEHIND_SHARE of their AppTicks since the first status seen."""
        return [{"community": community, "app": app, "missed": missed, "due": due}
                for (community, app), missed, due in fell_behind(self.first, self.last)]

    async def close(self) -> None:
        for client in self.clients.values():
            client.close()
        if self.tasks:
            await asyncio.wait(self.tasks, timeout=5)


async def wait_for(predicate, timeout: float, what: str, mission: OilspillMission | None = None,
                   quiet: bool = False, progress: Callable[[], None] | None = None, every: float = 5.0) -> None:
    """Poll until `predicate()` holds; fail naming `what` (and any community that died), or with
    `quiet` just return at the deadline. `progress` is called every `every` wall seconds of waiting,
    so a long wait says how it is going."""
    deadline = time.monotonic() + timeout
    next_progress = time.monotonic() + every
    while not predicate():
        if progress is not None and time.monotonic() >= next_progress:
            progress()
            next_progress += every
        if mission is not None and mission.dead():
            raise RuntimeError(f"while waiting for {what}: {', '.join(mission.dead())} stopped (see logs/antler_*.txt)")
        if time.monotonic() > deadline:
            if quiet:
                return
            raise TimeoutError(f"{what}: not within {timeout:.0f} s")
        await asyncio.sleep(0.05)
