"""Issue 15's four-vehicle MOOS-IvP loiter mission, rebuilt from the corpus m2_berta and flown by this
stack: nsplug expands the corpus templates for a shoreside and four vehicles (as its launch script
would), pAntler launches each community, the shoreside's DEPLOY_ALL deploys them, and pLogger's
vehicle alogs say how far each vessel went.

The issue's mission (kept back from the corpus) is m2_berta's layout with the deprecated uSimMarine and
pMarinePID and a live BHV_AvoidCollision. The corpus m2_berta runs uSimMarineV22 / pMarinePIDV22 and
BHV_AvdColregsV22, with that BHV_AvoidCollision block commented out (`//Behavior = ...`). So the
variants: `deprecated` renames the two apps in the generated vehicle files (Run lines and
ProcessConfig blocks); the AvdColregsV22 block (a behaviour this helm does not have) is always taken
out; `avoid` uncomments the BHV_AvoidCollision header, `avoid=False` leaves the block commented
(an anonymous block the helm skips): the issue's "avoidance blocks removed". Nothing else changes.
Used by benchmarks/loiter_mission_bench.py and tests/oilspill_moos/test_corpus_loiter.py.
"""
from __future__ import annotations

import asyncio
import itertools
import math
import re
import socket
import time
from dataclasses import dataclass
from pathlib import Path

from helpers import CORPUS, free_port
import numpy as np

from moosdb_py.alog import read_alog
from moosdb_py.client import MOOSClient
from moosdb_py.nsplug import preprocess
from oilspill_moos.oilspill_mission import Community, OilspillMission

M2_BERTA = CORPUS / "m2_berta"
# name: (START_POS, LOITER_POS). abe's are the corpus README's; the shoreside's uTimerScript moves
# vehicles 1 and 2's loiter centres to about (0..5, -75) and (125, -75) at 180 s and back at 360 s.
VEHICLES = {"abe": ("x=0,y=0,heading=0", "x=0,y=-50"), "ben": ("x=80,y=0,heading=0", "x=125,y=-50"),
            "cal": ("x=-80,y=0,heading=0", "x=-75,y=-150"), "deb": ("x=160,y=0,heading=0", "x=200,y=-150")}
DEPLOY = (("DEPLOY_ALL", "true"), ("MOOS_MANUAL_OVERRIDE_ALL", "false"), ("AVOID_ALL", "true"),
          ("RETURN_ALL", "false"))     # the shoreside viewer's DEPLOY button (button_one)
CPP_DISTANCE_M = (1025.0, 1037.0)      # issue 15: the C++ vessels, avoidance removed, 900 simulated s


def _expand(template: Path, defines: dict[str, str], target: Path) -> str:
    text = "".join(line.text + "\n" for line in preprocess(template, defines))
    target.write_text(text)
    return text


def _drop_block(text: str, header: str) -> str:
    """Text without the block that starts at the `header` line (through its closing brace)."""
    lines = text.splitlines(keepends=True)
    start = next(i for i, line in enumerate(lines) if line.strip().replace(" ", "") == header.replace(" ", ""))
    end = next(i for i in range(start, len(lines)) if lines[i].strip() == "}")
    return "".join(lines[:start] + lines[end + 1:])


@dataclass
class LoiterMission(OilspillMission):
    """m2_berta for four vehicles in `folder` on free loopback ports; launching, stopping and the
    antler logs are OilspillMission's, the templates and macros are m2_berta's."""

    deprecated: bool = True
    avoid: bool = False

    def __post_init__(self):
        self.folder = Path(self.folder).resolve()
        shore_pshare = free_port(socket.SOCK_DGRAM)
        common = {"WARP": f"{self.warp:g}", "IP_ADDR": "localhost"}
        self.shoreside = Community("shoreside", free_port(), {**common, "PSHARE_PORT": str(shore_pshare),
                                                              "VNAMES": ":".join(VEHICLES)})
        self.shoreside.defines["MOOS_PORT"] = str(self.shoreside.moos_port)
        self.fleet = {}
        for name, (start, loiter) in VEHICLES.items():
            port = free_port()
            self.fleet[name] = Community(name, port, {
                **common, "VNAME": name, "MOOS_PORT": str(port), "PSHARE_PORT": str(free_port(socket.SOCK_DGRAM)),
                "SHORE_IP": "localhost", "SHORE_PSHARE": str(shore_pshare), "XMODE": "SIM", "START_POS": start,
                "LOITER_POS": loiter, "MAX_SPD": "2"})

    def generate(self) -> list[Path]:
        (self.folder / "logs").mkdir(parents=True, exist_ok=True)
        text = _expand(M2_BERTA / "meta_shoreside.moos", self.shoreside.defines, self.folder / "targ_shoreside.moos")
        # the shoreside's port (fixed at 9000 in the corpus file) and the viewer's web page on free
        # ports: two runs at once must not both want 9000 and 8080
        text = re.sub(r"(?m)^ServerPort\s*=.*$", f"ServerPort = {self.shoreside.moos_port}", text, count=1)
        text = re.sub(r"(ProcessConfig = pMarineViewer\s*\{)", rf"\1\n  http_port = {free_port()}", text, count=1)
        (self.folder / "targ_shoreside.moos").write_text(text)
        for v in self.fleet.values():
            moos = _expand(M2_BERTA / "meta_vehicle.moos", v.defines, self.folder / v.moos_file)
            if self.deprecated:
                moos = re.sub(r"\b(uSimMarine|pMarinePID)V22\b", r"\1", moos)
            (self.folder / v.moos_file).write_text(moos)
            bhv = _drop_block(_expand(M2_BERTA / "meta_vehicle.bhv", v.defines, self.folder / f"targ_{v.name}.bhv"),
                              "Behavior = BHV_AvdColregsV22")
            if self.avoid:
                bhv = bhv.replace("//Behavior = BHV_AvoidCollision", "Behavior = BHV_AvoidCollision")
            (self.folder / f"targ_{v.name}.bhv").write_text(bhv)
        return [self.folder / c.moos_file for c in self.communities]

    def antler_log(self, name: str) -> str:
        return (self.folder / "logs" / f"antler_{name}.txt").read_text(errors="replace")

    def alog(self, name: str) -> Path:
        """pLogger's `File = LOG_%(VNAME)`, `PATH = ./`, time-stamped: a folder in the mission's."""
        found = sorted(self.folder.glob(f"LOG_{name.upper()}_*/*.alog"))
        if not found:
            raise FileNotFoundError(f"no alog for {name} in {self.folder}")
        return found[-1]


