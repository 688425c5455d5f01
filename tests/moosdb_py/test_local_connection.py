"""The in-process path (`MOOSDB.open_local`, pAntler --host-db) delivers the same mail as a TCP connection."""
from __future__ import annotations

import asyncio

from helpers import async_wait_until
from moosdb_py.client import MOOSClient
from moosdb_py.moosdb import MOOSDB

FIELDS = ("key", "msg_type", "data_type", "double", "string", "binary", "source", "source_aux", "community")


def _mail(client: MOOSClient) -> list[tuple]:
    return [tuple(getattr(m, f) for f in FIELDS) for m in client.inbox if not m.key.startswith("DB_")]


def test_local_and_socket_subscribers_get_the_same_mail():
    async def scenario():
        db = MOOSDB(port=0, community="local_test", time_warp=3.0)
        await db.start()
        pub = MOOSClient("pub", port=db.port, time_warp=3.0, local_db=db)
        over_tcp = MOOSClient("sub_tcp", port=db.port, time_warp=3.0)
        in_process = MOOSClient("sub_local", port=db.port, time_warp=3.0, local_db=db)
        clients = (pub, over_tcp, in_process)
        tasks = [asyncio.create_task(c.run()) for c in clients]
        for c in clients:
            assert await c.wait_connected(5), c.name
        for sub in (over_tcp, in_process):
            sub.register("X")
            sub.register("S", 0.0)
            sub.register_wildcard("B*")
            sub.register("DB_CLIENTS")
        await async_wait_until(lambda: {"X", "S"} <= db.core.clients["sub_tcp"].subscribed
                               and {"X", "S"} <= db.core.clients["sub_local"].subscribed)
        await asyncio.sleep(0.1)
        for i in range(20):
            pub.notify("X", float(i))
            pub.notify("S", f"text {i}, with = signs", source_aux=f"aux{i}")
            pub.notify("BLOB", bytes([i, 0, 255]))
            pub.notify("UNREAD", 1.0)
            if i % 5 == 0:
                await asyncio.sleep(0.01)
        await async_wait_until(lambda: len(_mail(over_tcp)) >= 60 and len(_mail(in_process)) >= 60)
        await asyncio.sleep(0.1)
        assert _mail(in_process) == _mail(over_tcp)
        assert [m[3] for m in _mail(in_process) if m[0] == "X"] == [float(i) for i in range(20)]
        await async_wait_until(lambda: any("sub_local" in m.string and "sub_tcp" in m.string
                                           for m in in_process.inbox if m.key == "DB_CLIENTS"), timeout=10)
        # a local client that closes is gone from the DB as a socket client is
        in_process.close()
        await async_wait_until(lambda: "sub_local" not in db.core.clients)
        for c in (pub, over_tcp):
            c.close()
        await asyncio.wait_for(asyncio.gather(*tasks), 5)
        db.close()
    asyncio.run(asyncio.wait_for(scenario(), 30))


def test_a_local_client_waits_for_its_db_and_reconnects():
    async def scenario():
        db = MOOSDB(port=0)
        client = MOOSClient("late", port=0, local_db=db)
        client.reconnect_interval = 0.05
        task = asyncio.create_task(client.run())
        assert not await client.wait_connected(0.2)        # not serving yet: refused, retried
        await db.start()
        assert await client.wait_connected(5)
        db.transmit(db.core.drop(db.core.clients["late"], "test", db.now()))
        await async_wait_until(lambda: not client.connected)
        await async_wait_until(lambda: client.connected and "late" in db.core.clients)
        client.close()
        await asyncio.wait_for(task, 5)
        db.close()
    asyncio.run(asyncio.wait_for(scenario(), 20))
