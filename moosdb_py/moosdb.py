"""MOOSDB: the MOOS community's hub, wire-compatible with the C++ MOOSDB, on asyncio.

Behaviour follows ../shared/spec/moos-wire-protocol.md §4-§8 and the captures, except where the
C++ DB has known flaws that clients do not depend on: mail for asynchronous clients is pushed as
soon as it is queued (not only when someone notifies), the DB_* variables refresh on a timer as
well as under traffic, and bad input costs only the offending client its connection.
"""
from __future__ import annotations

import argparse
import asyncio
import functools
import logging
import re
import signal
import socket
import sys
import time as _time
from dataclasses import dataclass, field

from . import codec
from .app import print_page
from .message import (BINARY, COMMAND, DOUBLE, NOT_SET, NOTIFY, NULL_MSG, POISON, REGISTER,
                      SERVER_REQUEST, STRING, TIMING, UNREGISTER, WELCOME, WILDCARD_REGISTER,
                      WILDCARD_UNREGISTER, MOOSMsg, moos_time)

log = logging.getLogger("moosdb")

DEFAULT_PORT = 9000
DEFAULT_COMMUNITY = "#1"
DEFAULT_CLIENT_TIMEOUT = 5.0
DEFAULT_MAX_QUEUE = 32 * 1024 * 1024
HANDSHAKE_TIMEOUT = 5.0
REFRESH_PERIOD = 2.0
DB_VARIABLES = (("DB_TIME", DOUBLE), ("DB_UPTIME", DOUBLE), ("DB_CLIENTS", STRING), ("DB_VARSUMMARY", STRING),
                ("DB_QOS", STRING), ("DB_RWSUMMARY", STRING), ("DB_EVENT", STRING))


@functools.lru_cache(maxsize=4096)
def _glob(pattern: str) -> re.Pattern:
    """MOOSWildCmp: whole-string, case-sensitive, only `*` and `?` are special."""
    return re.compile("".join(".*" if c == "*" else "." if c == "?" else re.escape(c) for c in pattern) + r"\Z",
                      re.DOTALL)


def wild_match(pattern: str, text: str) -> bool:
    return _glob(pattern).match(text) is not None


def parse_wildcard(sval: str) -> tuple[str, str, float]:
    """`AppPattern=<p>,VarPattern=<p>,Interval=<s>` -> (app, var, interval); ValueError if malformed."""
    fields = {}
    for token in sval.split(","):
        name, sep, value = token.partition("=")
        if sep:
            fields[name.strip()] = value.strip()
    try:
        return fields["AppPattern"], fields["VarPattern"], float(fields.get("Interval", "0"))
    except (KeyError, ValueError):
        raise ValueError(f"bad wildcard registration {sval!r}") from None


def parse_response(spec: str) -> list[tuple[str, float]]:
    """`--response=app:ms,pattern*:ms` -> [(pattern, seconds)]."""
    out = []
    for item in filter(None, (s.strip() for s in spec.split(","))):
        pattern, sep, ms = item.rpartition(":")
        if not sep:
            raise ValueError(f"--response item {item!r} is not NAME:MS")
        out.append((pattern, float(ms) / 1000.0))
    return out


@dataclass(eq=False, slots=True)
class DBVar:
    """One variable: type fixed by its first write, last message kept as the bytes that arrived."""

    name: str
    data_type: str = NOT_SET
    wire: bytes = b""                   # the stored value: the message as written (community filled in)
    source: str = ""                    # its writer
    written_time: float = -1.0
    freq: float = 0.0
    window_writes: int = 0
    window_start: float = 0.0
    subscribers: dict = field(default_factory=dict)   # ClientConnection -> [interval, last_sent]

    def reset(self) -> None:
        self.wire, self.source, self.written_time, self.freq, self.window_writes = b"", "", -1.0, 0.0, 0

    @property
    def written(self) -> bool:
        return self.written_time >= 0

    @property
    def last(self) -> MOOSMsg:
        """The stored message, decoded (for summaries and server requests, not the hot path)."""
        return codec.decode_message(self.wire)[0] if self.wire else MOOSMsg(NOTIFY, self.data_type, self.name)


