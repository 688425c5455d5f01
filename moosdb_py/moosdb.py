"""MOOSDB: the MOOS community's hub, wire-compatible with the C++ MOOSDB, on asyncio.

A thin shell, as the C++ DB's comms server is: it accepts TCP connections, hands each one's bytes
to the sans-I/O core (`db_core.MOOSDBCore`, where handshakes, routing, held mail and the DB_*
variables live) with the MOOS time now, and writes, closes or aborts connections as the core
answers. A timer feeds the core the passing of time (client time-outs, DB_* refresh).
"""
from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import socket
import sys
from collections.abc import Callable, Iterable

from . import codec
from .client import resolve
from .db_core import (ABORT, CLOSE, DEFAULT_CLIENT_TIMEOUT, DEFAULT_COMMUNITY, DEFAULT_MAX_QUEUE, REFRESH_PERIOD,
                      DBClient, DBVar, MOOSDBCore, Outgoing)
from .formats import print_page, version_page
from .message import MOOSMsg, moos_time

log = logging.getLogger("moosdb")

DEFAULT_PORT = 9000


def parse_response(spec: str) -> list[tuple[str, float]]:
    """`--response=app:ms,pattern*:ms` -> [(pattern, seconds)]."""
    out = []
    for item in filter(None, (s.strip() for s in spec.split(","))):
        pattern, sep, ms = item.rpartition(":")
        if not sep:
            raise ValueError(f"--response item {item!r} is not NAME:MS")
        out.append((pattern, float(ms) / 1000.0))
    return out


class ClientConnection(asyncio.Protocol):
    """One TCP client: its bytes and its end go to the core, what the core answers goes out."""

    def __init__(self, db: "MOOSDB"):
        self.db = db
        self.client: DBClient | None = None

    def connection_made(self, transport):
        peer = transport.get_extra_info("peername")
        self.client = self.db.core.connect(transport, f"{peer[0]}:{peer[1]}" if peer else "?", self.db.now())

    def data_received(self, data):
        db = self.db
        db.transmit(db.core.receive(self.client, data, moos_time(db.time_warp)))

    def connection_lost(self, exc):
        db = self.db
        db.transmit(db.core.connection_lost(self.client, f"connection lost ({exc})" if exc else "closed by client",
                                            db.now()))


class LocalLink:
    """An in-process client's connection (pAntler --host-db): MOOSMsgs both ways, no bytes, no socket.

    The client posts into its own outbox and `kick`s; the DB takes every kicked client's batch (`take`)
    in one pass of the event loop, after the posting code returns, as it would take a socket's bytes,
    and hands each client its mail (`deliver`) as soon as the core answers. The core's routing is the
    one socket clients get, so the mail is the same (tests/moosdb_py/test_local_connection.py).
    """

    def __init__(self, db: "MOOSDB", hello: MOOSMsg, shared_mail: bool = False):
        self.db = db
        self.take: Callable[[], list[MOOSMsg]] | None = None     # set by `attach`
        self.deliver: Callable[[list[MOOSMsg]], None] | None = None
        self.replies: list[MOOSMsg] = []     # what arrives before `attach`: the welcome or the poison
        self.ended = False
        self.error: BaseException | None = None   # what the client's `deliver` raised (its session re-raises it)
        self.wake: asyncio.Future | None = None   # the client's wait, resolved when the connection ends
        self.client, outgoing = db.core.connect_local(self, hello, db.now(), shared_mail)
        db.transmit(outgoing)

    def attach(self, take: Callable[[], list[MOOSMsg]], deliver: Callable[[list[MOOSMsg]], None]) -> None:
        self.take, self.deliver = take, deliver

    # -- the DB's side (what `MOOSDB.transmit` needs of a transport) -------------------------------
    def write(self, mail: list[MOOSMsg]) -> None:
        if self.deliver is None:
            self.replies += mail
        elif self.error is None:
            try:
                self.deliver(mail)
            except Exception as exc:   # the client's mail handler failed: its session ends with the error
                self.error = exc
                if self.wake is not None:
                    resolve(self.wake)

    def close(self) -> None:
        self.ended = True
        if self.wake is not None:
            resolve(self.wake)

    abort = close

    # -- the client's side ------------------------------------------------------------------------
    def kick(self) -> None:
        """The client has something to send: taken in this loop pass's flush."""
        if not self.ended:
            self.db.kick(self)

    def batch(self) -> list[MOOSMsg]:
        """What the client has to send (nothing once the link ended or its client failed)."""
        if self.ended or self.error is not None or self.take is None:
            return []
        return self.take()

    def flush(self) -> None:
        msgs = self.batch()
        if msgs:
            self.db.transmit(self.db.core.receive_local(self.client, msgs, self.db.now()))

    def disconnect(self) -> None:
        """Send what is queued (unless the client failed), then close, as a socket client's close does."""
        self.flush()
        if not self.ended:
            self.ended = True
            reason = f"client failed: {self.error!r}" if self.error else "closed by client"
            self.db.transmit(self.db.core.connection_lost(self.client, reason, self.db.now()))


