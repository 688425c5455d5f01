"""The brokers as MOOSApps: shoreside and one vehicle, each with its own moosdb and pShare, over a lossy link."""
from __future__ import annotations

import asyncio
import logging
import socket

from helpers import async_wait_until, start_moosdb

from moosdb_py.client import MOOSClient
from moosdb_py.message import MOOSMsg
from moosdb_py.share import Share, encode_datagram
from oilspill_moos.field.node_broker import NodeBroker
from oilspill_moos.field.shore_broker import ShoreBroker

WARP = 10  # pings every 5 s of MOOS time are 0.5 s here


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LossyRelay(asyncio.DatagramProtocol):
    """Forwards datagrams to `target`, dropping every other one (starting with the first)."""

    def __init__(self, target: tuple[str, int]):
        self.target, self.seen, self.dropped, self.lossy = target, 0, 0, True

    def connection_made(self, transport):
        self.transport = transport

    def datagram_received(self, data, _addr):
        self.seen += 1
        if self.lossy and self.seen % 2 == 1:  # the first one, the third, ...
            self.dropped += 1
            return
        self.transport.sendto(data, self.target)


class Watcher:
    def __init__(self, name, port, keys):
        self.keys, self.mail = keys, []
        self.client = MOOSClient(name, "127.0.0.1", port, on_mail=self.mail.extend, on_connect=self.subscribe,
                                 time_warp=WARP)

    def subscribe(self):
        for key in self.keys:
            self.client.register(key)

    def values(self, key):
        return [m.value for m in self.mail if m.key == key]


def mission(path, community, db_port, udp_port, blocks):
    path.write_text(
        f"ServerHost = localhost\nServerPort = {db_port}\nCommunity = {community}\nMOOSTimeWarp = {WARP}\n\n"
        f"ProcessConfig = pShare\n{{\n  AppTick = 10\n  input = route = localhost:{udp_port}\n}}\n\n{blocks}")
    return path


def test_handshake_over_a_lossy_link_then_bridges(tmp_path, caplog):
    shore_db = start_moosdb("--moos_community", "shoreside")
    abe_db = start_moosdb("--moos_community", "abe")
    shore_udp, abe_udp, to_shore, to_abe = (free_udp_port() for _ in range(4))
    shore_file = mission(tmp_path / "shore.moos", "shoreside", shore_db.port, shore_udp, (
        "ProcessConfig = uFldShoreBroker\n{\n  AppTick = 4\n  qbridge = DEPLOY\n  bridge = src=RETURN_$V, alias=RETURN\n}\n"))
    abe_file = mission(tmp_path / "abe.moos", "abe", abe_db.port, abe_udp, (
        "ProcessConfig = uFldNodeBroker\n{\n  AppTick = 4\n"
        f"  try_shore_host = pshare_route=localhost:{to_shore}\n"
        "  bridge = src=NODE_REPORT_LOCAL, alias=NODE_REPORT\n}\n"))
    apps = [Share(shore_file), ShoreBroker(shore_file), Share(abe_file), NodeBroker(abe_file)]
    shore = Watcher("shore_watch", shore_db.port, ["NODE_REPORT", "UFSB_NODE_COUNT"])
    abe = Watcher("abe_watch", abe_db.port, ["DEPLOY", "RETURN", "NODE_BROKER_ACK"])

    async def scenario():
        loop = asyncio.get_running_loop()
        relays = []
        for port, target in ((to_shore, shore_udp), (to_abe, abe_udp)):
            _, relay = await loop.create_datagram_endpoint(lambda t=target: LossyRelay(("127.0.0.1", t)),
                                                           local_addr=("127.0.0.1", port))
            relays.append(relay)
        tasks = [asyncio.create_task(a.run_async()) for a in apps]
        tasks += [asyncio.create_task(w.client.run()) for w in (shore, abe)]
        for runner in (*apps, shore, abe):
            assert await runner.client.wait_connected(5.0)
        # stands in for pHostInfo: the shore must reach abe through the relay
        abe.client.notify("PHI_HOST_INFO", f"community=abe,hostip=localhost,port_db={abe_db.port},"
                                           f"pshare_iroutes=localhost:{to_abe},timewarp={WARP}")
        await async_wait_until(lambda: abe.values("NODE_BROKER_ACK"), 20)
        ack = abe.mail[[m.key for m in abe.mail].index("NODE_BROKER_ACK")]
        assert ack.community == "shoreside" and ",status=ok,key=0," in ack.string
        assert f"pshare_iroutes=localhost:{shore_udp}" in ack.string  # the shore's record, from its pShare
        assert sum(r.dropped for r in relays) > 0
        for relay in relays:
            relay.lossy = False
        abe.client.notify("NODE_REPORT_LOCAL", "NAME=abe,X=1,Y=2")
        await async_wait_until(lambda: shore.values("NODE_REPORT"), 10)
        report = next(m for m in shore.mail if m.key == "NODE_REPORT")
        assert (report.community, report.source) == ("abe", "abe_watch")
        shore.client.notify("DEPLOY_ALL", "true")
        shore.client.notify("RETURN_ABE", "true")
        await async_wait_until(lambda: abe.values("DEPLOY") == ["true"] and abe.values("RETURN") == ["true"], 10)
        assert shore.values("UFSB_NODE_COUNT")[-1] == 1.0
        # a ping that is not a host record, from another community: logged and dropped
        bad = MOOSMsg.notification("NODE_BROKER_PING", "no fields here", time=0.0, source="intruder")
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
            raw.sendto(encode_datagram(bad, "NODE_BROKER_PING", "zed"), ("127.0.0.1", shore_udp))
        await async_wait_until(lambda: "NODE_BROKER_PING from intruder@zed dropped" in caplog.text, 5)
        shore.client.notify("DEPLOY_ALL", "again")
        await async_wait_until(lambda: abe.values("DEPLOY") == ["true", "again"], 10)
        for app in apps:
            app.stop()
        for watcher in (shore, abe):
            watcher.client.close()
        await asyncio.wait_for(asyncio.gather(*tasks), 5)
        for relay in relays:
            relay.transport.close()

    try:
        with caplog.at_level(logging.WARNING):
            asyncio.run(scenario())
    finally:
        shore_db.stop()
        abe_db.stop()


def test_a_misspelt_parameter_is_named_with_its_place(tmp_path, caplog):
    path = mission(tmp_path / "abe.moos", "abe", 9000, free_udp_port(),
                   "ProcessConfig = uFldNodeBroker\n{\n  try_shore_hots = pshare_route=localhost:9200\n}\n")
    broker = NodeBroker(path)
    with caplog.at_level(logging.WARNING):
        broker.on_startup()
    assert f"{path}:14: unhandled parameter 'try_shore_hots'" in caplog.text