class ClientConnection(asyncio.Protocol):
    """One TCP client: handshake state, held mail, subscriptions (per spec §5)."""

    def __init__(self, db: "MOOSDB"):
        self.db = db
        self.transport: asyncio.Transport | None = None
        self.peer = "?"
        self.state = "protocol"   # -> "name" -> "ready" -> "closed"
        self.framer = codec.StreamFramer(protocol_slot=True, max_packet=db.max_packet)
        self.scanner = codec.PacketScanner()
        self.name = ""
        self.asynchronous = False
        self.consolidation = 0.0
        self.held: list[bytes] = []     # chunks of back-to-back messages
        self.held_count = 0
        self.held_bytes = 0
        self.subscribed: set[str] = set()
        self.published: set[str] = set()
        self.filters: dict[tuple[str, str], float] = {}
        self.opened = self.last_rx = _time.monotonic()
        self.packets_in = 0
        self.latency = None   # (recent, max, min, sum, count) in ms from timing messages
        self.drop_reason = ""

    def __repr__(self) -> str:
        return f"client {self.name or '?'!r} ({self.peer})"

    # -- asyncio.Protocol ---------------------------------------------------------------------
    def connection_made(self, transport):
        self.transport = transport
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if peer else "?"

    def data_received(self, data):
        self.last_rx = _time.monotonic()
        framer = self.framer
        try:
            framer.feed(data)
            while self.state != "closed" and (unit := framer.next_unit()) is not None:
                self.packets_in += 1
                if self.state == "ready":
                    self.db.process_packet(self, unit)
                elif self.state == "protocol":
                    self._check_protocol(unit)
                else:
                    self._handshake(unit)
        except (codec.CodecError, codec.FramingError) as exc:
            self.drop(f"malformed input: {exc}")
        self.db.flush()     # everything this chunk produced goes out now, one packet per client

    def connection_lost(self, exc):
        self.state = "closed"
        reason = self.drop_reason or (f"connection lost ({exc})" if exc else "closed by client")
        self.db.remove_client(self, reason)

    # -- handshake (spec §4) ------------------------------------------------------------------
    def _check_protocol(self, slot: bytes) -> None:
        if codec.protocol_matches(slot):
            self.state = "name"
        else:
            log.warning("%s: wrong protocol string %r, closing", self, slot.split(b"\0", 1)[0][:32])
            self.close()

    def _handshake(self, packet: bytes) -> None:
        try:
            msgs = codec.decode_packet(packet)
        except codec.CodecError as exc:
            log.warning("%s: unreadable handshake: %s", self, exc)
            msgs = []
        if not msgs:
            self.poison("Failed to read receive client's name")
            return
        self.db.admit(self, msgs[0])

    # -- output -------------------------------------------------------------------------------
    def queue(self, chunk: bytes, count: int) -> None:
        """Hold `count` messages (back to back in `chunk`) for this client."""
        if self.state == "closed":
            return
        self.held.append(chunk)
        self.held_count += count
        self.held_bytes += len(chunk)
        if self.asynchronous:
            self.db.dirty[self] = None
        elif self.held_bytes > self.db.max_queue:
            self.drop(f"held mail over {self.db.max_queue} bytes (synchronous client not polling)")

    def take_held(self) -> tuple[list[bytes], int]:
        held, count = self.held, self.held_count
        self.held, self.held_count, self.held_bytes = [], 0, 0
        return held, count

    def send(self, packet: bytes) -> None:
        if self.state == "closed":
            return
        self.transport.write(packet)
        if self.transport.get_write_buffer_size() > self.db.max_queue:
            self.drop(f"outgoing queue over {self.db.max_queue} bytes (client not reading)")

    def poison(self, reason: str) -> None:
        log.warning("%s refused: %s", self, reason)
        msg = MOOSMsg(POISON, STRING, "", string=reason, time=self.db.now())
        self.transport.write(codec.encode_packet([msg]))
        self.close()

    def close(self) -> None:
        """Close after sending what is queued; the DB forgets the client in connection_lost."""
        if self.state != "closed":
            self.state, self.drop_reason = "closed", "closed by the DB"
            self.transport.close()

    def drop(self, reason: str) -> None:
        """Cut a misbehaving client off at once; nobody else is affected."""
        if self.state == "closed":
            return
        log.warning("dropping %s: %s", self, reason)
        self.state, self.drop_reason = "closed", reason
        self.held, self.held_count, self.held_bytes = [], 0, 0
        self.transport.abort()