class MOOSDB:
    """The asyncio server around a `MOOSDBCore`."""

    def __init__(self, *, host: str = "127.0.0.1", port: int = DEFAULT_PORT, community: str = DEFAULT_COMMUNITY,
                 time_warp: float = 1.0, client_timeout: float = DEFAULT_CLIENT_TIMEOUT,
                 max_packet: int = codec.DEFAULT_MAX_PACKET, max_queue: int = DEFAULT_MAX_QUEUE,
                 response: list[tuple[str, float]] = (), refresh_period: float = REFRESH_PERIOD):
        self.host, self.port, self.community = host, port, community
        self.time_warp = time_warp
        self.max_queue = max_queue
        self.refresh_period = refresh_period
        self.core = MOOSDBCore(now=self.now(), community=community, time_warp=time_warp,
                               client_timeout=client_timeout, max_packet=max_packet, max_queue=max_queue,
                               response=response, refresh_period=refresh_period, hostname=socket.gethostname())
        self.name = self.core.name
        self._server: asyncio.Server | None = None
        self._housekeeping: asyncio.Task | None = None
        self._serving = False
        self._kicked: dict[LocalLink, None] = {}   # in-process clients with a batch to take
        self._flush_due = False
        self._loop: asyncio.AbstractEventLoop | None = None   # the serving loop (asking each wake-up: a getpid call)

    @property
    def clients(self) -> dict[str, DBClient]:
        return self.core.clients

    @property
    def connections(self) -> set[DBClient]:
        return self.core.connections

    @property
    def vars(self) -> dict[str, DBVar]:
        return self.core.vars

    def now(self) -> float:
        return moos_time(self.time_warp)

    async def start(self) -> None:
        loop = self._loop = asyncio.get_running_loop()
        self._server = await loop.create_server(lambda: ClientConnection(self), self.host, self.port,
                                                backlog=4096, reuse_address=True)
        self.port = self._server.sockets[0].getsockname()[1]
        self._housekeeping = asyncio.create_task(self._housekeep())
        self._serving = True
        log.info("%s listening on %s:%d (time warp %g)", self.name, self.host, self.port, self.time_warp)

    async def run(self) -> None:
        """Serve until cancelled (how pAntler can host a DB in its own event loop)."""
        await self.start()
        try:
            await asyncio.get_running_loop().create_future()
        finally:
            self.close()

    def open_local(self, hello: MOOSMsg, shared_mail: bool = False) -> LocalLink:
        """A connection for a client in this process and event loop, without a socket (pAntler --host-db);
        `hello` is the client's handshake message, answered in the link's `replies`; `shared_mail`: see
        `MOOSDBCore.connect_local`."""
        if not self._serving:
            raise ConnectionRefusedError(f"{self.name} is not serving")
        return LocalLink(self, hello, shared_mail)

    def kick(self, link: LocalLink) -> None:
        """Take `link`'s batch later in this loop pass, with every other in-process client's."""
        self._kicked[link] = None
        if not self._flush_due:
            self._flush_due = True
            self._loop.call_soon(self._flush_local)

    def _flush_local(self) -> None:
        self._flush_due = False
        kicked, self._kicked = self._kicked, {}
        batches = [(link.client, msgs) for link in kicked if (msgs := link.batch())]
        if batches:
            self.transmit(self.core.receive_local_batches(batches, self.now()))

    def close(self) -> None:
        self._serving = False
        if self._housekeeping:
            self._housekeeping.cancel()
        if self._server:
            self._server.close()
        self.transmit(self.core.close_all(self.now()))

    async def _housekeep(self) -> None:
        """Tell the core the time (time-outs, DB_* refresh without traffic) twice a refresh period and four
        times a client time-out: with the defaults once a second (traffic refreshes DB_* on time anyway)."""
        period = min(self.refresh_period / 2, self.core.client_timeout / 4)
        while True:
            await asyncio.sleep(period)
            self.transmit(self.core.tick(self.now()))

    def transmit(self, outgoing: Iterable[Outgoing]) -> None:
        """Do what the core answered; a client whose unsent backlog passes max_queue is dropped."""
        stuck = None
        for client, data, end in outgoing:
            transport = client.handle
            if data:
                transport.write(data)
            if end is None and not client.local:     # mail handed over in-process never waits in a buffer
                if transport.get_write_buffer_size() > self.max_queue:
                    stuck = [*(stuck or ()), client]
            elif end == ABORT:
                transport.abort()
            elif end == CLOSE:
                transport.close()
        for client in stuck or ():
            reason = f"outgoing queue over {self.max_queue} bytes (client not reading)"
            self.transmit(self.core.drop(client, reason, self.now()))


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
    p.add_argument("--version", action="version", version=version_page("MOOSDB"), help="print the release")
    return p


def db_from_args(argv: list[str]) -> MOOSDB:
    """The DB the `moosdb` command line describes (pAntler builds a hosted DB from its Run line with it)."""
    return MOOSDB(**_settings(_parser().parse_args(argv)))


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
