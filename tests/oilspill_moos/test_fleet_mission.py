"""missions/fleet: the templates expand into one community per vehicle, and the fleet talks."""
from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import async_wait_until

from moosdb_py.client import MOOSClient
from moosdb_py.mission import read_mission

FLEET = Path(__file__).resolve().parents[2] / "missions" / "fleet"


def load_launcher():
    spec = importlib.util.spec_from_file_location("fleet_launch", FLEET / "launch.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_templates_expand_into_separate_communities(tmp_path):
    launcher = load_launcher()
    files = launcher.generate(launcher.plan(3, 10.0, 9500, 9700), tmp_path)
    missions = [read_mission(f) for f in files]
    assert [m.community for m in missions] == ["shoreside", "abe", "ben", "cal"]
    assert [m.server_port for m in missions] == [9500, 9501, 9502, 9503]
    assert {m.time_warp for m in missions} == {10.0}
    routes = [m.process_config("pShare").get("input") for m in missions]
    assert routes == [f"route = localhost:{9700 + i}" for i in range(4)]
    for vehicle in missions[1:]:
        broker = vehicle.process_config("uFldNodeBroker")
        assert broker.get("try_shore_host") == "pshare_route=localhost:9700"
        assert "src=NODE_REPORT_LOCAL,  alias=NODE_REPORT" in broker.get_all("bridge")
        bhv = (tmp_path / f"targ_{vehicle.community}.bhv").read_text()
        assert "$(" not in bhv
    shore = missions[0].process_config("uFldShoreBroker")
    assert any("DEPLOY" in q for q in shore.get_all("qbridge"))
    assert [r.exe for r in missions[1].antler.runs][:1] == ["MOOSDB"]


def test_launcher_rejects_bad_fleet_sizes(tmp_path):
    launcher = load_launcher()
    with pytest.raises(ValueError, match="--vehicles"):
        launcher.plan(0, 1.0)
    assert launcher.main(["--vehicles", "99", "--generate-only", "--dir", str(tmp_path)]) == 2


# --- the fleet running: shoreside + 3 vehicles, each community launched by pAntler ---------------

WARP = 10
APPS = ["MOOSDB", "pShare", "uFldShoreBroker", "uFldNodeBroker", "uSimMarineV22", "pNodeReporter"]


def port_block(kind: int, count: int) -> int:
    """A base port such that base..base+count-1 are all free for `kind` (SOCK_STREAM or SOCK_DGRAM)."""
    for _ in range(50):
        with socket.socket(socket.AF_INET, kind) as probe:
            probe.bind(("127.0.0.1", 0))
            base = probe.getsockname()[1]
        if base + count >= 65536:
            continue
        try:
            with contextlib.ExitStack() as stack:
                for port in range(base, base + count):
                    stack.enter_context(socket.socket(socket.AF_INET, kind)).bind(("127.0.0.1", port))
            return base
        except OSError:
            continue
    raise RuntimeError("no block of free ports")


class Fleet:
    """One pAntler per community, each in its own process group."""

    def __init__(self, files: list[Path]):
        self.files = {f.stem.removeprefix("targ_"): f for f in files}
        self.antlers: dict[str, subprocess.Popen] = {}

    def start(self, name: str) -> None:
        f = self.files[name]
        self.antlers[name] = subprocess.Popen(
            [sys.executable, "-m", "moosdb_py.antler", "--one-process", "--quiet", f.name, *APPS],
            cwd=f.parent, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def kill(self, name: str) -> None:
        proc = self.antlers.pop(name)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)  # a crash, not a clean shutdown
        proc.wait(timeout=10)

    def stop_all(self) -> None:
        for proc in self.antlers.values():
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in self.antlers.values():
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()


class Watcher:
    """A test client on one community's DB that keeps what it receives."""

    def __init__(self, community: str, port: int, keys: list[str]):
        self.mail: list = []
        self.keys = keys
        self.connections = 0
        self.client = MOOSClient(f"test_{community}", "127.0.0.1", port, on_mail=self.mail.extend,
                                 on_connect=self.on_connect, time_warp=WARP)

    def on_connect(self) -> None:
        self.connections += 1
        for key in self.keys:
            self.client.register(key)

    def values(self, key: str) -> list:
        return [m.value for m in self.mail if m.key == key]

    def reporters(self, since: float = 0.0) -> set[str]:
        """Communities whose NODE_REPORT was stamped after `since` (MOOS time): mail still in the socket
        from before a crash does not count."""
        return {m.community for m in self.mail if m.key == "NODE_REPORT" and m.time > since}


def test_fleet_bridges_survive_restarts(tmp_path):
    launcher = load_launcher()
    moos_base, udp_base = port_block(socket.SOCK_STREAM, 4), port_block(socket.SOCK_DGRAM, 4)
    communities = launcher.plan(3, WARP, moos_base, udp_base)
    fleet = Fleet(launcher.generate(communities, tmp_path))
    vehicles = ["abe", "ben", "cal"]
    ports = {c.name: c.moos_port for c in communities}
    shore = Watcher("shoreside", ports["shoreside"], ["NODE_REPORT", "PSHARE_OUTPUT_SUMMARY", "UFSB_NODE_COUNT"])
    boats = {v: Watcher(v, ports[v], ["DEPLOY", "X"]) for v in vehicles}

    async def until(predicate, timeout=30.0):
        await async_wait_until(predicate, timeout, interval=0.05)

    async def poke_until(key, value, seen_by, timeout=30.0):
        """Post on the shoreside (again every half second) until each vehicle in seen_by has it."""
        deadline = time.monotonic() + timeout
        while not all(value in boats[v].values(key.rsplit("_", 1)[0]) for v in seen_by):
            assert time.monotonic() < deadline, (
                f"{key}={value} did not reach {seen_by}; shoreside: nodes "
                f"{shore.values('UFSB_NODE_COUNT')[-1:]}, pShare outputs {shore.values('PSHARE_OUTPUT_SUMMARY')[-1:]}")
            shore.client.notify(key, value)
            await asyncio.sleep(0.5)

    async def scenario():
        tasks = [asyncio.create_task(w.client.run()) for w in (shore, *boats.values())]
        await until(lambda: shore.reporters() >= set(vehicles))  # every NODE_REPORT reaches the shore
        await poke_until("DEPLOY_ALL", "true", vehicles)
        await poke_until("X_BEN", "only-ben", ["ben"])
        await poke_until("DEPLOY_ALL", "again", vehicles)  # sent after X_BEN, on the same route
        assert boats["abe"].values("X") == [] and boats["cal"].values("X") == []
        # a vehicle crashes and is restarted: it handshakes again and its bridges come back
        fleet.kill("ben")
        restarted = shore.client.moos_time()
        fleet.start("ben")
        await until(lambda: "ben" in shore.reporters(since=restarted))
        await poke_until("X_BEN", "after-restart", ["ben"])
        # malformed datagrams on a vehicle's pShare port are dropped; nothing else is disturbed
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            for _ in range(3):
                raw.sendto(b"\xff" * 40, ("127.0.0.1", udp_base + 1))
        # the shoreside crashes and is restarted: every vehicle is bridged again
        connections = shore.connections
        fleet.kill("shoreside")
        restarted = shore.client.moos_time()
        fleet.start("shoreside")
        await until(lambda: shore.connections > connections)   # `connected` may not have noticed the crash yet
        await until(lambda: shore.reporters(since=restarted) >= set(vehicles))
        await poke_until("DEPLOY_ALL", "after-shore-restart", vehicles)
        for watcher in (shore, *boats.values()):
            watcher.client.close()
        await asyncio.wait_for(asyncio.gather(*tasks), 5)

    for name in ["shoreside", *vehicles]:
        fleet.start(name)
    try:
        asyncio.run(scenario())
    finally:
        fleet.stop_all()
    assert all(p.returncode is not None for p in fleet.antlers.values())
