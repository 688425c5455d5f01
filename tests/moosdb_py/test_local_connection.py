"""The in-process path (`MOOSDB.open_local`, pAntler --host-db) delivers the same mail as a TCP connection."""
from __future__ import annotations

import asyncio

from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import async_wait_until
from moosdb_py import codec
from moosdb_py.app import MOOSApp
from moosdb_py.client import MOOSClient
from moosdb_py.db_core import MOOSDBCore
from moosdb_py.message import REGISTER, STRING, WILDCARD_REGISTER, MOOSMsg
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


KEYS = ("X", "Y", "WIND", "W_2")
VALUES = st.one_of(st.floats(allow_nan=False), st.text(max_size=12), st.binary(max_size=6))
POSTS = st.lists(st.tuples(st.sampled_from(("pub_local", "pub_tcp")), st.floats(0.0, 0.6),
                           st.lists(st.tuples(st.sampled_from(KEYS), VALUES, st.text(max_size=3)), min_size=1, max_size=4)),
                 min_size=1, max_size=25)


@settings(max_examples=60, deadline=None)
@given(posts=POSTS, intervals=st.lists(st.sampled_from((0.0, 0.0, 0.5, 1.5)), min_size=2, max_size=2))
def test_core_gives_a_local_and_a_socket_subscriber_the_same_mail(posts, intervals):
    """The same batches, from an in-process and a socket publisher, at the same times: the in-process
    subscriber gets, message for message and field for field, what the socket subscriber decodes
    (throttled registrations, a wildcard, type clashes, text outside latin-1, binary values); one that
    shares its mail (`shared_mail`: MOOSApps) gets the same, the messages the DB keeps rather than copies."""
    core = MOOSDBCore(now=0.0, hostname="vm")
    mail: dict[str, list[MOOSMsg]] = {"sub_local": [], "sub_shared_local": [], "sub_tcp": [], "pub_local": [],
                                      "pub_tcp": []}

    def take(outgoing):
        for client, data, end in outgoing:
            mail[client.handle] += data if client.local else \
                [m for unit in codec.StreamFramer().units(data) for m in codec.decode_packet(unit)]

    clients = {}
    for name in mail:
        hello = MOOSMsg("i", STRING, "asynchronous", string=name, time=0.0)
        if name.endswith("local"):
            clients[name], outgoing = core.connect_local(name, hello, 0.0, shared_mail="shared" in name)
            take(outgoing)
        else:
            clients[name] = core.connect(name, "127.0.0.1:1", 0.0)
            take(core.receive(clients[name], codec.PROTOCOL_SLOT + codec.encode_packet([hello]), 0.0))

    def send(name, msgs, now):
        if name.endswith("local"):
            take(core.receive_local(clients[name], msgs, now))
        else:
            take(core.receive(clients[name], codec.encode_packet(msgs), now))

    for name in ("sub_local", "sub_shared_local", "sub_tcp"):
        send(name, [MOOSMsg(REGISTER, "D", "X", intervals[0], source=name, time=0.0),
                    MOOSMsg(REGISTER, "D", "Y", intervals[1], source=name, time=0.0),
                    MOOSMsg(WILDCARD_REGISTER, STRING, name, string="AppPattern=*,VarPattern=W*,Interval=0",
                            source=name, time=0.0)], 0.0)
    now, next_id = 0.0, 0
    for publisher, pause, batch in posts:
        now += pause
        msgs = []
        for key, value, aux in batch:
            msgs.append(MOOSMsg.notification(key, value, time=now, source=publisher, source_aux=aux, msg_id=next_id))
            next_id += 1
        send(publisher, msgs, now)
    fields = [f for f in MOOSMsg.__slots__]
    assert [[getattr(m, f) for f in fields] for m in mail["sub_local"]] == \
        [[getattr(m, f) for f in fields] for m in mail["sub_tcp"]] == \
        [[getattr(m, f) for f in fields] for m in mail["sub_shared_local"]]
    assert not {id(m) for m in mail["sub_local"]} & {id(m) for m in mail["sub_shared_local"]}
    assert mail["sub_tcp"]        # every key is subscribed: at least the first post of each went out


