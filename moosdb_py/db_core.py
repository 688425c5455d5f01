"""The MOOSDB's core, sans I/O: handshakes, routing, registrations, held mail and the DB's own variables.

What the C++ MOOSDB's CMOOSDB is, without its comms server: a state machine, as the codec is. The
server shell (`moosdb.MOOSDB`) feeds it what happens on each connection, always with the MOOS time it
happened at: a connection opening (`connect`), its bytes (`receive`), its end (`connection_lost`),
and the passing of time (`tick`). Every input answers with what to do: per connection, the bytes to
write and whether to close it afterwards (`Outgoing`). The core touches no socket and reads no clock,
so tests drive it with captured bytes and a clock of their own.

Behaviour follows docs/spec/moos-wire-protocol.md §4-§8 and the captures, except where the
C++ DB has known flaws that clients do not depend on: mail for asynchronous clients goes out as
soon as it is queued (not only when someone notifies), the DB_* variables refresh on `tick` as
well as under traffic, and bad input costs only the offending client its connection.
"""
from __future__ import annotations

import logging
import time as _time
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from . import codec
from .formats import wild_match
from .message import (BINARY, COMMAND, DOUBLE, NOT_SET, NOTIFY, NULL_MSG, POISON, REGISTER, SERVER_REQUEST,
                      STRING, TIMING, UNREGISTER, WELCOME, WILDCARD_REGISTER, WILDCARD_UNREGISTER, MOOSMsg)

log = logging.getLogger("moosdb")

DEFAULT_COMMUNITY = "#1"
DEFAULT_CLIENT_TIMEOUT = 5.0
DEFAULT_MAX_QUEUE = 32 * 1024 * 1024
HANDSHAKE_TIMEOUT = 5.0
REFRESH_PERIOD = 2.0
DB_VARIABLES = (("DB_TIME", DOUBLE), ("DB_UPTIME", DOUBLE), ("DB_CLIENTS", STRING), ("DB_VARSUMMARY", STRING),
                ("DB_QOS", STRING), ("DB_RWSUMMARY", STRING), ("DB_EVENT", STRING))

# A connection's states, in the order it goes through them (spec §4).
PROTOCOL, NAME, READY, CLOSED = "protocol", "name", "ready", "closed"
# What the shell does with a connection after writing its bytes.
CLOSE = "close"         # close once the bytes are sent
ABORT = "abort"         # cut off at once


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


@dataclass(eq=False, slots=True)
class DBVar:
    """One variable: type fixed by its first write, last message kept as it arrived (the bytes from a
    socket client, the MOOSMsg from an in-process one), the other form made only when asked for."""

    name: str
    data_type: str = NOT_SET
    _wire: bytes = b""                  # the stored value as the bytes written (community filled in)...
    _msg: MOOSMsg | None = None         # ... or as the message, decoded
    source: str = ""                    # its writer
    written_time: float = -1.0
    freq: float = 0.0
    window_writes: int = 0
    window_start: float = 0.0
    subscribers: dict = field(default_factory=dict)   # DBClient -> [interval, last_sent]

    def reset(self) -> None:
        self._wire, self._msg, self.source, self.written_time, self.freq, self.window_writes = b"", None, "", -1.0, 0.0, 0

    def store(self, wire: bytes = b"", msg: MOOSMsg | None = None) -> None:
        """The new value, in the form it came in."""
        self._wire, self._msg = wire, msg

    @property
    def written(self) -> bool:
        return self.written_time >= 0

    @property
    def stored(self) -> bool:
        return self._msg is not None or bool(self._wire)

    @property
    def wire(self) -> bytes:
        """The stored message as bytes (encoded once, when a socket client first needs it)."""
        if not self._wire and self._msg is not None:
            self._wire = codec.encode_message(self._msg)
        return self._wire

    @property
    def last(self) -> MOOSMsg:
        """The stored message, decoded once (not to be changed: copy it to hand it on)."""
        if self._msg is None:
            if not self._wire:
                return MOOSMsg(NOTIFY, self.data_type, self.name)
            self._msg = codec.decode_message(self._wire)[0]
        return self._msg


