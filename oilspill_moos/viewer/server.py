"""The page's server: static files and one WebSocket (`/ws`) on the same loopback port.

A thin asyncio shell (the `websockets` package) around JSON messages. Outgoing: a `snapshot`
when a page connects (or the picture is rebuilt), then `batch`es of Scene updates at most
`refresh_hz` times per wall second, so a busy community cannot flood a browser. Incoming:
`{"cmd": ...}` objects, handed to the app; a page can only press the configured buttons.
"""
from __future__ import annotations

import asyncio
import json
import logging
from collections.abc import Awaitable, Callable
from http import HTTPStatus
from importlib import resources

import websockets
from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

log = logging.getLogger("oilspill_moos.viewer")

STATIC = {"/": ("index.html", "text/html; charset=utf-8"),
          "/index.html": ("index.html", "text/html; charset=utf-8"),
          "/viewer.js": ("viewer.js", "text/javascript; charset=utf-8"),
          "/viewer.css": ("viewer.css", "text/css; charset=utf-8")}
MAX_COMMAND = 4096   # bytes; commands are tiny JSON objects


def static_files() -> dict[str, tuple[bytes, str]]:
    folder = resources.files("oilspill_moos.viewer") / "static"
    return {path: (folder.joinpath(name).read_bytes(), kind) for path, (name, kind) in STATIC.items()}


class MapServer:
    """Pushes the picture to every open page and hands their commands to `on_command`."""

    def __init__(self, host: str, port: int, snapshot: Callable[[], dict],
                 on_command: Callable[[dict], Awaitable[None]]):
        self.host, self.port = host, port
        self.snapshot = snapshot
        self.on_command = on_command
        self.pages: set[ServerConnection] = set()
        self.pending: list[dict] = []
        self._files = static_files()
        self._server: Server | None = None

    @property
    def url(self) -> str:
        return f"http://{self.host}:{self.port}/"

    def own_page(self, origin: str, host: str) -> bool:
        """Browsers may open the WebSocket only from this server's own page (loaded by the name the
        WebSocket request uses, or by a loopback name): a page from anywhere else (another tab) must
        not press the buttons. Clients without an Origin are not browsers."""
        loopback = {f"http://{name}:{self.port}" for name in (self.host, "127.0.0.1", "localhost")}
        return origin in loopback or (bool(host) and origin in (f"http://{host}", f"https://{host}"))

    async def start(self) -> None:
        self._server = await serve(self._session, self.host, self.port, process_request=self._static,
                                   max_size=MAX_COMMAND, compression=None)
        self.port = self._server.sockets[0].getsockname()[1]

    def close(self) -> None:
        if self._server is not None:
            self._server.close()

    async def shut_down(self, clock: dict, timeout: float = 2.0) -> None:
        """Send what is queued (the page's last word, e.g. "mission ended"), then close every page."""
        self.flush(clock)
        if self._server is not None:
            self._server.close()
            try:
                async with asyncio.timeout(timeout):
                    await self._server.wait_closed()
            except TimeoutError:
                log.warning("pages did not close within %.0f s", timeout)

    def _static(self, connection: ServerConnection, request: Request) -> Response | None:
        path = request.path.split("?")[0]
        if path == "/ws":
            origin = request.headers.get("Origin")
            if origin is not None and not self.own_page(origin, request.headers.get("Host", "")):
                return connection.respond(HTTPStatus.FORBIDDEN, f"pages from {origin} may not steer this mission\n")
            return None
        found = self._files.get(path)
        if found is None:
            return connection.respond(HTTPStatus.NOT_FOUND, f"no {path} here; the map is at /\n")
        body, kind = found
        headers = Headers([("Content-Type", kind), ("Content-Length", str(len(body))), ("Cache-Control", "no-cache")])
        return Response(200, "OK", headers, body)

    async def _session(self, page: ServerConnection) -> None:
        self.pages.add(page)
        try:
            await page.send(json.dumps({"type": "snapshot", **self.snapshot()}))
            async for raw in page:
                await self._command(page, raw)
        except websockets.ConnectionClosed:
            pass
        finally:
            self.pages.discard(page)

    async def _command(self, page: ServerConnection, raw: str | bytes) -> None:
        try:
            command = json.loads(raw)
            if not isinstance(command, dict) or not isinstance(command.get("cmd"), str):
                raise ValueError("expected a JSON object with a 'cmd' string")
        except ValueError as exc:
            log.warning("page %s: bad command %r: %s", page.remote_address, raw[:80], exc)
            return
        try:
            await self.on_command(command)
        except Exception:   # a failing command must not close the page's connection
            log.exception("page %s: command %r failed", page.remote_address, command)

    def queue(self, updates: list[dict]) -> None:
        self.pending.extend(updates)

    def flush(self, clock: dict) -> None:
        """Send what has been queued (and the clock) to every page in one message."""
        updates, self.pending = self.pending, []
        if self.pages:
            websockets.broadcast(self.pages, json.dumps({"type": "batch", **clock, "updates": updates}))

    def resend_snapshot(self) -> None:
        self.pending = []
        if self.pages:
            websockets.broadcast(self.pages, json.dumps({"type": "snapshot", **self.snapshot()}))

    async def flush_every(self, period: float, clock: Callable[[], dict]) -> None:
        while True:
            self.flush(clock())
            await asyncio.sleep(period)
