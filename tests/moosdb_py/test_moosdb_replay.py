"""Replay every conformance capture against the Python MOOSDB and compare its replies.

The DB runs in the test's own event loop on a loopback port, so after each client packet the test
can wait until the DB has consumed it (keeping the captured order between connections) instead of
sleeping. Timing-dependent scenarios are checked for their rule (conformance README, point 3).
"""
from __future__ import annotations

import asyncio
import time

import pytest

from helpers import async_wait_until, conformance_files, load_capture
from moosdb_py import codec
from moosdb_py.moosdb import MOOSDB

RULE_BASED = {"09_disconnect_events", "13_db_variables", "14_register_interval", "19_silent_client_timeout"}
VARIABLE_DVAL_TYPES = {".", "T", "W"}


def _timeline(cap: dict) -> list[dict]:
    """Packets plus client-side closes, in capture time order."""
    closes = [dict(c, kind="close") for c in cap["chunks"] if c.get("event") == "c2s_closed"]
    opened = {c["conn"]: c["t"] for c in cap["chunks"] if c.get("event") == "open"}
    units = [u if "t" in u else dict(u, t=opened[u["conn"]]) for u in cap["packets"]]
    return sorted(units + closes, key=lambda u: u["t"])


class ReplayClient:
    def __init__(self, reader, writer):
        self.reader, self.writer = reader, writer
        self.port = writer.get_extra_info("sockname")[1]
        self.mail: list = []          # (receive time, MOOSMsg)
        self.closed_at: float | None = None
        self.task = asyncio.create_task(self._read())

    async def _read(self):
        framer = codec.StreamFramer()
        try:
            while data := await self.reader.read(65536):
                for packet in framer.units(data):
                    self.mail.extend((time.monotonic(), m) for m in codec.decode_packet(packet))
        except ConnectionError:
            pass
        self.closed_at = time.monotonic()

    def send(self, data: bytes) -> None:
        if not self.writer.is_closing():
            self.writer.write(data)


def _db_side(db: MOOSDB, client: ReplayClient):
    return next((c for c in list(db.connections) + list(db.clients.values())
                 if c.peer == f"127.0.0.1:{client.port}"), None)


async def replay(cap: dict, db: MOOSDB, pace: float | None = None, until: float | None = None,
                 wait_replies: bool = True) -> dict:
    """Send each connection's bytes as captured; `pace` scales capture time into real waiting.

    After each client packet the DB has consumed it before the next is sent; with `wait_replies`
    each captured reply must also have arrived (rule-based scenarios expect different replies).
    """
    clients: dict[int, ReplayClient] = {}
    sides: dict[int, object] = {}       # the DB's ClientConnection of each
    expected: dict[int, int] = {}
    start = time.monotonic()
    for unit in _timeline(cap):
        if until is not None and unit["t"] > until:
            break
        if pace is not None:
            await asyncio.sleep(max(0.0, start + unit["t"] * pace - time.monotonic()))
        conn = unit["conn"]
        if conn not in clients:
            clients[conn] = ReplayClient(*await asyncio.open_connection(db.host, db.port))
            sides[conn] = await async_wait_until(lambda: _db_side(db, clients[conn]), 5)
        client, side = clients[conn], sides[conn]
        if unit["kind"] == "close":
            client.writer.close()
            await async_wait_until(lambda: side.state == "closed", 5)
        elif unit["dir"] == "s2c":
            if not wait_replies:
                continue
            expected[conn] = expected.get(conn, 0) + unit["decoded"]["num_msgs"]
            await async_wait_until(lambda: len(client.mail) >= expected[conn] or client.closed_at, 5)
        elif unit["kind"] == "protocol":
            client.send(unit["text"].encode("latin-1").ljust(32, b"\0"))
            await async_wait_until(lambda: side.packets_in, 5)
        else:
            before = side.packets_in
            client.send(bytes.fromhex(unit["hex"]))
            await async_wait_until(lambda: side.packets_in > before or side.state == "closed", 5)
    return clients


def _comparable(m: dict) -> tuple:
    dval = None if m["type"] in VARIABLE_DVAL_TYPES or m["key"].startswith("DB_") else m["dval"]
    sval = None if m["key"].startswith("DB_") and m["key"] != "DB_EVENT" else m["sval"]
    return (m["type"], m["dtype"], m["key"], m["src"], m["community"], m["id"], dval, sval)


def _as_dict(msg) -> dict:
    return {"type": msg.msg_type, "dtype": msg.data_type, "key": msg.key, "src": msg.source,
            "community": msg.community, "id": msg.id, "dval": msg.double,
            "sval": msg.binary.hex() if msg.is_binary() else msg.string}


def _captured_mail(cap: dict, conn: int) -> list[dict]:
    return [m for u in cap["packets"] if u.get("conn") == conn and u.get("dir") == "s2c" and u["kind"] == "packet"
            for m in u["decoded"]["msgs"]]


async def _with_db(scenario, **options):
    db = MOOSDB(port=0, **options)
    await db.start()
    try:
        return await scenario(db)
    finally:
        db.close()


