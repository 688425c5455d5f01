"""Running a mission headless for end-to-end tests: a copy with its own port and time warp, launched
with pAntler, watched by a MOOS client, deployed with uPokeDB, and judged from pLogger's alog; and
missions/oilspill itself, started and deployed, or its vehicle helm driven by hand."""
from __future__ import annotations

import asyncio
import contextlib
import math
import re
import shutil
import signal
import sys
import threading
from pathlib import Path

from behaviors.bhv_file import parse_bhv
from behaviors.domain import IvPDomain, parse_domain_line
from behaviors.helm import Helm
from moosdb_py.alog import Alog, read_alog
from moosdb_py.client import MOOSClient
from moosdb_py.nsplug import preprocess
from helpers import wait_until
from oilspill_moos.oilspill_mission import Observer, OilspillMission

BIN = Path(sys.executable).parent
MISSIONS = Path(__file__).resolve().parents[1] / "missions"


def prepare(mission_dir: Path, moos_name: str, folder: Path, port: int, warp: float) -> Path:
    """Copy the mission's files into `folder`, with ServerPort and MOOSTimeWarp set in the .moos file.

    Setting them in the file (not as pAntler overrides) lets uPokeDB, reading the same file, stamp
    its mail with the same warped clock as the apps.
    """
    for path in mission_dir.iterdir():
        if path.suffix in (".moos", ".bhv"):
            shutil.copy(path, folder / path.name)
    target = folder / moos_name
    text = target.read_text()
    for name, value in (("ServerPort", port), ("MOOSTimeWarp", warp)):
        text, count = re.subn(rf"(?m)^\s*{name}\s*=.*$", f"{name} = {value}", text)
        assert count == 1, f"{target}: expected one {name} line"
    target.write_text(text)
    return target


@contextlib.asynccontextmanager
async def headless(mission_file: Path, port: int, warp: float, keys: list[str], timeout: float = 20.0,
                   antler_args: tuple[str, ...] = ("--one-process",)):
    """pAntler running the mission (cwd = its folder) and a connected watcher registered for `keys`.

    `--one-process` (the default here) hosts the Python apps in pAntler's interpreter: each is still
    its own MOOS client, but the mission starts in a few seconds on a busy machine.
    """
    log = open(mission_file.parent / "antler.log", "wb")
    antler = await asyncio.create_subprocess_exec(
        str(BIN / "pAntler"), mission_file.name, *antler_args, cwd=mission_file.parent, stdout=log,
        stderr=asyncio.subprocess.STDOUT, start_new_session=True)
    watcher = MOOSClient("uMissionWatch", port=port, time_warp=warp)
    for key in keys:
        watcher.register(key)
    watching = asyncio.create_task(watcher.run())
    try:
        assert await watcher.wait_connected(timeout), "the mission's MOOSDB did not come up"
        yield watcher
    finally:
        watcher.close()
        with contextlib.suppress(ProcessLookupError):
            antler.send_signal(signal.SIGINT)   # pAntler stops its children, pLogger closes the alog
        try:
            await asyncio.wait_for(antler.wait(), 15)
        except TimeoutError:
            antler.kill()
            await antler.wait()
        await asyncio.wait_for(watching, 5)
        log.close()


async def until_helm_is_up(watcher: MOOSClient, timeout: float = 20.0) -> None:
    """Wait for the helm's first IVPHELM_STATE (its `initialize` values are posted by then) and nav."""
    deadline = asyncio.get_running_loop().time() + timeout
    while not (latest(watcher, "IVPHELM_STATE") and latest(watcher, "NAV_X") is not None):
        assert asyncio.get_running_loop().time() < deadline, "no IVPHELM_STATE and NAV_X from the mission"
        await asyncio.sleep(0.05)


