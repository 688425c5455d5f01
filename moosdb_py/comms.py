"""A synchronous client for scripts, shaped like pymoos's `comms` (see ../shared/spec/pymoos-api.md).

The `MOOSClient` runs in a background thread with its own event loop; every call here is
thread-safe. Differences from pymoos: messages are `MOOSMsg` objects (attributes `key`, `double`,
`string`, `binary`, `time`, `source`, ... instead of accessor methods).
"""
from __future__ import annotations

import asyncio
import threading
import time as _time
from collections.abc import Callable

from .client import MOOSClient
from .message import MOOSMsg, moos_time


class comms:  # noqa: N801 - pymoos's name, so scripts only change their import
    """Connect in the background, register, notify, fetch mail; reconnects by itself."""

    def __init__(self) -> None:
        self._client: MOOSClient | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._inbox: list[MOOSMsg] = []
        self._on_connect: Callable[[], object] | None = None
        self._on_mail: Callable[[], object] | None = None
        self.time_warp = 1.0

    # -- callbacks (run on the comms thread, as in pymoos) ----------------------------------
    def set_on_connect_callback(self, func: Callable[[], object]) -> bool:
        self._on_connect = func
        return True

    def set_on_mail_callback(self, func: Callable[[], object]) -> bool:
        self._on_mail = func
        return True

    def _mail(self, mail: list[MOOSMsg]) -> None:
        with self._lock:
            self._inbox.extend(mail)
        if self._on_mail:
            self._on_mail()

    def _connected(self) -> None:
        if self._on_connect:
            self._on_connect()

    # -- connection -------------------------------------------------------------------------
    def run(self, server: str, port: int, name: str) -> bool:
        """Start connecting in the background and return at once."""
        if self._thread is not None:
            raise RuntimeError(f"{name}: comms already running")
        self._client = MOOSClient(name, "127.0.0.1" if server == "localhost" else server, int(port),
                                  on_mail=self._mail, on_connect=self._connected, time_warp=self.time_warp)
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_until_complete, args=(self._client.run(),),
                                        name=f"moos comms {name}", daemon=True)
        self._thread.start()
        return True

    def close(self, nice: bool = True) -> bool:
        """Send what is queued (if `nice`) and disconnect."""
        if self._thread is None:
            return True
        self._call(self._client.close)
        self._thread.join(5.0 if nice else 0.5)
        self._thread = None
        return True

    def is_connected(self) -> bool:
        return self._client is not None and self._client.connected

    def wait_until_connected(self, n_ms: int) -> bool:
        deadline = _time.monotonic() + n_ms / 1000.0
        while not self.is_connected() and _time.monotonic() < deadline:
            _time.sleep(0.01)
        return self.is_connected()

    def _call(self, func, *args) -> bool:
        if self._loop is None or self._loop.is_closed():
            raise RuntimeError("comms is not running: call run() first")
        self._loop.call_soon_threadsafe(func, *args)
        return True

    # -- posting ----------------------------------------------------------------------------
    def register(self, name: str, *args) -> bool:
        """`register(name, interval=0)` or `register(var_pattern, app_pattern, interval)`."""
        if len(args) == 2:
            return self._call(self._client.register_wildcard, name, args[0], float(args[1]))
        return self._call(self._client.register, name, float(args[0]) if args else 0.0)

    def unregister(self, name: str) -> bool:
        return self._call(self._client.unregister, name)

    def notify(self, name: str, value: float | str | bytes, *args) -> bool:
        """`notify(name, value, time=-1)` or `notify(name, value, aux_src, time=-1)`; -1 means now."""
        aux, stamp = "", -1.0
        if args and isinstance(args[0], str):
            aux, args = args[0], args[1:]
        if args:
            stamp = float(args[0])
        return self._call(self._client.notify, name, value, None if stamp == -1 else stamp, aux)

    def notify_binary(self, name: str, binary_data: bytes, time: float = -1) -> bool:
        return self.notify(name, bytes(binary_data), time)

    def fetch(self) -> list[MOOSMsg]:
        with self._lock:
            mail, self._inbox = self._inbox, []
        return mail

    # -- state ------------------------------------------------------------------------------
    def time(self) -> float:
        return moos_time(self.time_warp)

    def get_moos_name(self) -> str:
        return self._client.name if self._client else ""

    def get_community_name(self) -> str:
        return self._client.community if self._client else ""

    def get_registered(self) -> list[str]:
        return sorted(self._client.registrations) if self._client else []

    def get_published(self) -> list[str]:
        return sorted(self._client.published) if self._client else []

    def is_registered_for(self, name: str) -> bool:
        return self._client is not None and name in self._client.registrations