class MOOSDB:
    """The DB state (single-threaded, as the C++ processing thread) and its asyncio server."""

    def __init__(self, *, host: str = "127.0.0.1", port: int = DEFAULT_PORT, community: str = DEFAULT_COMMUNITY,
                 time_warp: float = 1.0, client_timeout: float = DEFAULT_CLIENT_TIMEOUT,
                 max_packet: int = codec.DEFAULT_MAX_PACKET, max_queue: int = DEFAULT_MAX_QUEUE,
                 response: list[tuple[str, float]] = (), refresh_period: float = REFRESH_PERIOD):
        self.host, self.port, self.community = host, port, community
        self.community_field = codec.string_field(community.encode("latin-1"))
        self.name = f"MOOSDB_{community}"
        self.time_warp = time_warp
        self.client_timeout = client_timeout
        self.max_packet, self.max_queue = max_packet, max_queue
        self.response = list(response)
        self.refresh_period = refresh_period
        self.hostname = socket.gethostname()
        self.clients: dict[str, ClientConnection] = {}
        self.connections: set[ClientConnection] = set()
        self.vars: dict[str, DBVar] = {}
        self.dirty: dict[ClientConnection, None] = {}
        self._flush_scheduled = False
        self.start_time = self.now()
        self._last_refresh = _time.monotonic()
        self._server: asyncio.Server | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._housekeeping: asyncio.Task | None = None
        for name, dtype in DB_VARIABLES:
            var = self.vars[name] = DBVar(name, dtype)
            var.wire = codec.encode_message(MOOSMsg(NOTIFY, dtype, name, self.start_time, source=self.name,
                                                    community=community, time=self.start_time))
            var.window_start = self.start_time

    def now(self) -> float:
        return moos_time(self.time_warp)

    # -- server --------------------------------------------------------------------------------
    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._server = await self._loop.create_server(self._new_connection, self.host, self.port,
                                                      backlog=4096, reuse_address=True)
        self.port = self._server.sockets[0].getsockname()[1]
        self._housekeeping = asyncio.create_task(self._housekeep())
        log.info("%s listening on %s:%d (time warp %g)", self.name, self.host, self.port, self.time_warp)

    async def run(self) -> None:
        """Serve until cancelled (how pAntler can host a DB in its own event loop)."""
        await self.start()
        try:
            await asyncio.get_running_loop().create_future()
        finally:
            self.close()

    def close(self) -> None:
        if self._housekeeping:
            self._housekeeping.cancel()
        if self._server:
            self._server.close()
        for conn in list(self.connections):
            conn.close()

    def _new_connection(self) -> ClientConnection:
        conn = ClientConnection(self)
        self.connections.add(conn)
        return conn

    async def _housekeep(self) -> None:
        """Time-outs, DB_* refresh and handshakes that never finish."""
        period = min(self.refresh_period, 0.25)
        while True:
            await asyncio.sleep(period)
            mono = _time.monotonic()
            for conn in list(self.connections):
                if conn.state == "closed":
                    self.connections.discard(conn)
                elif conn.state == "ready" and mono - conn.last_rx > self.client_timeout:
                    conn.drop(f"silent for more than {self.client_timeout:g} s (client timeout)")
                elif conn.state in ("protocol", "name") and mono - conn.opened > HANDSHAKE_TIMEOUT:
                    log.info("%s: no handshake within %g s, closing", conn, HANDSHAKE_TIMEOUT)
                    conn.close()
            self.refresh_if_due()
            self.schedule_flush()

    # -- clients -------------------------------------------------------------------------------
    def admit(self, conn: ClientConnection, hello: MOOSMsg) -> None:
        name = hello.string
        conn.name = name
        if name in self.clients:
            conn.poison(f'A client of this name ("{name}") already exists')
            return
        conn.asynchronous = hello.key.lower() == "asynchronous"
        conn.consolidation = next((s for p, s in self.response if wild_match(p, name)), 0.0)
        conn.state = "ready"
        self.clients[name] = conn
        now = self.now()
        welcome = MOOSMsg(WELCOME, DOUBLE, "", now - hello.time, "asynchronous", source_aux=f"hostname={self.hostname}",
                          community=self.community, time=now)
        conn.send(codec.encode_packet([welcome]))
        log.info("%s connected (%s)", conn, "asynchronous" if conn.asynchronous else "synchronous")
        self.post("DB_EVENT", f"connected={name}")

    def remove_client(self, conn: ClientConnection, reason: str) -> None:
        """Disconnect (spec §7): forget its subscriptions, drop its mail, free its name."""
        self.connections.discard(conn)
        if self.clients.get(conn.name) is not conn:
            return
        del self.clients[conn.name]
        self.dirty.pop(conn, None)
        for key in conn.subscribed:
            var = self.vars.get(key)
            if var:
                var.subscribers.pop(conn, None)
        conn.subscribed.clear()
        conn.filters.clear()
        log.info("%s disconnected: %s", conn, reason)
        self.post("DB_EVENT", f"disconnected={conn.name}")
        self.schedule_flush()

    # -- mail delivery -------------------------------------------------------------------------
    def schedule_flush(self) -> None:
        """Send mail queued outside packet processing (DB events, timers) on the next loop turn."""
        if self.dirty and not self._flush_scheduled and self._loop is not None:
            self._flush_scheduled = True
            self._loop.call_soon(self.flush)

    def flush(self) -> None:
        self._flush_scheduled = False
        dirty, self.dirty = self.dirty, {}
        for conn in dirty:
            if conn.held:
                conn.send(codec.pack_packet(*conn.take_held()))

    # -- packet processing (spec §5) -----------------------------------------------------------
    def process_packet(self, conn: ClientConnection, packet: bytes) -> None:
        found = conn.scanner.scan(packet)
        if not found:
            return
        now = self.now()
        head: list[bytes] = []
        if found[0].msg_type == TIMING:
            first = found[0]
            timing = codec.decode_message(packet, first.start)[0]
            found[0] = first._replace(bounds=first.bounds[1:])     # any further ones are ignored
            self._audit(conn, now, timing.time)
            timing.double, timing.double_aux = now, conn.consolidation
            head.append(codec.encode_message(timing))
        if not conn.asynchronous:   # a synchronous client gets one reply per packet, NULL first
            head.insert(0, codec.encode_message(MOOSMsg(NULL_MSG, DOUBLE, double=now)))
        replies: list[bytes] = []
        community = self.community_field
        for run in found:
            mtype = run.msg_type
            if mtype == NOTIFY:
                conn.published.add(run.key)
                self.notify(run, codec.run_bytes(packet, run, community), now)
            elif mtype != COMMAND and mtype != NULL_MSG:
                for start in run.bounds[:-1]:
                    self._request(conn, codec.decode_message(packet, start)[0], replies, now)
        self.refresh_if_due()
        held, count = conn.take_held()
        if head or replies or held:
            conn.send(codec.pack_packet(head + replies + held, len(head) + len(replies) + count))

    def _request(self, conn: ClientConnection, msg: MOOSMsg, replies: list[bytes], now: float) -> None:
        mtype = msg.msg_type
        if mtype == REGISTER:
            self.register(conn, msg.key, msg.double)
        elif mtype == UNREGISTER:
            self.unregister(conn, msg.key)
        elif mtype == WILDCARD_REGISTER or mtype == WILDCARD_UNREGISTER:
            self._wildcard(conn, msg)
        elif mtype == SERVER_REQUEST:
            replies[:0] = self.server_request(msg, now)
        else:
            log.debug("%s: ignoring message type %r", conn, mtype)

    def notify(self, run: codec.WireRun, chunk: bytes, now: float) -> None:
        """Store the run's writes (as the bytes to forward, back to back in `chunk`) and queue them for
        the subscribers.

        All arrived in one packet, so at one DB time: a throttled subscriber gets the first only.
        """
        key, data_type = run.key, run.data_type
        var = self.vars.get(key)
        if var is None:
            var = self.vars[key] = DBVar(key, window_start=now)
        if var.data_type == NOT_SET:
            var.data_type = data_type
            self._apply_filters(var, run.source)
        elif var.data_type != data_type:
            log.info("rejected write of %s by %s: %s is of type %s, not %s", key, run.source, key, var.data_type,
                     data_type)
            return
        bounds = run.bounds
        count = len(bounds) - 1
        first = last = chunk
        if count > 1:
            grow = (len(chunk) - bounds[-1] + bounds[0]) // count      # the community filled in, per message
            first, last = chunk[:bounds[1] - bounds[0] + grow], chunk[len(chunk) - (bounds[-1] - bounds[-2] + grow):]
        var.wire = last
        var.source = run.source
        var.written_time = now
        var.window_writes += count
        for conn, sub in var.subscribers.items():
            if sub[0] <= 0.0:
                conn.queue(chunk, count)
            elif now - sub[1] >= sub[0]:
                sub[1] = now
                conn.queue(first, 1)

    def post(self, key: str, value: float | str) -> None:
        """A notify by the DB itself (its DB_* variables)."""
        now = self.now()
        msg = MOOSMsg.notification(key, value, time=now, source=self.name)
        msg.community = self.community
        wire = codec.encode_message(msg)
        self.notify(codec.scan_message(wire), wire, now)

    def register(self, conn: ClientConnection, key: str, interval: float) -> None:
        if not conn.name:
            log.info("%s: cannot register %s for a client without a name", conn, key)
            return
        var = self.vars.get(key)
        if var is None:
            var = self.vars[key] = DBVar(key, window_start=self.now())
        sub = var.subscribers[conn] = [interval, -1e300]   # the first write after this always goes out
        conn.subscribed.add(key)
        if var.written:
            sub[1] = self.now()
            conn.queue(var.wire if codec.message_id(var.wire) == -1 else codec.with_id(var.wire, -1), 1)

    def unregister(self, conn: ClientConnection, key: str) -> None:
        var = self.vars.get(key)
        if var is not None:
            var.subscribers.pop(conn, None)
        conn.subscribed.discard(key)

    def _wildcard(self, conn: ClientConnection, msg: MOOSMsg) -> None:
        try:
            app, pattern, interval = parse_wildcard(msg.string)
        except ValueError as exc:
            log.warning("%s: %s", conn, exc)
            return
        if msg.msg_type == WILDCARD_REGISTER:
            conn.filters[(app, pattern)] = interval
        for var in list(self.vars.values()):
            writer = var.source if var.written else ""
            if wild_match(app, writer) and wild_match(pattern, var.name):
                if msg.msg_type == WILDCARD_REGISTER:
                    self.register(conn, var.name, interval)
                else:
                    self.unregister(conn, var.name)

    def _apply_filters(self, var: DBVar, source: str) -> None:
        """A variable's first write subscribes every client whose wildcard filter matches it."""
        for conn in list(self.clients.values()):
            for (app, pattern), interval in conn.filters.items():
                if wild_match(app, source) and wild_match(pattern, var.name):
                    var.subscribers[conn] = [interval, -1e300]
                    conn.subscribed.add(var.name)
                    break

    # -- server requests (spec §7) -------------------------------------------------------------
    def server_request(self, msg: MOOSMsg, now: float) -> list[bytes]:
        """Replies in the order the C++ DB sends them (each inserted at the front)."""
        key, rid = msg.key, msg.id
        out: list[MOOSMsg] = []
        if key == "ALL":
            for var in sorted(self.vars.values(), key=lambda v: v.name):
                last = var.last
                since = var.written_time - self.start_time if var.written else -1.0
                out.append(MOOSMsg(NOTIFY, var.data_type, var.name, last.double, last.string, last.binary,
                                   last.source, last.source_aux, last.community, since if since >= 0 else -1.0,
                                   rid, var.freq))
        elif "VAR_SUMMARY" in key:
            out.append(MOOSMsg(NOTIFY, STRING, "VAR_SUMMARY", string=",".join(sorted(self.vars)), source=self.name,
                               time=now, id=rid))
        elif "PROC_SUMMARY" in key:
            for name in sorted(self.clients):
                conn = self.clients[name]
                text = (f"{name}:SUBSCRIBED=" + "".join("," + v for v in sorted(conn.subscribed))
                        + ",PUBLISHED=" + "".join("," + v for v in sorted(conn.published)))
                out.append(MOOSMsg(NOTIFY, STRING, "PROC_SUMMARY", string=text, source=self.name,
                                   time=self.now() - self.start_time, id=rid))
        elif "DB_CLEAR" in key:
            for var in self.vars.values():
                var.reset()
            for conn in self.clients.values():
                conn.take_held()
            log.info("DB_CLEAR: every variable reset and all held mail dropped")
        return [codec.encode_message(m) for m in reversed(out)]

    # -- the DB's own variables ----------------------------------------------------------------
    def _audit(self, conn: ClientConnection, now: float, sent: float) -> None:
        ms = (now - sent) * 1000.0
        if conn.latency is None:
            conn.latency = [ms, ms, ms, ms, 1]
        else:
            lat = conn.latency
            lat[0], lat[1], lat[2], lat[3], lat[4] = ms, max(lat[1], ms), min(lat[2], ms), lat[3] + ms, lat[4] + 1

    def refresh_if_due(self) -> None:
        mono = _time.monotonic()
        if mono - self._last_refresh >= self.refresh_period:
            self._last_refresh = mono
            self.refresh()

    def refresh(self) -> None:
        now = self.now()
        for var in self.vars.values():
            span = now - var.window_start
            if span > 0:
                var.freq, var.window_writes, var.window_start = var.window_writes / span, 0, now
        clients = sorted(self.clients)
        self.post("DB_TIME", now)
        self.post("DB_UPTIME", now - self.start_time)
        self.post("DB_CLIENTS", "".join(f"{n}," for n in clients))
        self.post("DB_VARSUMMARY", self.var_summary())
        self.post("DB_QOS", "".join(f"{n}={self._qos(self.clients[n])}," for n in clients))
        self.post("DB_RWSUMMARY", ",".join(
            f"{n}={':'.join(sorted(self.clients[n].subscribed))}&{':'.join(sorted(self.clients[n].published))}"
            for n in clients))

    @staticmethod
    def _qos(conn: ClientConnection) -> str:
        if conn.latency is None:
            return "0:0:1e+09:0"
        recent, high, low, total, count = conn.latency
        return f"{recent:g}:{high:g}:{low:g}:{total / count:g}"

    def var_summary(self) -> str:
        """DB_VARSUMMARY in the C++ DB's layout; its own variables show their creation until written."""
        lines = []
        for name in sorted(self.vars):
            var = self.vars[name]
            last = var.last
            known = var.written or bool(var.wire)
            when = var.written_time if var.written else last.time
            stamp = (_time.strftime("%H:%M:%S", _time.localtime(when)) + f".{int(when * 1000) % 1000:03d}"
                     if known else "")
            writer = last.source if known else "(write pending)"
            if not var.written:
                value = ""
            elif var.data_type == DOUBLE:
                value = f"{last.double:.1f}"
            elif var.data_type == BINARY:
                value = _size(len(last.binary))
            else:
                value = last.string if len(last.string) <= 25 else last.string[:22] + "..."
            lines.append(f"{name:<20} {stamp:<20} {writer:<20} {var.freq:4.1f} Hz {var.data_type:<2} {value}\n")
        return "".join(lines)


