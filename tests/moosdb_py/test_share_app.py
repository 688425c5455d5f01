"""pShare as a MOOSApp: two communities (two real moosdb processes) bridged over loopback UDP."""
from __future__ import annotations

import asyncio
import logging
import socket
import subprocess
import sys

import pytest
from helpers import async_wait_until, start_moosdb

from moosdb_py.app import MOOSApp
from moosdb_py.client import MOOSClient
from moosdb_py.message import MOOSMsg
from moosdb_py.share import MAX_DATAGRAM, Share


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_mission(path, community, db_port, share_lines):
    body = "\n".join(f"  {line}" for line in share_lines)
    path.write_text(f"ServerHost = localhost\nServerPort = {db_port}\nCommunity = {community}\nMOOSTimeWarp = 1\n\n"
                    f"ProcessConfig = pShare\n{{\n  AppTick = 20\n{body}\n}}\n")
    return path


class Mailbox:
    """A test client that keeps every message it receives, by variable."""

    def __init__(self, name, port, keys):
        self.mail: dict[str, list] = {}
        self.client = MOOSClient(name, "127.0.0.1", port, on_mail=self.take, on_connect=self.subscribe)
        self.keys = keys

    def subscribe(self):
        for key in self.keys:
            self.client.register(key)

    def take(self, mail):
        for msg in mail:
            self.mail.setdefault(msg.key, []).append(msg)

    def values(self, key):
        return [m.value for m in self.mail.get(key, [])]


@pytest.fixture
def communities(tmp_path):
    shore_db = start_moosdb("--moos_community", "shoreside")
    abe_db = start_moosdb("--moos_community", "abe")
    yield tmp_path, shore_db, abe_db
    shore_db.stop()
    abe_db.stop()


async def started(*runners):
    tasks = [asyncio.create_task(r.run_async() if isinstance(r, MOOSApp) else r.client.run()) for r in runners]
    for runner in runners:
        client = runner.client
        assert await client.wait_connected(5.0), f"{client.name} did not connect"
    return tasks


async def stopped(runners, tasks):
    for runner in runners:
        runner.stop() if isinstance(runner, MOOSApp) else runner.client.close()
    await asyncio.wait_for(asyncio.gather(*tasks), 5.0)


def test_forwarding_renaming_commands_echo_and_bad_datagrams(communities, caplog):
    tmp_path, shore_db, abe_db = communities
    shore_udp, abe_udp = free_udp_port(), free_udp_port()
    multicast_base = free_udp_port() - 3  # so that multicast_3 is a port nobody uses
    shore_share = Share(write_mission(tmp_path / "shore.moos", "shoreside", shore_db.port, [
        f"input = route = localhost:{shore_udp}",
        f"multicast_base_port = {multicast_base}",
        "output = src_name = M, route = multicast_3",
        f"output = src_name = X_ALL, dest_name = X, route = localhost:{abe_udp}",
        f"output = NAV_*->V_:localhost:{abe_udp}",
        f"output = src_name = ECHO_ALL, dest_name = ECHO, route = localhost:{abe_udp}",
    ]))
    abe_share = Share(write_mission(tmp_path / "abe.moos", "abe", abe_db.port, [
        f"input = route = localhost:{abe_udp} & multicast_3",
        f"multicast_base_port = {multicast_base}",
        f"output = src_name = ECHO, dest_name = ECHO_ALL, route = localhost:{shore_udp}",  # a loop
    ]))
    shore = Mailbox("poker", shore_db.port, ["X_ALL", "Y", "ECHO_ALL"])
    abe = Mailbox("watcher", abe_db.port, ["X", "V_NAV_X", "ECHO", "M", "PSHARE_INPUT_SUMMARY"])

    async def scenario():
        runners = [shore_share, abe_share, shore, abe]
        tasks = await started(*runners)
        shore.client.notify("X_ALL", "one")
        await async_wait_until(lambda: abe.values("X") == ["one"], 5)
        got = abe.mail["X"][0]
        assert (got.source, got.community) == ("poker", "shoreside")  # the real writer and its community
        shore.client.notify("NAV_X", 12.5)
        await async_wait_until(lambda: abe.values("V_NAV_X") == [12.5], 5)
        shore.client.notify("M", "to the group")
        await async_wait_until(lambda: abe.values("M") == ["to the group"], 5)
        # ECHO_ALL -> abe's ECHO -> shore's ECHO_ALL would loop; a pShare drops what it forwards itself
        shore.client.notify("ECHO_ALL", "ping")
        await async_wait_until(lambda: abe_share.counts["echo"] == 1, 5)
        abe.client.notify("ECHO", "pong")
        await async_wait_until(lambda: shore_share.counts["echo"] == 1, 5)
        assert shore.values("ECHO_ALL") == ["ping"] and abe.values("ECHO") == ["pong"]
        # run-time configuration
        abe.client.notify("PSHARE_CMD", f"cmd=output,src_name=Y,route=localhost:{shore_udp}")
        await async_wait_until(lambda: "Y->Y:localhost" in abe_share.table.output_summary(), 5)
        abe.client.notify("Y", 7.0)
        await async_wait_until(lambda: shore.values("Y") == [7.0], 5)
        abe.client.notify("PSHARE_CMD", "cmd=output,src_name=Y")
        await async_wait_until(lambda: "rejected" in caplog.text, 5)
        # garbage on the input port is logged and dropped; forwarding goes on
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.sendto(b"\x07\x00\x00\x00garbage", ("127.0.0.1", abe_udp))
        await async_wait_until(lambda: abe_share.counts["malformed"] == 1, 5)
        # too large for a datagram: a clear error, and the next value still goes
        shore.client.notify("X_ALL", "z" * MAX_DATAGRAM)
        await async_wait_until(lambda: shore_share.counts["oversize"] == 1, 5)
        shore.client.notify("X_ALL", "two")
        await async_wait_until(lambda: abe.values("X") == ["one", "two"], 5)
        await async_wait_until(lambda: abe.values("PSHARE_INPUT_SUMMARY")[-1:] == [
            f"localhost:{abe_udp},224.1.1.11:{multicast_base + 3}:multicast_3"], 5)
        await stopped(runners, tasks)

    with caplog.at_level(logging.WARNING):
        asyncio.run(scenario())
    assert "malformed datagram from 127.0.0.1" in caplog.text
    assert "X_ALL -> X:" in caplog.text and "not forwarded" in caplog.text


