"""MOOSClient against a real moosdb process: values of every type, wildcards, reconnects, poison."""
from __future__ import annotations

import asyncio

from helpers import async_wait_until, conformance_files, load_capture, start_moosdb
from moosdb_py import codec
from moosdb_py.client import MOOSClient
from moosdb_py.message import MOOSMsg


def _run(coro):
    return asyncio.run(asyncio.wait_for(coro, 20))


async def _connected(*clients: MOOSClient) -> list[asyncio.Task]:
    tasks = [asyncio.create_task(c.run()) for c in clients]
    for c in clients:
        assert await c.wait_connected(5), c.name
    return tasks


async def _close(clients, tasks):
    for c in clients:
        c.close()
    await asyncio.gather(*tasks)


def _values(client, key):
    return [m.value for m in client.inbox if m.key == key]


def test_doubles_strings_binary_between_two_clients(moosdb_server):
    async def scenario():
        sub = MOOSClient("sub", port=moosdb_server.port)
        pub = MOOSClient("pub", port=moosdb_server.port)
        tasks = await _connected(sub, pub)
        sub.register("X")
        sub.register("S")
        sub.register("B")
        pub.notify("X", 3.5)
        await async_wait_until(lambda: sub._applied and not sub._outbox)
        blob = bytes(range(256)) * 3
        for v in (1.0, 2.0, 3.0):
            pub.notify("X", v)
        pub.notify("S", "hello, world = 1", source_aux="aux")
        pub.notify("B", blob)
        pub.post(MOOSMsg.notification("X", 9.0, time=1.0, source="forwarded_from"), keep_source=True)
        await async_wait_until(lambda: 9.0 in _values(sub, "X"))
        assert _values(sub, "X")[-4:] == [1.0, 2.0, 3.0, 9.0]
        (s,) = [m for m in sub.inbox if m.key == "S"]
        assert (s.string, s.source, s.source_aux, s.community) == ("hello, world = 1", "pub", "aux", "#1")
        assert _values(sub, "B") == [blob]
        assert [m.source for m in sub.inbox if m.key == "X"][-1] == "forwarded_from"
        await _close([sub, pub], tasks)
    _run(scenario())


def test_wildcards_and_server_requests(moosdb_server):
    async def scenario():
        sub = MOOSClient("wsub", port=moosdb_server.port)
        pub = MOOSClient("wpub", port=moosdb_server.port)
        tasks = await _connected(sub, pub)
        pub.notify("NAV_X", 1.0)
        await pub.flush()
        sub.register_wildcard("NAV_*", "w?ub")
        pub.notify("NAV_Y", 2.0)
        pub.notify("OTHER", 3.0)
        await async_wait_until(lambda: _values(sub, "NAV_Y"))
        assert _values(sub, "NAV_X") == [1.0] and not _values(sub, "OTHER")
        sub.server_request("VAR_SUMMARY")
        await async_wait_until(lambda: _values(sub, "VAR_SUMMARY"))
        assert "NAV_X,NAV_Y,OTHER" in _values(sub, "VAR_SUMMARY")[0]
        sub.unregister("NAV_Y")
        sub.server_request("VAR_SUMMARY")   # its reply shows the DB has taken the unregister
        await async_wait_until(lambda: len(_values(sub, "VAR_SUMMARY")) == 2)
        pub.notify("NAV_Y", 5.0)
        pub.notify("NAV_X", 6.0)
        await async_wait_until(lambda: 6.0 in _values(sub, "NAV_X"))
        assert _values(sub, "NAV_Y") == [2.0]
        await _close([sub, pub], tasks)
    _run(scenario())