class DBClient:
    """One connection as the DB knows it: handshake state, held mail, subscriptions (spec §5)."""

    __slots__ = ("handle", "peer", "local", "shared", "state", "framer", "scanner", "name", "asynchronous", "consolidation",
                 "held", "held_count", "held_bytes", "outgoing", "end", "subscribed", "published", "filters", "opened",
                 "last_rx", "packets_in", "latency", "drop_reason")

    def __init__(self, handle: Any, peer: str, now: float, max_packet: int, local: bool = False):
        self.handle = handle            # the shell's token for the connection (its transport, a test's label)
        self.peer = peer
        self.local = local              # in-process (`connect_local`): held and outgoing hold MOOSMsgs, not bytes
        self.shared = False             # in-process and given the DB's own messages, not copies (`connect_local`)
        self.state = PROTOCOL
        self.framer = codec.StreamFramer(protocol_slot=True, max_packet=max_packet)
        self.scanner = codec.PacketScanner()
        self.name = ""
        self.asynchronous = False
        self.consolidation = 0.0
        self.held: list = []            # mail not yet in a packet: chunks of back-to-back messages (MOOSMsgs if local)
        self.held_count = 0
        self.held_bytes = 0
        self.outgoing: list = []          # packets for the shell to write (MOOSMsgs if local)
        self.end: str | None = None       # CLOSE or ABORT once the DB is done with the connection
        self.subscribed: set[str] = set()
        self.published: set[str] = set()
        self.filters: dict[tuple[str, str], float] = {}
        self.opened = self.last_rx = now
        self.packets_in = 0
        self.latency = None   # (recent, max, min, sum, count) in ms from timing messages
        self.drop_reason = ""

    def __repr__(self) -> str:
        return f"client {self.name or '?'!r} ({self.peer})"

    def take_held(self) -> tuple[list[bytes], int]:
        held, count = self.held, self.held_count
        self.held, self.held_count, self.held_bytes = [], 0, 0
        return held, count


# What the shell does on one connection: (client, bytes to write, then CLOSE, ABORT or None); for an
# in-process client a list of MOOSMsgs instead of the bytes. A plain tuple: a NamedTuple made per
# answer cost a measurable part of a small packet's trip through the DB.
Outgoing = tuple[DBClient, bytes, "str | None"]


