"""The `moosdb` command: real processes on loopback ports, talked to with raw sockets."""
from __future__ import annotations

import socket
import subprocess
import sys
import time

from helpers import free_port, start_moosdb
from moosdb_py import codec
from moosdb_py.message import MOOSMsg


class RawClient:
    """A blocking client speaking the wire protocol directly (no moosdb_py client involved)."""

    def __init__(self, port: int, name: str, asynchronous: bool = True):
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
        self.framer = codec.StreamFramer()
        hello = MOOSMsg("i", "S", "asynchronous" if asynchronous else "", string=name, time=time.time())
        self.sock.sendall(codec.PROTOCOL_SLOT + codec.encode_packet([hello]))
        self.pending: list[bytes] = []

    def packet(self) -> list[MOOSMsg]:
        while not self.pending:
            data = self.sock.recv(65536)
            if not data:
                raise ConnectionError("closed by the DB")
            self.pending.extend(self.framer.units(data))
        return codec.decode_packet(self.pending.pop(0))

    def send(self, *msgs: MOOSMsg) -> None:
        self.sock.sendall(codec.encode_packet(msgs))

    def close(self) -> None:
        self.sock.close()


def test_welcome_from_default_db(moosdb_server):
    client = RawClient(moosdb_server.port, "hello")
    (welcome,) = client.packet()
    assert (welcome.msg_type, welcome.community, welcome.string) == ("W", "#1", "asynchronous")
    assert welcome.source_aux == f"hostname={socket.gethostname()}"
    assert abs(welcome.time - time.time()) < 5
    client.close()


def test_mission_file_and_flags(tmp_path):
    port = free_port()
    mission = tmp_path / "m.moos"
    mission.write_text(f"ServerHost = localhost\nServerPort = {port}\nCommunity = alpha\nMOOSTimeWarp = 10\n")
    db = start_moosdb(str(mission), port=port)
    try:
        client = RawClient(port, "c")
        (welcome,) = client.packet()
        assert welcome.community == "alpha"
        assert abs(welcome.time / 10 - time.time()) < 5    # MOOS time is warped
        client.send(MOOSMsg("Q", "S", "VAR_SUMMARY", id=-2, source="c"))
        (summary,) = client.packet()
        assert summary.source == "MOOSDB_alpha" and "DB_CLIENTS" in summary.string
        client.close()
    finally:
        db.stop()
    db = start_moosdb(str(mission), "--moos_community=beta", "--response=c*:250", port=port)
    try:
        client = RawClient(port, "c")
        assert client.packet()[0].community == "beta"
        client.send(MOOSMsg("T", "D", "_async_timing", 0.0, time=time.time() * 10))
        (echo,) = client.packet()
        assert echo.key == "_async_timing" and echo.double_aux == 0.25    # consolidation period from --response
        client.close()
    finally:
        db.stop()


def test_db_clear_forgets_values(moosdb_server):
    client = RawClient(moosdb_server.port, "clearer")
    client.packet()
    client.send(MOOSMsg.notification("X", 1.0, time=1.0, source="clearer"),
                MOOSMsg("Q", "S", "DB_CLEAR", id=-2, source="clearer"),
                MOOSMsg("R", "D", "X", 0.0, source="clearer"),
                MOOSMsg("Q", "S", "VAR_SUMMARY", id=-2, source="clearer"))
    (summary,) = client.packet()          # X was cleared: no current value comes back on register
    assert summary.key == "VAR_SUMMARY" and "X" in summary.string.split(",")
    client.send(MOOSMsg.notification("X", 2.0, time=1.0, source="clearer"))
    (back,) = client.packet()             # the subscription survives DB_CLEAR
    assert back.value == 2.0
    client.close()


def test_help_and_bad_mission(tmp_path):
    out = subprocess.run([sys.executable, "-m", "moosdb_py.moosdb", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "--moos_port" in out.stdout and "127.0.0.1" in out.stdout
    bad = tmp_path / "bad.moos"
    bad.write_text("ServerPort = not_a_port\n")
    out = subprocess.run([sys.executable, "-m", "moosdb_py.moosdb", str(bad)], capture_output=True, text=True)
    assert out.returncode == 1 and "bad.moos:1" in out.stderr


def test_writes_in_one_packet_keep_order_and_throttling(moosdb_server):
    sub, slow = RawClient(moosdb_server.port, "all"), RawClient(moosdb_server.port, "slow")
    sub.packet()
    slow.packet()
    sub.send(MOOSMsg("R", "D", "X", 0.0, source="all"), MOOSMsg("R", "D", "Y", 0.0, source="all"))
    slow.send(MOOSMsg("R", "D", "X", 10.0, source="slow"), MOOSMsg("Q", "S", "VAR_SUMMARY", id=-2, source="slow"))
    slow.packet()                         # the registrations are in
    writes = [("X", 1.0), ("X", 2.0), ("Y", 1.0), ("X", 3.0), ("X", 4.0)]
    sub.send(*(MOOSMsg.notification(k, v, time=1.0, source="all") for k, v in writes))
    got = []
    while len(got) < len(writes):
        got += [(m.key, m.value) for m in sub.packet()]
    assert got == writes
    assert [(m.key, m.value) for m in slow.packet()] == [("X", 1.0)]   # one per 10 s: the rest dropped
    sub.close()
    slow.close()