def test_mail_survives_reconnects_of_db_and_clients(free_port):
    port = free_port()
    db = start_moosdb(port=port)

    async def scenario():
        nonlocal db
        connects = []
        sub = MOOSClient("rsub", port=port, on_connect=lambda: connects.append(1))
        pub = MOOSClient("rpub", port=port)
        sub.reconnect_interval = pub.reconnect_interval = 0.1
        tasks = await _connected(sub, pub)
        sub.register("R")
        await sub.flush()
        pub.notify("R", "before")
        await async_wait_until(lambda: _values(sub, "R") == ["before"])
        db.stop()
        await async_wait_until(lambda: not sub.connected and not pub.connected)
        db = start_moosdb(port=port)
        await async_wait_until(lambda: sub.connected and pub.connected and len(connects) == 2, 10)
        await async_wait_until(lambda: not sub._outbox)
        pub.notify("R", "after")
        await async_wait_until(lambda: _values(sub, "R") == ["before", "after"])
        await _close([sub, pub], tasks)
    try:
        _run(scenario())
    finally:
        db.stop()


def test_name_clash_poisons_the_second_client(moosdb_server):
    async def scenario():
        first = MOOSClient("dup", port=moosdb_server.port)
        tasks = await _connected(first)
        second = MOOSClient("dup", port=moosdb_server.port)
        await asyncio.wait_for(second.run(), 5)   # returns: a poisoned client stops
        assert second.poisoned == 'A client of this name ("dup") already exists' and not second.connected
        await _close([first], tasks)
    _run(scenario())


def test_client_speaks_like_the_captured_async_client():
    """What the client sends matches capture 01 (slot, handshake key, timing messages)."""
    cap = load_capture(conformance_files()[0])
    welcome = next(bytes.fromhex(p["hex"]) for p in cap["packets"] if p.get("dir") == "s2c")
    want = [codec.decode_packet(bytes.fromhex(p["hex"]))[0] for p in cap["packets"]
            if p.get("dir") == "c2s" and p["kind"] == "packet"][:2]

    async def scenario():
        received = asyncio.Queue()

        async def fake_db(reader, writer):
            framer = codec.StreamFramer(protocol_slot=True)
            writer.write(welcome)
            while data := await reader.read(4096):
                for unit in framer.units(data):
                    await received.put(unit)
        server = await asyncio.start_server(fake_db, "127.0.0.1", 0)
        client = MOOSClient("alpha", port=server.sockets[0].getsockname()[1])
        task = asyncio.create_task(client.run())
        assert await received.get() == codec.PROTOCOL_SLOT
        for expected in want:
            got = codec.decode_packet(await received.get())[0]
            assert (got.msg_type, got.data_type, got.key, got.string, got.double, got.double_aux, got.id) == \
                   (expected.msg_type, expected.data_type, expected.key, expected.string, expected.double,
                    expected.double_aux, expected.id)
        assert client.community == "#1" and client.db_hostname == "vm"
        client.close()
        await task
        server.close()
    _run(scenario())


def test_pymoos_style_comms_facade(moosdb_server):
    from helpers import wait_until
    from moosdb_py.comms import comms

    sub, pub = comms(), comms()
    sub.set_on_connect_callback(lambda: sub.register("Z", 0) and sub.register("W*", "*", 0))
    mail_calls = []
    sub.set_on_mail_callback(lambda: mail_calls.append(1))
    sub.run("localhost", moosdb_server.port, "script_sub")
    pub.run("localhost", moosdb_server.port, "script_pub")
    assert sub.wait_until_connected(5000) and pub.wait_until_connected(5000)
    sub.notify("Z", 0.0)     # comes back once the DB has taken the registrations
    got = []
    wait_until(lambda: got.extend(sub.fetch()) or got)
    pub.notify("Z", 1.5)
    pub.notify("Z", "text", "aux_src", 1234.0)   # "Z" is a double: the DB rejects this string
    pub.notify_binary("WB", b"\x00\x01")
    pub.notify("Z", 2.5, "aux_src", 1234.0)
    wait_until(lambda: got.extend(sub.fetch()) or len(got) >= 4)
    assert [(m.key, m.value) for m in got] == [("Z", 0.0), ("Z", 1.5), ("WB", b"\x00\x01"), ("Z", 2.5)]
    assert (got[-1].source_aux, got[-1].time, got[-1].source) == ("aux_src", 1234.0, "script_pub")
    assert mail_calls and sub.get_community_name() == "#1" and pub.get_published() == ["WB", "Z"]
    sub.close()
    pub.close()
    assert not sub.is_connected()