def _size(n: int) -> str:
    if n < 1024:
        return f"*binary* {n} B"
    if n < 1024 * 1024:
        return f"*binary* {n / 1024:.1f} KB"
    return f"*binary* {n / 1024 / 1024:.1f} MB"


# -- command line --------------------------------------------------------------------------------
EXAMPLE = """\
// The MOOSDB has no ProcessConfig block: it reads these globals of the mission file.
ServerHost    = localhost   // where clients look for the DB (the DB itself binds --host, 127.0.0.1)
ServerPort    = 9000        // TCP port (default 9000)
Community     = alpha       // community name (default #1); the DB's own name is MOOSDB_<Community>
MOOSTimeWarp  = 1           // time warp of DB time and the DB_* stamps (default 1)
ClientTimeout = 5           // drop clients silent this many seconds (default 5)
"""
INTERFACE = """\
SUBSCRIPTIONS:
  none (server requests ALL, VAR_SUMMARY, PROC_SUMMARY, DB_CLEAR are answered)
PUBLICATIONS:
  DB_TIME, DB_UPTIME      DB time and uptime (s), every 2 s
  DB_CLIENTS              connected client names, comma-terminated
  DB_VARSUMMARY           one line per variable: name, time, writer, rate, type, value
  DB_RWSUMMARY            per client: name=what it reads&what it writes
  DB_QOS                  per client: timing-message latencies
  DB_EVENT                connected=<name> / disconnected=<name>
"""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="moosdb", description="A MOOSDB in pure Python, wire-compatible with the C++ MOOSDB "
        "(C++ apps, pymoos and moosdb_py clients can all connect).")
    p.add_argument("mission", nargs="?", help="mission file: ServerPort, Community, MOOSTimeWarp, ClientTimeout")
    p.add_argument("--port", "--moos_port", type=int, dest="port", help=f"TCP port (default {DEFAULT_PORT})")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1; 0.0.0.0 for a network)")
    p.add_argument("--moos_community", dest="community", help=f"community name (default {DEFAULT_COMMUNITY})")
    p.add_argument("--moos_time_warp", dest="time_warp", type=float, help="MOOS time warp (default 1)")
    p.add_argument("--moos_timeout", dest="timeout", type=float,
                   help=f"drop clients silent this many seconds (default {DEFAULT_CLIENT_TIMEOUT:g})")
    p.add_argument("--response", default="", help="per-client consolidation period: app:ms,pattern*:ms")
    p.add_argument("--max_packet", type=int, default=codec.DEFAULT_MAX_PACKET,
                   help="largest packet accepted, bytes (bigger: client dropped)")
    p.add_argument("--max_queue", type=int, default=DEFAULT_MAX_QUEUE,
                   help="largest per-client outgoing backlog, bytes (bigger: client dropped)")
    p.add_argument("-v", "--verbose", action="store_true", help="log every connection and rejected write")
    p.add_argument("--example", action="store_true", help="print the mission globals the DB reads")
    p.add_argument("--interface", action="store_true", help="print what the DB publishes")
    return p


