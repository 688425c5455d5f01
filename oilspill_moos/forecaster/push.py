"""The forecaster -> pPathAssign boundary push (architecture doc, "The oil-spill protocol").

One UTF-8 line per boundary, JSON or a plain MOOS polygon string; pPathAssign answers each line
with ``OK <seq>`` or ``ERR <reason>``. The line itself is ``oilspill_moos.messages.boundary_line`` (pPathAssign reads it there too);
``parse_reply`` is pure;
``BoundaryPusher`` is a thin asyncio shell that reconnects when pPathAssign restarts and sends
the unanswered line again (a repeated boundary only re-plans the same loop, a lost one would
leave the fleet on a stale perimeter).
"""
from __future__ import annotations

import asyncio
from dataclasses import dataclass

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 9100


class PushRejected(RuntimeError):
    """pPathAssign answered ``ERR <reason>``."""


class PushUnreachable(ConnectionError):
    """No pPathAssign answered on host:port before the deadline."""


def parse_reply(line: bytes) -> int:
    """``OK <seq>`` -> seq; ``ERR <reason>`` -> PushRejected; anything else -> ValueError."""
    text = line.decode("utf-8", errors="replace").strip()
    word, _, rest = text.partition(" ")
    if word == "OK":
        try:
            return int(rest)
        except ValueError:
            raise ValueError(f"pPathAssign reply {text!r}: OK without a sequence number") from None
    if word == "ERR":
        raise PushRejected(rest or "no reason given")
    raise ValueError(f"unexpected pPathAssign reply {text!r}")


@dataclass
class BoundaryPusher:
    """Line client to pPathAssign; ``await push(line)`` returns its sequence number."""

    host: str = DEFAULT_HOST
    port: int = DEFAULT_PORT
    connect_timeout: float = 10.0     # how long to keep retrying a (re)connection
    reply_timeout: float = 10.0
    retry_interval: float = 0.2

    def __post_init__(self):
        self._reader: asyncio.StreamReader | None = None
        self._writer: asyncio.StreamWriter | None = None

    @property
    def connected(self) -> bool:
        return self._writer is not None and not self._writer.is_closing()

    async def connect(self) -> None:
        deadline = asyncio.get_running_loop().time() + self.connect_timeout
        while True:
            try:
                self._reader, self._writer = await asyncio.open_connection(self.host, self.port)
                return
            except OSError as exc:
                if asyncio.get_running_loop().time() >= deadline:
                    raise PushUnreachable(f"pPathAssign at {self.host}:{self.port}: {exc}") from exc
                await asyncio.sleep(self.retry_interval)

    async def push(self, line: bytes) -> int:
        if not line.endswith(b"\n") or b"\n" in line[:-1]:
            raise ValueError("a push is exactly one newline-terminated line")
        retried = False
        while True:
            if not self.connected:
                await self.connect()
            try:
                self._writer.write(line)
                await self._writer.drain()
                reply = await asyncio.wait_for(self._reader.readline(), self.reply_timeout)
                if not reply:
                    raise ConnectionResetError("pPathAssign closed the connection")
                return parse_reply(reply)
            except TimeoutError:
                await self.close()
                raise PushUnreachable(f"pPathAssign at {self.host}:{self.port}: no reply within "
                                      f"{self.reply_timeout} s") from None
            except ConnectionError as exc:
                await self.close()
                if retried:
                    raise PushUnreachable(f"pPathAssign at {self.host}:{self.port}: {exc}") from exc
                retried = True

    async def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            try:
                await self._writer.wait_closed()
            except OSError:
                pass
        self._reader = self._writer = None


def push_lines(lines: list[bytes], host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
               connect_timeout: float = 10.0) -> list[int]:
    """Blocking helper for the CLI: send lines in order on one connection, return their seqs."""

    async def run() -> list[int]:
        pusher = BoundaryPusher(host, port, connect_timeout=connect_timeout)
        try:
            return [await pusher.push(line) for line in lines]
        finally:
            await pusher.close()

    return asyncio.run(run())
