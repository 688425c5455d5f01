"""An asyncio MOOS client (the V10 asynchronous kind), usable against this DB or the C++ MOOSDB.

Like `MOOS::MOOSAsyncCommClient`: it sends when it has mail (prefixed by a timing message at most
once a second, and at least once a second to stay alive), the DB pushes mail to it, and it
reconnects every second after a lost connection, re-applying its subscriptions.
"""
from __future__ import annotations

import asyncio
import logging
import time as _time
from collections.abc import Callable

from . import codec
from .message import (ASYNC_TIMING_KEY, DATA, NULL_MSG, POISON, REGISTER, SERVER_REQUEST, SERVER_REQUEST_ID,
                      STRING, TIMING, UNREGISTER, WELCOME, WILDCARD_REGISTER, MOOSMsg, moos_time)

log = logging.getLogger("moosdb_py.client")

OUTBOX_LIMIT = 65536        # unsent messages kept; beyond it the oldest half goes, as the C++ client does
TIMING_PERIOD = 1.0
KEEPALIVE_DELAY = 1.25 * TIMING_PERIOD  # in-process: a timing message alone when no AppTick sent one for this long
HANDSHAKE_TIMEOUT = 5.0


def resolve(future: asyncio.Future) -> None:
    """Wake whoever awaits `future` (a sleep that ends early), once."""
    if not future.done():
        future.set_result(None)


class Poisoned(ConnectionError):
    """The DB refused this client (e.g. its name is taken); MOOS clients then stop trying."""