def _settings(args: argparse.Namespace) -> dict:
    """Command line over mission file over defaults, as the C++ DB does."""
    port, community, warp, timeout = DEFAULT_PORT, DEFAULT_COMMUNITY, 1.0, DEFAULT_CLIENT_TIMEOUT
    if args.mission:
        from .mission import read_mission
        mission = read_mission(args.mission)
        port, community, warp = mission.server_port, mission.community, mission.time_warp
        timeout = float(mission.get_global("ClientTimeout", str(timeout)))
    return dict(host=args.host, port=args.port if args.port is not None else port,
                community=args.community or community, time_warp=args.time_warp or warp,
                client_timeout=args.timeout or timeout, max_packet=args.max_packet, max_queue=args.max_queue,
                response=parse_response(args.response))


async def _serve(db: MOOSDB) -> None:
    await db.start()
    print(f"moosdb: community {db.community} on {db.host}:{db.port}, time warp {db.time_warp:g}", flush=True)
    stop = asyncio.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        asyncio.get_running_loop().add_signal_handler(sig, stop.set)
    await stop.wait()
    db.close()


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if args.example or args.interface:
        print_page(EXAMPLE if args.example else INTERFACE)
        return 0
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(asctime)s %(name)s: %(message)s", stream=sys.stderr)
    try:
        db = MOOSDB(**_settings(args))
    except (ValueError, OSError) as exc:
        print(f"moosdb: {exc}", file=sys.stderr)
        return 1
    try:
        asyncio.run(_serve(db))
    except OSError as exc:
        print(f"moosdb: cannot serve on {db.host}:{db.port}: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