async def poke(mission_file: Path, *assignments: str) -> None:
    proc = await asyncio.create_subprocess_exec(str(BIN / "uPokeDB"), mission_file.name, *assignments,
                                                cwd=mission_file.parent, stdout=asyncio.subprocess.PIPE,
                                                stderr=asyncio.subprocess.STDOUT)
    out, _ = await asyncio.wait_for(proc.communicate(), 30)
    assert proc.returncode == 0, out.decode(errors="replace")


def latest(watcher: MOOSClient, key: str):
    """The last value of `key` the watcher has received, or None."""
    return next((m.value for m in reversed(watcher.inbox) if m.key == key), None)


def mission_alog(folder: Path) -> Alog:
    logs = sorted(folder.glob("LOG_*/*.alog"))
    assert len(logs) == 1, f"expected one alog in {folder}, found {logs}"
    return read_alog(logs[0])


def nav_track(alog: Alog) -> list[tuple[float, float, float]]:
    """(time, x, y) from the NAV_X/NAV_Y pairs uSimMarine posts together."""
    track, x = [], None
    for entry in alog.entries:
        if entry.key == "NAV_X":
            x = entry.value
        elif entry.key == "NAV_Y" and x is not None:
            track.append((entry.time, x, entry.value))
            x = None
    return track


def distance(point: tuple[float, float], x: float, y: float) -> float:
    return math.hypot(x - point[0], y - point[1])


@contextlib.contextmanager
def deployed(mission: OilspillMission, clients: tuple[MOOSClient, ...] = (), timeout: float = 40.0):
    """missions/oilspill started, an Observer on its shoreside and `clients` running in a thread of
    their own, every vehicle reporting and deployed; yields (observer, loop). On exit the clients
    close and the mission stops."""
    mission.start()
    loop = asyncio.new_event_loop()
    observer = Observer("127.0.0.1", mission.shoreside.moos_port, mission.warp)
    everyone = (observer.client, *clients)

    async def run_clients():
        await asyncio.gather(*(client.run() for client in everyone))

    thread = threading.Thread(target=loop.run_until_complete, args=(run_clients(),), daemon=True)
    thread.start()
    try:
        wait_until(lambda: mission.dead() or observer.vehicles_seen() >= set(mission.fleet), timeout=timeout)
        assert not mission.dead(), f"communities stopped: {mission.dead()}"
        asyncio.run_coroutine_threadsafe(observer.deploy(mission.fleet, timeout, mission), loop).result(timeout + 5)
        yield observer, loop
    finally:
        for client in everyone:
            loop.call_soon_threadsafe(client.close)
        thread.join(timeout=5)
        mission.stop()


class VehicleHelm:
    """meta_vehicle.bhv expanded with nsplug, driven by hand: mail in, posts out, position set directly."""

    def __init__(self, tmp_path, **defines):
        target = tmp_path / "targ_abe.bhv"
        lines = preprocess(MISSIONS / "oilspill" / "meta_vehicle.bhv", {"VNAME": "abe", "START_POS": "0,0", **defines})
        target.write_text("".join(line.text + "\n" for line in lines))
        domain = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41")])
        self.helm = Helm([parse_bhv(preprocess(target), target)], domain, "abe", active_start=True)
        self.now = 0.0
        self.posts = self.helm.startup(self.now)
        self.at(0.0, 0.0)

    def at(self, x, y):
        for key, value in (("NAV_X", x), ("NAV_Y", y), ("NAV_HEADING", 0.0), ("NAV_SPEED", 0.0)):
            self.helm.on_mail(key, value, self.now)

    def mail(self, **values):
        for key, value in values.items():
            self.helm.on_mail(key, value, self.now)

    def run(self, seconds):
        for _ in range(int(seconds * 4)):
            self.now += 0.25
            posts = self.helm.iterate(self.now)
            self.posts += posts
            for key, value, _ in posts:  # the helm's own flags come back as mail, as through the MOOSDB
                if key in ("STATION_KEEP", "COMMS_LOST", "DEPLOY"):
                    self.helm.on_mail(key, value, self.now)
        return self

    def last(self, key):
        return next((value for k, value, _ in reversed(self.posts) if k == key), None)
