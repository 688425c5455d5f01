"""The MOOSDB core with no socket: the C++ clients' captured bytes in, the C++ MOOSDB's bytes out.

`MOOSDBCore` is fed each connection's TCP reads exactly as captured, at the captured times on the
test's own clock, and what it answers must be what the C++ MOOSDB sent, byte for byte once the fields
the conformance README lists as varying are masked, packet for packet. The scenarios that the socket
replay can only check for a rule (timeouts, throttling, DB_* refresh) are exact here, and hypothesis
checks routing invariants: every subscriber gets each write once, in order, however the bytes are cut.
"""
from __future__ import annotations

import dataclasses
import logging
from collections import defaultdict

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers import conformance_files, load_capture
from moosdb_py import codec
from moosdb_py.db_core import ABORT, CLOSE, MOOSDBCore
from moosdb_py.formats import wild_match
from moosdb_py.message import DOUBLE, MOOSMsg, NOTIFY, SERVER_REQUEST_ID

VARYING_CONTENT = {"DB_TIME", "DB_UPTIME", "DB_VARSUMMARY", "DB_QOS", "DB_RWSUMMARY"}
RULE_BASED = {"09_disconnect_events", "13_db_variables", "19_silent_client_timeout"}
TICK = 0.25            # how often the shell tells the core the time


class Community:
    """A core and, per connection (by the test's label), the bytes it wrote and how it ended."""

    def __init__(self, now: float, **options):
        self.core = MOOSDBCore(now=now, hostname="vm", **options)
        self.clients = {}
        self.wrote: dict = defaultdict(bytearray)
        self.ended: dict = {}
        self.ended_at: dict = {}

    def _take(self, outgoing, now: float) -> None:
        for client, data, end in outgoing:
            label = client.handle
            assert label not in self.ended, f"{label}: output after {self.ended[label]}"
            framer = codec.StreamFramer()
            framer.units(data)
            assert framer.buffered == 0, f"{label}: output is not whole packets"
            self.wrote[label] += data
            if end:
                self.ended[label], self.ended_at[label] = end, now

    def open(self, label, now: float) -> None:
        self.clients[label] = self.core.connect(label, f"127.0.0.1:{len(self.clients) + 40000}", now)

    def send(self, label, data: bytes, now: float) -> None:
        self._take(self.core.receive(self.clients[label], data, now), now)

    def lose(self, label, now: float) -> None:
        self._take(self.core.connection_lost(self.clients[label], "closed by client", now), now)

    def tick(self, now: float) -> None:
        self._take(self.core.tick(now), now)

    def packets(self, label) -> list[list[MOOSMsg]]:
        return [codec.decode_packet(p) for p in codec.StreamFramer().units(bytes(self.wrote[label]))]

    def mail(self, label) -> list[MOOSMsg]:
        return [m for packet in self.packets(label) for m in packet]


def hello(name: str, asynchronous: bool = True, now: float = 0.0) -> bytes:
    return codec.PROTOCOL_SLOT + codec.encode_packet(
        [MOOSMsg("i", "S", "asynchronous" if asynchronous else "", string=name, time=now)])


# -- the captures, replayed into the core ------------------------------------------------------------
def _db_clock(cap: dict) -> tuple[float, float]:
    """The C++ DB's clock at capture time 0 (from its first timing reply; any will do without one) and
    when it started (DB_TIME - DB_UPTIME where the capture shows them, else at capture time 0), so that
    the core's stamps and DB_* refreshes line up with the C++ DB's."""
    replies = [(u["t"], m) for u in cap["packets"] if u.get("dir") == "s2c" for m in u["decoded"]["msgs"]]
    base = next((m["dval"] - t for t, m in replies if m["type"] == "T"), 1.8e9)
    clock = {m["key"]: m["dval"] for _, m in replies if m["key"] in ("DB_TIME", "DB_UPTIME")}
    return base, clock["DB_TIME"] - clock["DB_UPTIME"] if len(clock) == 2 else base


def replay(cap: dict) -> tuple[Community, float]:
    """Feed every captured client read to a core at its captured time, telling it the time every TICK;
    return the core's community and the DB clock at capture time 0."""
    base, start = _db_clock(cap)
    db = Community(start)
    clock = 0.0
    for chunk in sorted((c for c in cap["chunks"] if c.get("dir") != "s2c"), key=lambda c: c["t"]):
        while clock + TICK < chunk["t"]:
            clock += TICK
            db.tick(base + clock)
        conn, now = chunk.get("conn"), base + chunk["t"]
        if chunk.get("event") == "open":
            db.open(conn, now)
        elif chunk.get("event") == "c2s_closed":
            db.lose(conn, now)
        elif "hex" in chunk and conn not in db.ended:
            db.send(conn, bytes.fromhex(chunk["hex"]), now)
    return db, base