def _run(scenario, **options):
    return asyncio.run(_with_db(scenario, **options))


@pytest.mark.parametrize("path", [p for p in conformance_files() if p.stem not in RULE_BASED], ids=lambda p: p.stem)
def test_replay_gives_captured_replies(path):
    cap = load_capture(path)

    async def scenario(db):
        clients = await replay(cap, db)
        for conn, client in clients.items():
            want = [_comparable(m) for m in _captured_mail(cap, conn)]
            await async_wait_until(lambda: len(client.mail) >= len(want), 5)
            got = [_comparable(_as_dict(m)) for _, m in client.mail]
            assert got == want, f"conn {conn}"
            if any(c.get("event") == "s2c_closed" and c["conn"] == conn and
                   not any(k.get("event") == "c2s_closed" and k["conn"] == conn and k["t"] < c["t"]
                           for k in cap["chunks"]) for c in cap["chunks"]):
                await async_wait_until(lambda: client.closed_at, 2)   # the DB closed this one itself
    _run(scenario)


def _values(client, key):
    return [m.value for _, m in client.mail if m.key == key]


def test_disconnect_events_are_delivered_promptly():
    """Scenario 09, minus the C++ flaw: the disconnect events reach the watcher at once."""
    cap = load_capture(next(p for p in conformance_files() if p.stem == "09_disconnect_events"))

    async def scenario(db):
        clients = await replay(cap, db, wait_replies=False)
        watcher = clients[1]
        events = ["connected=watcher", "connected=graceful", "connected=crasher",
                  "disconnected=graceful", "disconnected=crasher"]
        await async_wait_until(lambda: _values(watcher, "DB_EVENT") == events, 5)
        assert set(_values(watcher, "DB_CLIENTS")) <= {"watcher,", "graceful,watcher,", "crasher,graceful,watcher,",
                                                       "crasher,watcher,"}
    _run(scenario)


def test_db_variables_refresh_without_traffic():
    """Scenario 13: the DB_* variables reach a subscriber, with the captured content rules."""
    cap = load_capture(next(p for p in conformance_files() if p.stem == "13_db_variables"))

    async def scenario(db):
        watch = (await replay(cap, db, until=0.5, wait_replies=False))[1]
        assert _values(watch, "DB_EVENT")[0] == "connected=watch"
        await async_wait_until(lambda: _values(watch, "DB_RWSUMMARY") and _values(watch, "DB_QOS"), 5)
        assert _values(watch, "DB_CLIENTS")[-1] == "watch,"
        assert _values(watch, "DB_RWSUMMARY")[-1] == \
            "watch=DB_CLIENTS:DB_EVENT:DB_QOS:DB_RWSUMMARY:DB_TIME:DB_UPTIME:DB_VARSUMMARY&A"
        assert _values(watch, "DB_QOS")[-1].startswith("watch=")
        summary = _values(watch, "DB_VARSUMMARY")[-1].splitlines()
        assert [line.split()[0] for line in summary] == sorted(db.vars)
        a_line = next(line for line in summary if line.startswith("A "))
        assert a_line.split()[2] == "watch" and a_line.split()[-3:] == ["Hz", "D", "1.0"]
        db_line = next(line for line in summary if line.startswith("DB_CLIENTS "))
        assert db_line[:21] == f"{'DB_CLIENTS':<20} " and db_line[42:63] == f"{'MOOSDB_#1':<20} "
        assert _values(watch, "DB_UPTIME")[-1] > 0 and _values(watch, "DB_TIME")[-1] > 1e9
    _run(scenario, refresh_period=0.2)


def test_register_interval_throttles_by_dropping():
    """Scenario 14 at time warp 10: at most one FAST per (warped) second, the first one at once."""
    cap = load_capture(next(p for p in conformance_files() if p.stem == "14_register_interval"))

    async def scenario(db):
        began = time.monotonic()
        slow = (await replay(cap, db, pace=0.1, wait_replies=False))[1]
        elapsed = time.monotonic() - began          # 1 warped second = 0.1 s here
        got = [m.double for _, m in slow.mail if m.key == "FAST"]
        assert got[0] == 0.0 and got == sorted(set(got))
        assert 2 <= len(got) <= elapsed / 0.1 + 1   # the other writes were dropped, not delayed
    _run(scenario, time_warp=10.0)


def test_silent_client_is_dropped_after_timeout():
    """Scenario 19 with a 1 s client timeout: 'sleepy' goes, 'watcher' (timing only) stays."""
    cap = load_capture(next(p for p in conformance_files() if p.stem == "19_silent_client_timeout"))

    async def scenario(db):
        clients = await replay(cap, db, pace=1.0, until=1.8, wait_replies=False)
        watcher, sleepy = clients[1], clients[2]
        assert sleepy.closed_at is not None and 0.9 <= sleepy.closed_at - sleepy.mail[0][0] <= 2.5
        assert watcher.closed_at is None and "watcher" in db.clients
        await async_wait_until(lambda: "disconnected=sleepy" in _values(watcher, "DB_EVENT"), 1)
    _run(scenario, client_timeout=1.0)