def test_bad_config_names_file_and_line(tmp_path):
    mission = write_mission(tmp_path / "bad.moos", "abe", 9000, ["output = src_name=X, route=nowhere"])
    app = Share(mission)
    with pytest.raises(ValueError, match=r"bad\.moos:\d+: output: route 'nowhere'"):
        asyncio.run(_startup(app))
    app = Share(write_mission(tmp_path / "port.moos", "abe", 9000, ["multicast_base_port = 90a0"]))
    with pytest.raises(ValueError, match=r"port\.moos:\d+: multicast_base_port: '90a0' is not a port number"):
        asyncio.run(_startup(app))


def test_port_in_use_is_a_clear_error(tmp_path):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as taken:
        taken.bind(("127.0.0.1", 0))
        port = taken.getsockname()[1]
        app = Share(write_mission(tmp_path / "busy.moos", "abe", 9000, [f"input = route = localhost:{port}"]))
        with pytest.raises(ValueError, match=f"cannot listen on localhost:{port}"):
            asyncio.run(_startup(app))


def test_commands_from_before_start_up_are_stale(tmp_path):
    app = Share(write_mission(tmp_path / "cmd.moos", "abe", 9000, []))
    cmd = "cmd=output,src_name=A,route=localhost:9"

    async def scenario():
        app.on_startup()
        app.on_new_mail([MOOSMsg.notification("PSHARE_CMD", cmd, time=app.start_time - 1.0)])
        assert app.table.outputs == {}
        app.on_new_mail([MOOSMsg.notification("PSHARE_CMD", cmd, time=app.start_time + 1.0)])
        assert list(app.table.outputs) == ["A"]
        app.close_sockets()

    asyncio.run(scenario())


async def _startup(app: Share):
    try:
        app.on_startup()
    finally:
        app.close_sockets()


def test_routes_from_the_command_line(moosdb_server):
    udp_in, udp_out = free_udp_port(), free_udp_port()
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from moosdb_py.share import main; sys.exit(main())",
                             f"--moos_port={moosdb_server.port}", f"-i=localhost:{udp_in}",
                             f"-o=X->Y:localhost:{udp_out}@2,Z->localhost:{udp_out}"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    watcher = Mailbox("cli_watch", moosdb_server.port, ["PSHARE_INPUT_SUMMARY", "PSHARE_OUTPUT_SUMMARY"])

    async def scenario():
        task = asyncio.create_task(watcher.client.run())
        await async_wait_until(lambda: watcher.values("PSHARE_OUTPUT_SUMMARY"), 10)
        watcher.client.close()
        await task

    try:
        asyncio.run(scenario())
    finally:
        proc.terminate()
        proc.wait(timeout=5)
    assert watcher.values("PSHARE_INPUT_SUMMARY")[-1] == f"localhost:{udp_in}"
    assert watcher.values("PSHARE_OUTPUT_SUMMARY")[-1] == f"X->Y:localhost:{udp_out}, Z->Z:localhost:{udp_out}"