def masked(m: MOOSMsg) -> bytes:
    """The message as bytes, with the fields that vary from run to run (conformance README) blanked."""
    m = dataclasses.replace(m)
    if m.msg_type != NOTIFY or m.source.startswith("MOOSDB_") or m.id == SERVER_REQUEST_ID:
        m.time = 0.0                           # the DB's clock (forwarded mail keeps the writer's time)
    if m.msg_type in ".TW":
        m.double = 0.0                         # DB clock, skew estimate
    if m.msg_type == "W":
        m.source_aux = "hostname=?"
    if m.key.startswith("DB_"):
        m.double = 0.0                         # the DB's clock (in ALL replies even for its string variables)
    if m.key in VARYING_CONTENT or m.key.endswith("_STATUS"):
        m.string = ""
    if m.id == SERVER_REQUEST_ID:
        m.double_aux = 0.0                     # write frequency in ALL replies
    return codec.encode_message(m)


def captured_packets(cap: dict, conn: int) -> list[list[bytes]]:
    return [[masked(m) for m in codec.decode_packet(bytes.fromhex(u["hex"]))] for u in cap["packets"]
            if u.get("conn") == conn and u.get("dir") == "s2c" and u["kind"] == "packet"]


def closed_by_db(cap: dict) -> set[int]:
    """Connections the DB hung up on: their s2c side closed before the client closed its side."""
    first: dict[int, str] = {}
    for chunk in cap["chunks"]:                  # in time order
        if chunk.get("event") in ("s2c_closed", "c2s_closed"):
            first.setdefault(chunk["conn"], chunk["event"])
    return {conn for conn, event in first.items() if event == "s2c_closed"}


@pytest.mark.parametrize("path", [p for p in conformance_files() if p.stem not in RULE_BASED], ids=lambda p: p.stem)
def test_core_answers_the_captured_bytes(path):
    cap = load_capture(path)
    db, _ = replay(cap)
    for conn in sorted({c["conn"] for c in cap["chunks"]}):
        got = [[masked(m) for m in packet] for packet in db.packets(conn)]
        assert got == captured_packets(cap, conn), f"conn {conn}"
    assert set(db.ended) == closed_by_db(cap)


def _capture(stem: str) -> dict:
    return load_capture(next(p for p in conformance_files() if p.stem == stem))


def _values(db: Community, label, key: str) -> list:
    return [m.value for m in db.mail(label) if m.key == key]


def test_disconnect_events_go_out_with_the_disconnect():
    """Scenario 09 without the C++ flaw: the watcher hears of each disconnect in the core's answer to it."""
    cap = _capture("09_disconnect_events")
    db, base = replay(cap)
    assert _values(db, 1, "DB_EVENT") == ["connected=watcher", "connected=graceful", "connected=crasher",
                                          "disconnected=graceful", "disconnected=crasher"]
    closes = [c["t"] for c in cap["chunks"] if c.get("event") == "c2s_closed" and c["conn"] in (2, 3)]
    assert [m.time - base for m in db.mail(1) if m.string.startswith("disconnected=")] == pytest.approx(closes)
    assert set(_values(db, 1, "DB_CLIENTS")) <= {"graceful,watcher,", "crasher,graceful,watcher,", "watcher,"}
    assert not db.ended


def test_db_variables_refresh_every_period_with_the_captured_content():
    """Scenario 13: DB_* refresh on the clock alone, every 2 s (to the tick), with the C++ DB's content."""
    db, _ = replay(_capture("13_db_variables"))
    core = db.core
    times = _values(db, 1, "DB_TIME")
    assert len(times) >= 3 and all(2.0 <= b - a < 2.0 + TICK for a, b in zip(times, times[1:]))
    assert _values(db, 1, "DB_UPTIME") == [t - core.start_time for t in times]
    assert set(_values(db, 1, "DB_CLIENTS")) == {"watch,"}
    assert set(_values(db, 1, "DB_RWSUMMARY")) == {
        "watch=DB_CLIENTS:DB_EVENT:DB_QOS:DB_RWSUMMARY:DB_TIME:DB_UPTIME:DB_VARSUMMARY&A"}
    assert all(q.startswith("watch=") and q.count(":") == 3 for q in _values(db, 1, "DB_QOS"))
    summaries = [s.splitlines() for s in _values(db, 1, "DB_VARSUMMARY")]
    assert all([line.split()[0] for line in summary] == sorted(core.vars) for summary in summaries)
    a_lines = [next(line.split() for line in summary if line.startswith("A ")) for summary in summaries]
    assert [(a[2], a[-2], a[-1]) for a in a_lines] == [("watch", "D", "1.0"), ("watch", "D", "2.0"),
                                                       ("watch", "D", "2.0")]     # A=2 at 2.9 s, A=3 at 5.4 s


