"""Bad input and load: the offender is dropped with a logged reason, everyone else keeps their mail in order."""
from __future__ import annotations

import asyncio
import logging
import socket
import struct
import time

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import async_wait_until
from moosdb_py import codec
from moosdb_py.client import MOOSClient
from moosdb_py.message import MOOSMsg
from moosdb_py.moosdb import MOOSDB


def _hello(name: str, asynchronous: bool = True) -> bytes:
    return codec.PROTOCOL_SLOT + codec.encode_packet(
        [MOOSMsg("i", "S", "asynchronous" if asynchronous else "", string=name, time=time.time())])


async def _with_pair(db: MOOSDB, trouble, n: int = 30) -> list[float]:
    """`sub` subscribes to X while `pub` writes 0..n-1 and `trouble()` misbehaves; return sub's values."""
    sub = MOOSClient("good_sub", port=db.port)
    pub = MOOSClient("good_pub", port=db.port)
    tasks = [asyncio.create_task(c.run()) for c in (sub, pub)]
    await sub.wait_connected(5)
    await pub.wait_connected(5)
    sub.register("X")
    sub.notify("X", -1.0)                        # comes back once the DB has the registration
    await async_wait_until(lambda: sub.inbox, 5)
    half = n // 2
    for i in range(half):
        pub.notify("X", float(i))
    await trouble()
    for i in range(half, n):
        pub.notify("X", float(i))
    await async_wait_until(lambda: any(m.double == n - 1 for m in sub.inbox), 5)
    for c in (sub, pub):
        c.close()
    await asyncio.gather(*tasks)
    return [m.double for m in sub.inbox[1:]]


async def _start_db(**options) -> MOOSDB:
    db = MOOSDB(port=0, **options)
    await db.start()
    return db


garbage = st.one_of(
    st.binary(min_size=1, max_size=200),                                                       # noise
    st.integers(-2**31, 2**31 - 1).map(lambda n: struct.pack("<i", n) + b"\0" * 8),            # any length
    st.tuples(st.integers(0, 80), st.binary(min_size=1, max_size=4)).map(                      # corrupted packet
        lambda cut: (lambda p: p[:cut[0] % len(p)] + cut[1] + p[cut[0] % len(p) + len(cut[1]):])(
            codec.encode_packet([MOOSMsg.notification("Y", 1.0, time=1.0, source="bad")]))),
)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(junk=st.lists(garbage, min_size=1, max_size=4), handshake=st.booleans())
def test_garbage_from_one_client_disturbs_nobody(junk, handshake, caplog):
    async def scenario():
        db = await _start_db()
        bad_state = {}

        async def trouble():
            reader, writer = await asyncio.open_connection(db.host, db.port)
            writer.write(_hello("bad") if handshake else b"")
            for chunk in junk:
                writer.write(chunk)
            await writer.drain()
            bad_state["writer"] = writer

        caplog.clear()
        with caplog.at_level(logging.INFO, logger="moosdb"):
            values = await _with_pair(db, trouble)
        assert values == [float(i) for i in range(30)]
        assert set(db.clients) <= {"bad"}          # the good ones closed; the DB is still serving
        bad_state["writer"].close()
        db.close()
    asyncio.run(asyncio.wait_for(scenario(), 15))


def _survives(caplog, trouble, *logged: str, **options) -> None:
    """Run `trouble(db)` beside a good pair; their mail must be complete and `logged` texts in the log."""
    async def scenario():
        db = await _start_db(**options)
        with caplog.at_level(logging.INFO, logger="moosdb"):
            values = await _with_pair(db, lambda: trouble(db))
        db.close()
        assert [v for v in values if v >= 0] == [float(i) for i in range(30)]
        text = "\n".join(r.message for r in caplog.records)
        for part in logged:
            assert part in text
    asyncio.run(asyncio.wait_for(scenario(), 15))


def test_malformed_packet_drops_the_client_with_the_reason(caplog):
    async def trouble(db):
        reader, writer = await asyncio.open_connection(db.host, db.port)
        writer.write(_hello("liar"))
        await async_wait_until(lambda: "liar" in db.clients)
        packet = codec.encode_packet([MOOSMsg.notification("Y", 1.0, time=1.0, source="liar")])
        writer.write(packet[:9] + struct.pack("<i", 999) + packet[13:])    # message length disagrees
        await async_wait_until(lambda: "liar" not in db.clients)
        await reader.read()                    # returns: the DB hung up on it
    _survives(caplog, trouble, "dropping client 'liar'", "claims length 999")


def test_oversized_packet_and_garbage_before_handshake(caplog):
    async def trouble(db):
        _, big = await asyncio.open_connection(db.host, db.port)
        big.write(_hello("big") + struct.pack("<i", 50_000))
        _, noisy = await asyncio.open_connection(db.host, db.port)
        noisy.write(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n" + b"\0" * 8)
        await async_wait_until(lambda: len(db.connections) == 2)   # only the two good clients left
        big.close()
        noisy.close()
    _survives(caplog, trouble, "dropping client 'big'", "packet length 50000 outside [9, 10000]",
              "wrong protocol string b'GET / HTTP/1.1", max_packet=10_000)


def test_client_that_stops_reading_is_dropped(caplog):
    """A subscriber that never reads: its backlog passes max_queue and it goes; the others carry on."""
    async def trouble(db):
        stuck = socket.socket()
        stuck.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        stuck.connect((db.host, db.port))
        stuck.setblocking(False)
        reg = MOOSMsg("R", "D", "BIG", 0.0, source="stuck", time=time.time())
        await asyncio.get_running_loop().sock_sendall(stuck, _hello("stuck") + codec.encode_packet([reg]))
        await async_wait_until(lambda: "stuck" in db.clients and db.vars.get("BIG"))
        flooder = MOOSClient("flooder", port=db.port)
        task = asyncio.create_task(flooder.run())
        await flooder.wait_connected(5)
        payload = b"\xab" * 100_000
        for _ in range(100):                   # 10 MB the stuck client never reads
            flooder.notify("BIG", payload)
            await asyncio.sleep(0)
        await async_wait_until(lambda: "stuck" not in db.clients, 5)
        flooder.close()
        await task
        stuck.close()
    _survives(caplog, trouble, "dropping client 'stuck'", "(client not reading)", max_queue=200_000)


def test_synchronous_client_that_stops_polling_is_dropped(caplog):
    async def trouble(db):
        reader, writer = await asyncio.open_connection(db.host, db.port)
        reg = MOOSMsg("R", "D", "X", 0.0, source="lazy", time=time.time())
        writer.write(_hello("lazy", asynchronous=False) + codec.encode_packet([reg]))
        await async_wait_until(lambda: "lazy" in db.clients and db.clients["lazy"].subscribed)
        spammer = MOOSClient("spammer", port=db.port)
        task = asyncio.create_task(spammer.run())
        await spammer.wait_connected(5)
        for i in range(2000):
            spammer.notify("X", float(-i - 1))     # held for `lazy`, which never polls
        await async_wait_until(lambda: "lazy" not in db.clients, 5)
        spammer.close()
        await task
        writer.close()
    _survives(caplog, trouble, "dropping client 'lazy'", "(synchronous client not polling)", max_queue=50_000)