class MOOSDBCore:
    """The DB state (single-threaded, as the C++ processing thread), driven by `connect`, `receive`,
    `connection_lost`, `tick`, `drop` and `close_all`, each taking the MOOS time now. Each but `connect`
    answers with the `Outgoing`s it caused, to be taken in full before the next input."""

    def __init__(self, *, now: float, community: str = DEFAULT_COMMUNITY, time_warp: float = 1.0,
                 client_timeout: float = DEFAULT_CLIENT_TIMEOUT, max_packet: int = codec.DEFAULT_MAX_PACKET,
                 max_queue: int = DEFAULT_MAX_QUEUE, response: list[tuple[str, float]] = (),
                 refresh_period: float = REFRESH_PERIOD, hostname: str = "localhost"):
        self.community = community
        self.community_field = codec.string_field(community.encode("latin-1"))
        self.name = f"MOOSDB_{community}"
        self.time_warp = time_warp
        self.max_packet, self.max_queue = max_packet, max_queue
        self.response = list(response)
        self.hostname = hostname
        self.client_timeout = client_timeout
        # Time-outs and the refresh period are real seconds; MOOS time runs time_warp times faster.
        self._timeout_span = client_timeout * time_warp
        self._handshake_span = HANDSHAKE_TIMEOUT * time_warp
        self._refresh_span = refresh_period * time_warp
        self.clients: dict[str, DBClient] = {}
        self.connections: set[DBClient] = set()
        self.vars: dict[str, DBVar] = {}
        self._ready: dict[DBClient, None] = {}   # clients with something for the shell
        self._ended: list[DBClient] = []         # closed by the DB, to be forgotten before the next output
        self.start_time = self._last_refresh = now
        for name, dtype in DB_VARIABLES:
            var = self.vars[name] = DBVar(name, dtype)
            var.store(msg=MOOSMsg(NOTIFY, dtype, name, now, source=self.name, community=community, time=now))
            var.window_start = now

    # -- inputs ----------------------------------------------------------------------------------
    def connect(self, handle: Any, peer: str, now: float) -> DBClient:
        """A connection opened; `handle` comes back in every `Outgoing` for it."""
        client = DBClient(handle, peer, now, self.max_packet)
        self.connections.add(client)
        return client

    def connect_local(self, handle: Any, hello: MOOSMsg, now: float,
                      shared_mail: bool = False) -> tuple[DBClient, Iterable[Outgoing]]:
        """An in-process client's connection, its handshake done at once: the welcome (or the poison that
        refuses it) is its first mail. It then talks in MOOSMsgs (`receive_local`), without bytes. Its mail
        is each subscriber's own copy, or with `shared_mail` the message the DB keeps, the same object
        for every such subscriber (a client that never changes its mail: a copy per post and subscriber
        was a tenth of a hosted vessel's routing)."""
        client = DBClient(handle, "in-process", now, self.max_packet, local=True)
        client.shared = shared_mail
        self.connections.add(client)
        client.state = NAME
        self._admit(client, hello, now)
        return client, self._output(now)

    def receive_local(self, client: DBClient, msgs: list[MOOSMsg], now: float) -> Iterable[Outgoing]:
        """Messages from an in-process client, with the effect `receive` gives their packet: the same
        routing, replies and mail, as the messages a subscriber would decode (the DB keeps and hands on
        copies; the client gives the list away)."""
        return self.receive_local_batches(((client, msgs),), now)

    def receive_local_batches(self, batches: Iterable[tuple[DBClient, list[MOOSMsg]]], now: float) -> Iterable[Outgoing]:
        """`receive_local` of several in-process clients' batches, routed in order and answered together: each
        subscriber gets the mail of all of them at once, as a socket client reads several packets in one read."""
        for client, msgs in batches:
            if client.state == READY and msgs:
                self._route_local(client, msgs, now)
        return self._output(now)

    def _route_local(self, client: DBClient, msgs: list[MOOSMsg], now: float) -> None:
        client.last_rx = now
        client.packets_in += 1
        head: list[MOOSMsg] = []
        first = 0
        if msgs[0].msg_type == TIMING:
            timing, first = msgs[0], 1
            self._audit(client, now, timing.time)
            timing.double, timing.double_aux = now, client.consolidation
            head.append(timing)
        replies: list[MOOSMsg] = []
        community = self.community
        for msg in msgs[first:] if first else msgs:
            mtype = msg.msg_type
            if mtype == NOTIFY:
                codec.as_on_the_wire(msg)
                if not msg.community:
                    msg.community = community
                client.published.add(msg.key)
                self._notify_message(msg, now)
            elif mtype != COMMAND and mtype != NULL_MSG:
                self._request(client, msg, replies, now)
        self._refresh_if_due(now)
        if head or replies:
            client.outgoing += head + replies
            self._ready[client] = None

    def receive(self, client: DBClient, data: bytes, now: float) -> Iterable[Outgoing]:
        """Bytes from a client, however the stream was chunked."""
        if client.state == CLOSED:
            return self._output(now)
        client.last_rx = now
        framer = client.framer
        try:
            framer.feed(data)
            while client.state != CLOSED and (unit := framer.next_unit()) is not None:
                client.packets_in += 1
                if client.state == READY:
                    self._process_packet(client, unit, now)
                elif client.state == PROTOCOL:
                    self._check_protocol(client, unit)
                else:
                    self._handshake(client, unit, now)
        except (codec.CodecError, codec.FramingError) as exc:
            self._drop(client, f"malformed input: {exc}")
        return self._output(now)

    def connection_lost(self, client: DBClient, reason: str, now: float) -> Iterable[Outgoing]:
        """The connection is gone (closed by the client, or after the DB's own close or abort)."""
        if client.state != CLOSED:
            client.state, client.drop_reason = CLOSED, reason
        client.take_held()
        client.outgoing.clear()
        self._ready.pop(client, None)       # nothing can be written any more
        self._remove(client, client.drop_reason, now)
        return self._output(now)

    def tick(self, now: float) -> Iterable[Outgoing]:
        """Time passing: silent clients, handshakes that never finish, the DB_* refresh."""
        for client in list(self.connections):
            if client.state == READY and now - client.last_rx > self._timeout_span:
                self._drop(client, f"silent for more than {self.client_timeout:g} s (client timeout)")
            elif client.state in (PROTOCOL, NAME) and now - client.opened > self._handshake_span:
                log.info("%s: no handshake within %g s, closing", client, HANDSHAKE_TIMEOUT)
                self._close(client)
        self._refresh_if_due(now)
        return self._output(now)

    def drop(self, client: DBClient, reason: str, now: float) -> Iterable[Outgoing]:
        """Cut a misbehaving client off at once (e.g. the shell finds it does not read its mail)."""
        self._drop(client, reason)
        return self._output(now)

    def close_all(self, now: float) -> Iterable[Outgoing]:
        """The DB shuts down: every connection closes once its bytes are sent."""
        for client in list(self.connections):
            self._close(client)
        return self._output(now)

    # -- output ----------------------------------------------------------------------------------
    def _output(self, now: float) -> Iterable[Outgoing]:
        """Everything to write since the last input (one packet of held mail per asynchronous client),
        made as it is taken, so the shell writes each client's bytes before the next client's are built."""
        while self._ended:
            ended, self._ended = self._ended, []
            for client in ended:
                self._remove(client, client.drop_reason, now)
        ready, self._ready = self._ready, {}
        if len(ready) == 1:                # the usual answer to a packet: one client's bytes
            (client,) = ready
            out = self._take(client)
            return (out,) if out else ()
        return filter(None, map(self._take, ready))

    @staticmethod
    def _take(client: DBClient) -> Outgoing | None:
        if client.local:
            mail = client.outgoing
            if client.held:
                mail += client.held
                client.held, client.held_count = [], 0
            if mail:
                client.outgoing = []
                return (client, mail, client.end)
            return (client, mail, client.end) if client.end else None
        packets = client.outgoing
        if client.held:
            packet = codec.pack_packet(client.held, client.held_count)
            client.held, client.held_count, client.held_bytes = [], 0, 0
            if not packets:
                return (client, packet, client.end)
            packets.append(packet)
        if packets:
            data = packets[0] if len(packets) == 1 else b"".join(packets)
            packets.clear()
            return (client, data, client.end)
        return (client, b"", client.end) if client.end else None

    def _send(self, client: DBClient, packet: bytes) -> None:
        if client.state != CLOSED:
            client.outgoing.append(packet)
            self._ready[client] = None

    def _reply(self, client: DBClient, msg: MOOSMsg) -> None:
        """One message in a packet of its own (the welcome, a poison)."""
        if client.local:
            if client.state != CLOSED:
                client.outgoing.append(msg)
                self._ready[client] = None
        else:
            self._send(client, codec.encode_packet([msg]))

    def _queue_messages(self, client: DBClient, msgs: list[MOOSMsg]) -> None:
        """Hold mail for an in-process client (always asynchronous)."""
        if client.state != CLOSED:
            client.held += msgs
            client.held_count += len(msgs)
            self._ready[client] = None

    def _queue(self, client: DBClient, chunk: bytes, count: int) -> None:
        """Hold `count` messages (back to back in `chunk`) for this client."""
        if client.state == CLOSED:
            return
        client.held.append(chunk)
        client.held_count += count
        client.held_bytes += len(chunk)
        if client.asynchronous:
            self._ready[client] = None
        elif client.held_bytes > self.max_queue:
            self._drop(client, f"held mail over {self.max_queue} bytes (synchronous client not polling)")

    def _close(self, client: DBClient) -> None:
        """Close after sending what is queued; the DB forgets the client before its next output."""
        if client.state != CLOSED:
            client.state, client.drop_reason, client.end = CLOSED, "closed by the DB", CLOSE
            client.take_held()
            self._ready[client] = None
            self._ended.append(client)

    def _drop(self, client: DBClient, reason: str) -> None:
        """Cut a misbehaving client off at once; nobody else is affected."""
        if client.state == CLOSED:
            return
        log.warning("dropping %s: %s", client, reason)
        client.state, client.drop_reason, client.end = CLOSED, reason, ABORT
        client.take_held()
        self._ready[client] = None
        self._ended.append(client)

    def _poison(self, client: DBClient, reason: str, now: float) -> None:
        log.warning("%s refused: %s", client, reason)
        self._reply(client, MOOSMsg(POISON, STRING, "", string=reason, time=now))
        self._close(client)

    # -- handshake (spec §4) ---------------------------------------------------------------------
    def _check_protocol(self, client: DBClient, slot: bytes) -> None:
        if codec.protocol_matches(slot):
            client.state = NAME
        else:
            log.warning("%s: wrong protocol string %r, closing", client, slot.split(b"\0", 1)[0][:32])
            self._close(client)

    def _handshake(self, client: DBClient, packet: bytes, now: float) -> None:
        try:
            msgs = codec.decode_packet(packet)
        except codec.CodecError as exc:
            log.warning("%s: unreadable handshake: %s", client, exc)
            msgs = []
        if not msgs:
            self._poison(client, "Failed to read receive client's name", now)
            return
        self._admit(client, msgs[0], now)

    def _admit(self, client: DBClient, hello: MOOSMsg, now: float) -> None:
        name = hello.string
        client.name = name
        if name in self.clients:
            self._poison(client, f'A client of this name ("{name}") already exists', now)
            return
        client.asynchronous = hello.key.lower() == "asynchronous"
        client.consolidation = next((s for p, s in self.response if wild_match(p, name)), 0.0)
        client.state = READY
        self.clients[name] = client
        welcome = MOOSMsg(WELCOME, DOUBLE, "", now - hello.time, "asynchronous", source_aux=f"hostname={self.hostname}",
                          community=self.community, time=now)
        self._reply(client, welcome)
        log.info("%s connected (%s)", client, "asynchronous" if client.asynchronous else "synchronous")
        self._post("DB_EVENT", f"connected={name}", now)

    def _remove(self, client: DBClient, reason: str, now: float) -> None:
        """Disconnect (spec §7): forget its subscriptions, drop its mail, free its name."""
        self.connections.discard(client)
        if self.clients.get(client.name) is not client:
            return
        del self.clients[client.name]
        for key in client.subscribed:
            var = self.vars.get(key)
            if var:
                var.subscribers.pop(client, None)
        client.subscribed.clear()
        client.filters.clear()
        log.info("%s disconnected: %s", client, reason)
        self._post("DB_EVENT", f"disconnected={client.name}", now)

    # -- packet processing (spec §5) -------------------------------------------------------------
    def _process_packet(self, client: DBClient, packet: bytes, now: float) -> None:
        found = client.scanner.scan(packet)
        if not found:
            return
        head: list[bytes] = []
        if found[0].msg_type == TIMING:
            first = found[0]
            timing = codec.decode_message(packet, first.start)[0]
            found[0] = first._replace(bounds=first.bounds[1:])     # any further ones are ignored
            self._audit(client, now, timing.time)
            timing.double, timing.double_aux = now, client.consolidation
            head.append(codec.encode_message(timing))
        if not client.asynchronous:   # a synchronous client gets one reply per packet, NULL first
            head.insert(0, codec.encode_message(MOOSMsg(NULL_MSG, DOUBLE, double=now)))
        replies: list[MOOSMsg] = []
        community = self.community_field
        for run in found:
            mtype = run.msg_type
            if mtype == NOTIFY:
                client.published.add(run.key)
                self._notify(run, codec.run_bytes(packet, run, community), now)
            elif mtype != COMMAND and mtype != NULL_MSG:
                for start in run.bounds[:-1]:
                    self._request(client, codec.decode_message(packet, start)[0], replies, now)
        self._refresh_if_due(now)
        held, count = client.take_held()
        if head or replies or held:
            head += map(codec.encode_message, replies)
            self._send(client, codec.pack_packet(head + held, len(head) + count))

    def _request(self, client: DBClient, msg: MOOSMsg, replies: list[MOOSMsg], now: float) -> None:
        mtype = msg.msg_type
        if mtype == REGISTER:
            self._register(client, msg.key, msg.double, now)
        elif mtype == UNREGISTER:
            self._unregister(client, msg.key)
        elif mtype == WILDCARD_REGISTER or mtype == WILDCARD_UNREGISTER:
            self._wildcard(client, msg, now)
        elif mtype == SERVER_REQUEST:
            replies[:0] = self._server_request(msg, now)
        else:
            log.debug("%s: ignoring message type %r", client, mtype)

    def _written(self, key: str, data_type: str, source: str, now: float) -> DBVar | None:
        """The variable a write goes to; None when its type refuses the write."""
        var = self.vars.get(key)
        if var is None:
            var = self.vars[key] = DBVar(key, window_start=now)
        if var.data_type == NOT_SET:
            var.data_type = data_type
            self._apply_filters(var, source)
        elif var.data_type != data_type:
            log.info("rejected write of %s by %s: %s is of type %s, not %s", key, source, key, var.data_type,
                     data_type)
            return None
        return var

    def _notify(self, run: codec.WireRun, chunk: bytes, now: float) -> None:
        """Store the run's writes (as the bytes to forward, back to back in `chunk`) and queue them for
        the subscribers.

        All arrived in one packet, so at one DB time: a throttled subscriber gets the first only.
        """
        var = self._written(run.key, run.data_type, run.source, now)
        if var is None:
            return
        bounds = run.bounds
        count = len(bounds) - 1
        first = last = chunk
        if count > 1:
            grow = (len(chunk) - bounds[-1] + bounds[0]) // count      # the community filled in, per message
            first, last = chunk[:bounds[1] - bounds[0] + grow], chunk[len(chunk) - (bounds[-1] - bounds[-2] + grow):]
        var.store(wire=last)
        var.source = run.source
        var.written_time = now
        var.window_writes += count
        decoded = None
        for client, sub in var.subscribers.items():
            if sub[0] <= 0.0:
                wire, n = chunk, count
            elif now - sub[1] >= sub[0]:
                sub[1] = now
                wire, n = first, 1
            else:
                continue
            if client.local:
                if decoded is None:
                    decoded = codec.decode_run(chunk, count)[0]
                self._queue_messages(client, decoded[:n] if client.shared else [m.copy() for m in decoded[:n]])
            else:
                self._queue(client, wire, n)

    def _notify_message(self, msg: MOOSMsg, now: float) -> None:
        """`_notify` for a write that came as a message (an in-process client's, the DB's own): encoded only
        if a socket client subscribes, each in-process subscriber given its own copy.

        Written out in one piece (no call per subscriber): hosted vessels route about a hundred of these
        per vessel per simulated second, and the calls were most of their cost."""
        var = self.vars.get(msg.key)
        if var is None or var.data_type != msg.data_type:     # new, never written, or the wrong type
            var = self._written(msg.key, msg.data_type, msg.source, now)
            if var is None:
                return
        var.store(msg=msg)
        var.source = msg.source
        var.written_time = now
        var.window_writes += 1
        if not var.subscribers:
            return
        ready = self._ready
        for client, sub in var.subscribers.items():
            if sub[0] > 0.0:
                if now - sub[1] < sub[0]:
                    continue
                sub[1] = now
            if not client.local:
                self._queue(client, var.wire, 1)
            elif client.state != CLOSED:
                client.held.append(msg if client.shared else msg.copy())
                client.held_count += 1
                ready[client] = None

    def _post(self, key: str, value: float | str, now: float) -> None:
        """A notify by the DB itself (its DB_* variables)."""
        msg = MOOSMsg.notification(key, value, time=now, source=self.name)
        msg.community = self.community
        self._notify_message(msg, now)

    def _register(self, client: DBClient, key: str, interval: float, now: float) -> None:
        if not client.name:
            log.info("%s: cannot register %s for a client without a name", client, key)
            return
        var = self.vars.get(key)
        if var is None:
            var = self.vars[key] = DBVar(key, window_start=now)
        sub = var.subscribers[client] = [interval, -1e300]   # the first write after this always goes out
        client.subscribed.add(key)
        if var.written:
            sub[1] = now
            if client.local:
                current = var.last.copy()
                current.id = -1
                self._queue_messages(client, [current])
            else:
                self._queue(client, var.wire if codec.message_id(var.wire) == -1 else codec.with_id(var.wire, -1), 1)

    def _unregister(self, client: DBClient, key: str) -> None:
        var = self.vars.get(key)
        if var is not None:
            var.subscribers.pop(client, None)
        client.subscribed.discard(key)

    def _wildcard(self, client: DBClient, msg: MOOSMsg, now: float) -> None:
        try:
            app, pattern, interval = parse_wildcard(msg.string)
        except ValueError as exc:
            log.warning("%s: %s", client, exc)
            return
        if msg.msg_type == WILDCARD_REGISTER:
            client.filters[(app, pattern)] = interval
        for var in list(self.vars.values()):
            writer = var.source if var.written else ""
            if wild_match(app, writer) and wild_match(pattern, var.name):
                if msg.msg_type == WILDCARD_REGISTER:
                    self._register(client, var.name, interval, now)
                else:
                    self._unregister(client, var.name)

    def _apply_filters(self, var: DBVar, source: str) -> None:
        """A variable's first write subscribes every client whose wildcard filter matches it."""
        for client in list(self.clients.values()):
            for (app, pattern), interval in client.filters.items():
                if wild_match(app, source) and wild_match(pattern, var.name):
                    var.subscribers[client] = [interval, -1e300]
                    client.subscribed.add(var.name)
                    break

    # -- server requests (spec §7) ---------------------------------------------------------------
    def _server_request(self, msg: MOOSMsg, now: float) -> list[MOOSMsg]:
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
                client = self.clients[name]
                text = (f"{name}:SUBSCRIBED=" + "".join("," + v for v in sorted(client.subscribed))
                        + ",PUBLISHED=" + "".join("," + v for v in sorted(client.published)))
                out.append(MOOSMsg(NOTIFY, STRING, "PROC_SUMMARY", string=text, source=self.name,
                                   time=now - self.start_time, id=rid))
        elif "DB_CLEAR" in key:
            for var in self.vars.values():
                var.reset()
            for client in self.clients.values():
                client.take_held()
            log.info("DB_CLEAR: every variable reset and all held mail dropped")
        return out[::-1]

    # -- the DB's own variables ------------------------------------------------------------------
    @staticmethod
    def _audit(client: DBClient, now: float, sent: float) -> None:
        ms = (now - sent) * 1000.0
        if client.latency is None:
            client.latency = [ms, ms, ms, ms, 1]
        else:
            lat = client.latency
            lat[0], lat[1], lat[2], lat[3], lat[4] = ms, max(lat[1], ms), min(lat[2], ms), lat[3] + ms, lat[4] + 1

    def _refresh_if_due(self, now: float) -> None:
        if now - self._last_refresh >= self._refresh_span:
            self._last_refresh = now
            self._refresh(now)

    def _refresh(self, now: float) -> None:
        for var in self.vars.values():
            span = now - var.window_start
            if span > 0:
                var.freq, var.window_writes, var.window_start = var.window_writes / span, 0, now
        clients = sorted(self.clients)
        self._post("DB_TIME", now, now)
        self._post("DB_UPTIME", now - self.start_time, now)
        self._post("DB_CLIENTS", "".join(f"{n}," for n in clients), now)
        self._post("DB_VARSUMMARY", self.var_summary(), now)
        self._post("DB_QOS", "".join(f"{n}={self._qos(self.clients[n])}," for n in clients), now)
        self._post("DB_RWSUMMARY", ",".join(
            f"{n}={':'.join(sorted(self.clients[n].subscribed))}&{':'.join(sorted(self.clients[n].published))}"
            for n in clients), now)

    @staticmethod
    def _qos(client: DBClient) -> str:
        if client.latency is None:
            return "0:0:1e+09:0"
        recent, high, low, total, count = client.latency
        return f"{recent:g}:{high:g}:{low:g}:{total / count:g}"

    def var_summary(self) -> str:
        """DB_VARSUMMARY in the C++ DB's layout; its own variables show their creation until written."""
        lines = []
        for name in sorted(self.vars):
            var = self.vars[name]
            last = var.last
            known = var.written or var.stored
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