def test_silent_client_is_dropped_after_the_timeout(caplog):
    """Scenario 19: 'sleepy' is cut off 5 s (to the tick) after its last bytes; 'watcher' stays and is told."""
    cap = _capture("19_silent_client_timeout")
    with caplog.at_level(logging.WARNING, logger="moosdb"):
        db, base = replay(cap)
    last_read = max(c["t"] for c in cap["chunks"] if c.get("conn") == 2 and c.get("dir") == "c2s")
    assert db.ended == {2: ABORT}
    assert 5.0 < db.ended_at[2] - base - last_read <= 5.0 + TICK
    assert _values(db, 1, "DB_EVENT")[-1] == "disconnected=sleepy"
    assert "silent for more than 5 s (client timeout)" in caplog.text


def test_timeouts_are_real_seconds_under_time_warp():
    """MOOS time runs time_warp times faster; a 1 s client timeout is 1 s of the wall, 10 of MOOS time."""
    db = Community(1000.0, client_timeout=1.0, time_warp=10.0)
    db.open("c", 1000.0)
    db.send("c", hello("c", now=1000.0), 1000.0)
    db.tick(1009.9)
    assert not db.ended
    db.tick(1010.1)
    assert db.ended == {"c": ABORT}
    db.open("mute", 1010.1)
    db.tick(1059.0)
    assert "mute" not in db.ended
    db.tick(1061.0)                              # 5 s of wall time without a handshake
    assert db.ended["mute"] == CLOSE and not db.wrote["mute"]


# -- bad input, no socket ----------------------------------------------------------------------------
def note(source: str, key: str, value: float, msg_id: int = 0) -> MOOSMsg:
    return MOOSMsg.notification(key, value, time=5.0, source=source, msg_id=msg_id)


def register(source: str, key: str, interval: float = 0.0) -> MOOSMsg:
    return MOOSMsg("R", DOUBLE, key, interval, source=source)


def poll(source: str) -> MOOSMsg:
    return MOOSMsg(".", DOUBLE, "", source=source)


def _pair(**options) -> Community:
    db = Community(0.0, **options)
    for name in ("sub", "pub"):
        db.open(name, 0.0)
        db.send(name, hello(name), 0.0)
    db.send("sub", codec.encode_packet([register("sub", "X")]), 0.0)
    return db


def test_malformed_packet_aborts_only_its_sender(caplog):
    db = _pair()
    db.open("liar", 0.0)
    good = codec.encode_packet([note("liar", "X", 1.0)])
    with caplog.at_level(logging.WARNING, logger="moosdb"):
        db.send("liar", hello("liar") + good + good[:9] + (999).to_bytes(4, "little") + good[13:], 1.0)
    assert db.ended == {"liar": ABORT} and "liar" not in db.core.clients
    assert "dropping client 'liar'" in caplog.text and "claims length 999" in caplog.text
    db.send("pub", codec.encode_packet([note("pub", "X", 2.0)]), 2.0)
    assert _values(db, "sub", "X") == [1.0, 2.0]          # the liar's good packet went through, then it went
    assert _values(db, "sub", "DB_EVENT") == []


def test_synchronous_client_that_stops_polling_is_dropped():
    db = Community(0.0, max_queue=2_000)
    db.open("lazy", 0.0)
    db.send("lazy", hello("lazy", asynchronous=False) + codec.encode_packet([register("lazy", "X")]), 0.0)
    db.open("pub", 0.0)
    db.send("pub", hello("pub"), 0.0)
    for i in range(40):
        db.send("pub", codec.encode_packet([note("pub", "X", float(i), i)]), 1.0)
    assert db.ended == {"lazy": ABORT}
    assert [len(p) for p in db.packets("lazy")] == [1, 1]   # welcome, the NULL reply to its registration