def test_idle_local_clients_stay_alive_with_timing_messages():
    """A bare in-process client (its keep-alive timer) and an app that posts nothing (its AppTicks) both
    send timing messages, so a DB with a 2 s client timeout keeps them."""
    async def scenario():
        db = MOOSDB(port=0, client_timeout=2.0)
        await db.start()
        bare = MOOSClient("bare", port=db.port, local_db=db)
        app = MOOSApp(name="pIdle", port=db.port)
        app.client.local_db = db
        tasks = [asyncio.create_task(bare.run()), asyncio.create_task(app.run_async())]
        await async_wait_until(lambda: {"bare", "pIdle"} <= set(db.core.clients))
        await asyncio.sleep(3.0)
        kept = {name: db.core.clients[name].latency[4] for name in ("bare", "pIdle") if name in db.core.clients}
        bare.close()
        app.stop()
        await asyncio.wait_for(asyncio.gather(*tasks), 5)
        db.close()
        assert set(kept) == {"bare", "pIdle"}, "dropped as silent"
        assert kept["bare"] >= 2 and kept["pIdle"] >= 2     # timing messages the DB counted, in 3 s and more
    asyncio.run(asyncio.wait_for(scenario(), 20))


GROUPS = st.lists(st.tuples(st.floats(0.0, 0.6), st.lists(st.tuples(
    st.sampled_from(("pub_a", "pub_b")), st.lists(st.tuples(st.sampled_from(KEYS), VALUES), min_size=1, max_size=3)),
    min_size=1, max_size=4)), min_size=1, max_size=12)


@settings(max_examples=60, deadline=None)
@given(groups=GROUPS, interval=st.sampled_from((0.0, 0.5)))
def test_batches_routed_together_give_each_subscriber_the_same_mail_in_one_delivery(groups, interval):
    """Hosted clients' batches of one wake-up, routed together (`receive_local_batches`), give a subscriber
    the mail that routing them one by one gives, in the same order, in one delivery per wake-up."""
    def community():
        core = MOOSDBCore(now=0.0, hostname="vm")
        clients = {}
        for name in ("sub", "pub_a", "pub_b"):
            clients[name], _ = core.connect_local(name, MOOSMsg("i", STRING, "asynchronous", string=name, time=0.0), 0.0)
        list(core.receive_local(clients["sub"], [
            MOOSMsg(REGISTER, "D", "X", interval, source="sub", time=0.0),
            MOOSMsg(WILDCARD_REGISTER, STRING, "sub", string="AppPattern=*,VarPattern=W*,Interval=0", time=0.0)], 0.0))
        return core, clients

    one_by_one, together = community(), community()
    mail: dict[int, list[MOOSMsg]] = {0: [], 1: []}
    deliveries = []
    now, next_id = 0.0, 0
    for pause, wake_up in groups:
        now += pause
        batches = {0: [], 1: []}
        for publisher, posts in wake_up:
            msgs = [MOOSMsg.notification(key, value, time=now, source=publisher, msg_id=next_id + i)
                    for i, (key, value) in enumerate(posts)]
            next_id += len(posts)
            for side, (_, clients) in enumerate((one_by_one, together)):
                batches[side].append((clients[publisher], [m.copy() for m in msgs]))
        for client, msgs in batches[0]:
            mail[0] += [m for c, data, _ in one_by_one[0].receive_local(client, msgs, now) if c.handle == "sub"
                        for m in data]
        out = [data for c, data, _ in together[0].receive_local_batches(batches[1], now) if c.handle == "sub"]
        deliveries.append(len(out))
        mail[1] += [m for data in out for m in data]
    fields = list(MOOSMsg.__slots__)
    assert [[getattr(m, f) for f in fields] for m in mail[1]] == [[getattr(m, f) for f in fields] for m in mail[0]]
    assert max(deliveries) <= 1