class MOOSClient:
    """Connect, handshake, register, notify, receive mail; reconnects by itself until `close()`.

    `on_mail(list[MOOSMsg])` and `on_connect()` run in the event loop. Without `on_mail`, mail
    collects for `fetch()`.
    """

    reconnect_interval = 1.0

    def __init__(self, name: str, host: str = "127.0.0.1", port: int = 9000, *,
                 on_mail: Callable[[list[MOOSMsg]], None] | None = None,
                 on_connect: Callable[[], None] | None = None, time_warp: float = 1.0, local_db=None):
        self.name, self.host, self.port = name, host, port
        self.local_db = local_db    # a MOOSDB in this event loop: connect through `open_local`, no socket
        self.shared_mail = False    # in-process: mail is the DB's own message, shared, not a copy (read, never changed)
        self.on_mail, self.on_connect = on_mail, on_connect
        self.time_warp = time_warp
        self.connected = False
        self.community = ""
        self.db_hostname = ""
        self.poisoned: str | None = None
        self.registrations: dict[str, float] = {}
        self.wildcards: dict[tuple[str, str], float] = {}
        self.published: set[str] = set()
        self.inbox: list[MOOSMsg] = []
        self.messages_sent = self.messages_read = 0
        self.bytes_sent = self.bytes_read = 0
        self.db_skew = 0.0          # the welcome's dval: DB time - our hello's time (CMOOSCommClient::HandShake)
        self._applied: dict[object, float] = {}
        self._outbox: list[MOOSMsg] = []
        self._next_id = 0
        self._closing = False
        self._last_timing = -1e300
        self._kick: Callable[[], None] | None = None   # the session's "something to send" (a post calls it)
        self._holding = False       # posts wait for `send_held` (a MOOSApp's tick: one batch per tick)
        self._wake: asyncio.Future | None = None   # the session's sleep, resolved early by close()
        self._connected_event: asyncio.Event | None = None
        self._closed_event: asyncio.Event | None = None

    def moos_time(self) -> float:
        return moos_time(self.time_warp)

    # -- life cycle ----------------------------------------------------------------------------
    async def run(self) -> None:
        """Connect and serve until `close()` (or a poison from the DB)."""
        self._connected_event, self._closed_event = asyncio.Event(), asyncio.Event()
        while not self._closing:
            try:
                if self.local_db is not None:
                    await self._local_session(self.local_db)
                else:
                    await self._session()
            except Poisoned as exc:
                self.poisoned = str(exc)
                log.error("%s: refused by the DB: %s", self.name, exc)
                break
            except (OSError, EOFError, TimeoutError, codec.CodecError, codec.FramingError) as exc:
                if self._closing:
                    pass
                elif self.connected:
                    log.warning("%s: connection to %s:%d lost: %s", self.name, self.host, self.port, exc)
                else:
                    log.debug("%s: cannot connect to %s:%d: %s", self.name, self.host, self.port, exc)
            finally:
                self.connected = False
                self._connected_event.clear()
                self._kick = None
            if not self._closing:
                try:
                    async with asyncio.timeout(self.reconnect_interval):
                        await self._closed_event.wait()
                except TimeoutError:
                    pass
        self._closed_event.set()

    async def wait_connected(self, timeout: float) -> bool:
        while self._connected_event is None:          # run() not started yet
            await asyncio.sleep(0.005)
            timeout -= 0.005
        try:
            async with asyncio.timeout(max(timeout, 0.0)):
                await self._connected_event.wait()
        except TimeoutError:
            pass
        return self.connected

    def close(self) -> None:
        """Send what is queued, then disconnect and stop reconnecting."""
        self._closing = True
        self._wake_up()
        if self._closed_event is not None:
            self._closed_event.set()

    # -- one connection ------------------------------------------------------------------------
    def _hello(self) -> MOOSMsg:
        return MOOSMsg(DATA, STRING, "asynchronous", string=self.name, time=self.moos_time())

    def _welcomed(self, reply: MOOSMsg | None) -> None:
        """The DB's answer to our hello: connected (subscriptions re-applied, `on_connect` called), or refused."""
        if reply is not None and reply.msg_type == POISON:
            raise Poisoned(reply.string)
        if reply is None or reply.msg_type != WELCOME:
            raise codec.CodecError(f"expected a welcome, got {reply or 'an empty packet'}")
        self.community = reply.community
        self.db_hostname = reply.source_aux.partition("=")[2]
        self.db_skew = reply.double
        self.connected = True
        self._last_timing = -1e300
        self._applied.clear()
        self._apply_subscriptions()
        self._connected_event.set()
        log.info("%s: connected to %s:%d (community %s)", self.name, self.host, self.port, self.community)
        if self.on_connect:
            self.on_connect()

    async def _session(self) -> None:
        """One TCP connection: handshake, then a write loop beside the reads."""
        reader, writer = await asyncio.open_connection(self.host, self.port)
        try:
            writer.write(codec.PROTOCOL_SLOT + codec.encode_packet([self._hello()]))
            framer = codec.StreamFramer()
            async with asyncio.timeout(HANDSHAKE_TIMEOUT):
                while (packet := framer.next_unit()) is None:
                    data = await reader.read(65536)
                    if not data:
                        raise EOFError("DB closed the connection during the handshake (bad protocol?)")
                    framer.feed(data)
            reply = codec.decode_packet(packet)
            self._welcomed(reply[0] if reply else None)
            writing = asyncio.create_task(self._write_loop(writer))
            self._kick = self._wake_up
            try:
                self._deliver(framer)
                while True:
                    data = await reader.read(262144)
                    if not data:
                        if self._closing:
                            return
                        raise EOFError("DB closed the connection")
                    self.bytes_read += len(data)
                    framer.feed(data)
                    self._deliver(framer)
            finally:
                writing.cancel()
        finally:
            writer.close()

    async def _local_session(self, db) -> None:
        """One in-process connection (`MOOSDB.open_local`): the DB takes our batches and hands us mail as
        MOOSMsgs. A timing message goes with the first batch a second after the last one (a MOOSApp's
        AppTick sends one then, `send_held`); a keep-alive timer, moved on by each, sends one alone only
        when none went for KEEPALIVE_DELAY: while its app ticks, the connection wakes the loop for nothing."""
        link = db.open_local(self._hello(), self.shared_mail)
        loop = asyncio.get_running_loop()
        keepalive = loop.call_soon(link.kick)     # the first timing message, at once

        def take() -> list[MOOSMsg]:
            nonlocal keepalive
            sent = self._last_timing
            msgs = self._next_batch()
            if self._last_timing != sent:
                keepalive.cancel()
                keepalive = loop.call_later(KEEPALIVE_DELAY, link.kick)
            return msgs

        try:
            self._welcomed(link.replies[0] if link.replies else None)
            link.attach(take, self._deliver_mail)
            self._deliver_mail(link.replies[1:])
            self._kick = link.kick
            while not self._closing:
                self._wake = link.wake = wake = loop.create_future()
                try:
                    await wake
                finally:
                    self._wake = link.wake = None
                if link.error is not None:
                    raise link.error
                if link.ended:
                    raise EOFError("DB closed the connection")
        finally:
            link.disconnect()
            keepalive.cancel()

    def _wake_up(self) -> None:
        if self._wake is not None:
            resolve(self._wake)

    def _next_batch(self) -> list[MOOSMsg]:
        """What goes to the DB now: the outbox, after a timing message when a second has passed since the
        last one (also sent alone, to stay alive)."""
        msgs, self._outbox = self._outbox, []
        mono = _time.monotonic()
        if mono - self._last_timing >= TIMING_PERIOD:
            self._last_timing = mono
            msgs.insert(0, MOOSMsg(TIMING, "D", ASYNC_TIMING_KEY, 0.0, time=self.moos_time()))
        self.messages_sent += len(msgs)
        return msgs

    async def _write_loop(self, writer: asyncio.StreamWriter) -> None:
        loop = asyncio.get_running_loop()
        while True:
            delay = self._last_timing + TIMING_PERIOD - _time.monotonic()
            if delay > 0 and not self._outbox and not self._closing:
                self._wake = wake = loop.create_future()
                timer = loop.call_later(delay, resolve, wake)
                try:
                    await wake
                finally:
                    timer.cancel()
                    self._wake = None
            msgs = self._next_batch()
            if msgs:
                packet = codec.encode_packet(msgs)
                writer.write(packet)
                self.bytes_sent += len(packet)
                await writer.drain()
            if self._closing and not self._outbox:
                writer.close()
                return

    def _deliver(self, framer: codec.StreamFramer) -> None:
        mail = []
        while (packet := framer.next_unit()) is not None:
            mail += codec.decode_packet(packet)
        self._deliver_mail(mail)

    def _deliver_mail(self, mail: list[MOOSMsg]) -> None:
        """Mail from the DB (timing echoes and NULL messages left out) to `on_mail`, else the inbox."""
        mail = [m for m in mail if m.msg_type != TIMING and m.msg_type != NULL_MSG]
        if not mail:
            return
        self.messages_read += len(mail)
        if self.on_mail is not None:
            self.on_mail(mail)
        else:
            self.inbox.extend(mail)

    # -- posting -------------------------------------------------------------------------------
    def post(self, msg: MOOSMsg, *, keep_source: bool = False) -> None:
        """Queue any message (CMOOSCommClient::Post): numbered, stamped with our name unless
        `keep_source` (how pShare forwards mail under its original source)."""
        if msg.id != SERVER_REQUEST_ID:
            msg.id = self._next_id
            self._next_id += 1
        if not keep_source:
            msg.source = self.name
        self._send(msg)

    def _send(self, msg: MOOSMsg) -> None:
        """Queue a numbered, signed message and say there is something to send (unless posts are held)."""
        outbox = self._outbox
        outbox.append(msg)
        if len(outbox) > OUTBOX_LIMIT:
            log.warning("%s: outbox over %d messages, dropping the oldest half", self.name, OUTBOX_LIMIT)
            del outbox[:len(outbox) // 2]
        if self._kick is not None and not self._holding:
            self._kick()

    def hold_posts(self) -> None:
        """Keep posts in the outbox until `send_held` (no wake-up per post)."""
        self._holding = True

    def send_held(self) -> None:
        """Send what was held, with a timing message when one is due even if nothing was held: an app's
        AppTick keeps its connection alive. In-process, the DB takes it when the running loop callback
        (the AppTicker's wake-up) returns, with every other hosted client's: the batching MOOS's clients
        do at a time warp (they hold mail 0.2 ms per unit of warp), and the apps of one wake-up cost the
        DB one delivery per subscriber."""
        self._holding = False
        if self._kick is not None and (self._outbox or _time.monotonic() - self._last_timing >= TIMING_PERIOD):
            self._kick()

    def _apply_subscriptions(self) -> None:
        for key, interval in self.registrations.items():
            self._send_register(key, interval)
        for (var, app), interval in self.wildcards.items():
            self._send_wildcard(var, app, interval)

    def _send_register(self, key: str, interval: float) -> None:
        if self.connected and self._applied.get(key) != interval:
            self._applied[key] = interval
            self.post(MOOSMsg(REGISTER, "D", key, float(interval), time=self.moos_time()))

    def _send_wildcard(self, var: str, app: str, interval: float) -> None:
        if self.connected and self._applied.get((var, app)) != interval:
            self._applied[(var, app)] = interval
            self.post(MOOSMsg(WILDCARD_REGISTER, STRING, self.name, time=self.moos_time(),
                               string=f"AppPattern={app},VarPattern={var},Interval={interval:g}"))

    def register(self, key: str, interval: float = 0.0) -> None:
        """Subscribe (kept across reconnects); registering again with the same interval is a no-op."""
        self.registrations[key] = interval
        self._send_register(key, interval)

    def register_wildcard(self, var_pattern: str, app_pattern: str = "*", interval: float = 0.0) -> None:
        self.wildcards[(var_pattern, app_pattern)] = interval
        self._send_wildcard(var_pattern, app_pattern, interval)

    def unregister(self, key: str) -> None:
        self.registrations.pop(key, None)
        self._applied.pop(key, None)
        if self.connected:   # also ends a subscription made by a wildcard
            self.post(MOOSMsg(UNREGISTER, "D", key, 0.0, time=self.moos_time()))

    def notify(self, key: str, value: float | str | bytes, time: float | None = None, source_aux: str = "") -> None:
        """`post` of a notification, numbered and signed as it is made (apps post about a hundred a
        simulated second)."""
        self.published.add(key)
        self._send(MOOSMsg.notification(key, value, time=moos_time(self.time_warp) if time is None else time,
                                        source=self.name, source_aux=source_aux, msg_id=self._next_id))
        self._next_id += 1

    def server_request(self, request: str) -> None:
        """Ask the DB for ALL, VAR_SUMMARY, PROC_SUMMARY or DB_CLEAR; replies arrive as mail (id -2)."""
        self.post(MOOSMsg(SERVER_REQUEST, STRING, request, time=self.moos_time(), id=SERVER_REQUEST_ID))

    @property
    def unsent_messages(self) -> int:
        """Messages queued but not yet handed to the socket."""
        return len(self._outbox)

    def fetch(self) -> list[MOOSMsg]:
        """Mail received since the last fetch (when no `on_mail` callback is set)."""
        mail, self.inbox = self.inbox, []
        return mail

    async def flush(self, timeout: float = 5.0) -> None:
        """Wait until everything queued so far has been handed to the socket."""
        async with asyncio.timeout(timeout):
            while self._outbox:
                await asyncio.sleep(0.001)