def test_name_clash_and_unreadable_name_are_poisoned():
    db = _pair()
    db.open("second", 1.0)
    db.send("second", hello("sub"), 1.0)
    db.open("blank", 1.0)
    db.send("blank", codec.PROTOCOL_SLOT + codec.encode_packet([]), 1.0)
    assert db.ended == {"second": CLOSE, "blank": CLOSE}
    assert [(m.msg_type, m.string) for m in db.mail("second")] == [("K", 'A client of this name ("sub") already exists')]
    assert [(m.msg_type, m.string) for m in db.mail("blank")] == [("K", "Failed to read receive client's name")]
    assert db.core.clients["sub"] is db.clients["sub"]


# -- routing invariants ------------------------------------------------------------------------------
KEYS = ("X", "XY", "Y", "YZ", "Z")
PATTERNS = ("X*", "?Y", "*Z")                # none matches a DB_* variable

subscribers = st.lists(st.fixed_dictionaries({"sync": st.booleans(), "keys": st.sets(st.sampled_from(KEYS)),
                                              "pattern": st.none() | st.sampled_from(PATTERNS)}),
                       min_size=1, max_size=4)
writes = st.lists(st.tuples(st.integers(0, 1), st.lists(st.tuples(st.sampled_from(KEYS), st.integers(-99, 99)),
                                                         min_size=1, max_size=6)), max_size=8)


def script(subs: list[dict], steps: list) -> list[tuple[str, bytes]]:
    """Subscribers register, then publishers write packets of notifies (synchronous ones poll after each)."""
    out = []
    for i, sub in enumerate(subs):
        name = f"sub{i}"
        wildcard = [MOOSMsg("*", "S", name, string=f"AppPattern=*,VarPattern={sub['pattern']},Interval=0",
                            source=name)] if sub["pattern"] else []
        out += [(name, hello(name, not sub["sync"])),
                (name, codec.encode_packet([poll(name), *(register(name, k) for k in sorted(sub["keys"])), *wildcard]))]
    out += [(f"pub{p}", hello(f"pub{p}")) for p in (0, 1)]
    msg_id = 0
    for publisher, packet in steps:
        msgs = []
        for key, value in packet:
            msgs.append(note(f"pub{publisher}", key, float(value), msg_id))
            msg_id += 1
        out.append((f"pub{publisher}", codec.encode_packet(msgs)))
        out += [(f"sub{i}", codec.encode_packet([poll(f"sub{i}")])) for i, sub in enumerate(subs) if sub["sync"]]
    return out


def run(steps: list[tuple[str, bytes]]) -> Community:
    db = Community(0.0)
    for label, data in steps:
        if label not in db.clients:
            db.open(label, 0.0)
        db.send(label, data, 0.0)
    return db


@settings(max_examples=60, deadline=None)
@given(subs=subscribers, steps=writes)
def test_every_subscriber_gets_each_write_once_in_order(subs, steps):
    db = run(script(subs, steps))
    written = [(f"pub{p}", key, float(value)) for p, packet in steps for key, value in packet]
    written = [(*w, msg_id) for msg_id, w in enumerate(written)]
    for i, sub in enumerate(subs):
        label = f"sub{i}"
        wanted = [w for w in written if w[1] in sub["keys"] or (sub["pattern"] and wild_match(sub["pattern"], w[1]))]
        assert [(m.source, m.key, m.double, m.id) for m in db.mail(label) if m.msg_type == NOTIFY] == wanted
        if sub["sync"]:       # one reply per packet sent after the welcome, NULL first
            replies = db.packets(label)[1:]
            assert len(replies) == 1 + len(steps) and all(p[0].msg_type == "." for p in replies)
    assert not db.ended


@settings(max_examples=60, deadline=None)
@given(subs=subscribers, steps=writes, data=st.data())
def test_how_the_bytes_are_cut_changes_nobody_s_mail(subs, steps, data):
    """The same streams, once a packet per read and once merged and cut anywhere: the same messages."""
    steps = script(subs, steps)
    whole = run(steps)
    merged: list[tuple[str, bytes]] = []
    for label, chunk in steps:
        if merged and merged[-1][0] == label:
            merged[-1] = (label, merged[-1][1] + chunk)
        else:
            merged.append((label, chunk))
    cut = []
    for label, chunk in merged:
        points = sorted(data.draw(st.sets(st.integers(1, len(chunk) - 1), max_size=4), label=label))
        cut += [(label, chunk[a:b]) for a, b in zip([0, *points], [*points, len(chunk)])]
    pieces = run(cut)
    for label in whole.wrote:
        assert [codec.encode_message(m) for m in pieces.mail(label)] == \
            [codec.encode_message(m) for m in whole.mail(label)], label
    assert pieces.ended == whole.ended == {}