def clients(value) -> set[str]:
    return {c for c in str(value or "").split(",") if c}


async def fly(mission: LoiterMission, seconds: float, timeout: float = 120.0) -> dict:
    """Wait for every vehicle's NODE_REPORT on the shoreside, deploy, fly `seconds` of MOOS time.
    Returns each community's DB_CLIENTS (as last seen) and the deploy's MOOS time."""
    watchers = {c.name: MOOSClient("uLoiterWatch", port=c.moos_port, time_warp=mission.warp) for c in mission.communities}
    for watcher in watchers.values():
        watcher.register("DB_CLIENTS")
    shore = watchers["shoreside"]
    for v in mission.fleet.values():
        shore.register(f"NODE_REPORT_{v.name.upper()}")
    tasks = [asyncio.create_task(w.run()) for w in watchers.values()]

    def latest(name, key):
        values = [m.value for m in watchers[name].inbox if m.key == key]
        return values[-1] if values else None

    async def until(predicate, what):
        deadline = time.monotonic() + timeout
        while not predicate():
            dead = mission.dead()
            if dead or time.monotonic() > deadline:
                raise TimeoutError(f"{what}: {'pAntler ended: ' + ', '.join(dead) if dead else 'timed out'}")
            await asyncio.sleep(0.1)

    try:
        await until(lambda: all(latest("shoreside", f"NODE_REPORT_{v.name.upper()}") for v in mission.fleet.values()),
                    "every vehicle reporting to the shoreside")
        for key, value in DEPLOY:
            shore.notify(key, value)
        deployed = shore.moos_time()
        await until(lambda: shore.moos_time() - deployed >= seconds, f"{seconds:g} s of flight")
        return {"deployed": deployed, "clients": {n: clients(latest(n, "DB_CLIENTS")) for n in watchers}}
    finally:
        for watcher in watchers.values():
            watcher.close()
        await asyncio.gather(*tasks, return_exceptions=True)


def distances(mission: LoiterMission, seconds: float) -> dict[str, float]:
    """Metres each vehicle's NAV_X/NAV_Y moved in the first `seconds` after its helm saw DEPLOY=true."""
    out = {}
    for v in mission.fleet.values():
        alog = read_alog(mission.alog(v.name))
        deploy = next(e.time for e in alog.entries if e.key == "DEPLOY" and str(e.value).lower() == "true")
        xs = {e.time: e.value for e in alog.entries if e.key == "NAV_X"}
        ys = {e.time: e.value for e in alog.entries if e.key == "NAV_Y"}
        track = [(xs[t], ys[t]) for t in sorted(xs) if t in ys and deploy <= t <= deploy + seconds]
        out[v.name] = sum(math.dist(a, b) for a, b in zip(track, track[1:]))
    return out


def closest_approach(mission: LoiterMission, seconds: float) -> float:
    """The least distance between any two vehicles while flying (their NAV_X/NAV_Y on the MOOS clock,
    interpolated every 0.5 s over the span all of them logged)."""
    tracks = []
    for v in mission.fleet.values():
        alog = read_alog(mission.alog(v.name))
        deploy = alog.log_start + next(e.time for e in alog.entries if e.key == "DEPLOY" and str(e.value).lower() == "true")
        xs = {alog.log_start + e.time: e.value for e in alog.entries if e.key == "NAV_X"}
        ys = {alog.log_start + e.time: e.value for e in alog.entries if e.key == "NAV_Y"}
        times = np.array(sorted(t for t in xs if t in ys and t <= deploy + seconds))
        tracks.append((times, np.array([xs[t] for t in times]), np.array([ys[t] for t in times])))
    grid = np.arange(max(t[0][0] for t in tracks), min(t[0][-1] for t in tracks), 0.5)
    at = [(np.interp(grid, t, x), np.interp(grid, t, y)) for t, x, y in tracks]
    return float(min(np.hypot(a[0] - b[0], a[1] - b[1]).min() for a, b in itertools.combinations(at, 2)))
