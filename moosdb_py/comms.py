"""A synchronous client for scripts, shaped like pymoos's `comms` (see docs/spec/pymoos-api.md).

The `MOOSClient` runs in a background thread with its own event loop; every call here is
thread-safe. Differences from pymoos: messages are `MOOSMsg` objects (attributes `key`, `double`,
`string`, `binary`, `time`, `source`, ... instead of accessor methods). `moosdb_py.pymoos` builds
the complete pymoos surface on this class.
"""
from __future__ import annotations

import asyncio
import inspect
import logging
import threading
import time as _time
from collections.abc import Callable

from .client import MOOSClient
from .message import MOOSMsg, moos_time

log = logging.getLogger("moosdb_py.comms")


def call_back(where: str, func: Callable, *args):
    """Run a user callback; what it raises is logged with its traceback and swallowed, so the
    thread that called it (comms, active queue, app loop) carries on. Returns None then."""
    try:
        return func(*args)
    except Exception:   # noqa: BLE001 - any error of user code is reported, none stops the client
        log.exception("%s: caught an exception thrown in python callback", where)
        return None


_ARG = inspect.Parameter.POSITIONAL_OR_KEYWORD
_PLAIN_REGISTER = inspect.Signature([inspect.Parameter("name", _ARG), inspect.Parameter("interval", _ARG, default=0.0)])
_WILDCARD_REGISTER = inspect.Signature([inspect.Parameter(n, _ARG) for n in ("var_pattern", "app_pattern", "interval")])


def register_arguments(args: tuple, kwargs: dict) -> tuple[str, str | None, float]:
    """pymoos's two `register` overloads -> (name or var pattern, app pattern or None, interval)."""
    try:
        bound = _PLAIN_REGISTER.bind(*args, **kwargs)
        if not isinstance(bound.arguments.get("interval", 0.0), str):
            bound.apply_defaults()
            return bound.arguments["name"], None, float(bound.arguments["interval"])
    except TypeError:
        pass
    try:
        bound = _WILDCARD_REGISTER.bind(*args, **kwargs)
    except TypeError:
        raise TypeError(f"register{args}: expected (name, interval=0) or (var_pattern, app_pattern, interval)") from None
    return bound.arguments["var_pattern"], bound.arguments["app_pattern"], float(bound.arguments["interval"])


def notify_arguments(name: str, args: tuple, aux_src: str | None, time: float) -> tuple[str, float]:
    """pymoos's `notify` tails `(time=-1)` and `(aux_src, time=-1)` -> (aux_src, time)."""
    if args and isinstance(args[0], str):
        if aux_src is not None:
            raise TypeError(f"notify({name!r}): aux_src given twice")
        aux_src, args = args[0], args[1:]
    if len(args) > 1:
        raise TypeError(f"notify({name!r}): too many arguments {args!r}")
    if args:
        time = args[0]
    return aux_src or "", float(time)


class comms:  # noqa: N801 - pymoos's name, so scripts only change their import
    """Connect in the background, register, notify, fetch mail; reconnects by itself."""

    def __init__(self) -> None:
        self._client: MOOSClient | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._inbox: list[MOOSMsg] = []
        self._registered: set[str] = set()     # kept here, in the caller's thread, so a query
        self._published: set[str] = set()      # right after `register`/`notify` sees it
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
            call_back(f"{self.where()} OnMail", self._on_mail)

    def _connected(self) -> None:
        if self._on_connect:
            call_back(f"{self.where()} OnConnect", self._on_connect)

    def where(self) -> str:
        """This client in log lines: its MOOS name once `run` gave it one."""
        return self.get_moos_name() or "comms (not running)"

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
        self._call("close")
        if threading.current_thread() is not self._thread:     # a callback may close its own comms
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

    def _call(self, method: str, *args) -> bool:
        """`self._client.<method>(*args)`, run in the comms thread."""
        if self._loop is None or self._loop.is_closed():
            raise RuntimeError(f"comms is not running: call run() before {method}")
        self._loop.call_soon_threadsafe(getattr(self._client, method), *args)
        return True

    # -- posting ----------------------------------------------------------------------------
    def register(self, *args, **kwargs) -> bool:
        """`register(name, interval=0)` or `register(var_pattern, app_pattern, interval)`."""
        name, app_pattern, interval = register_arguments(args, kwargs)
        if app_pattern is not None:
            return self._call("register_wildcard", name, app_pattern, interval)
        self._call("register", name, interval)
        self._registered.add(name)
        return True

    def unregister(self, name: str) -> bool:
        self._call("unregister", name)
        self._registered.discard(name)
        return True

    def notify(self, name: str, value: float | str | bytes, *args, aux_src: str | None = None,
               time: float = -1.0) -> bool:
        """`notify(name, value, time=-1)` or `notify(name, value, aux_src, time=-1)`; -1 means now."""
        aux, stamp = notify_arguments(name, args, aux_src, time)
        return self._notify(name, value, aux, stamp)

    def notify_binary(self, name: str, binary_data: bytes, time: float = -1) -> bool:
        return self._notify(name, bytes(binary_data), "", float(time))

    def _notify(self, name: str, value: float | str | bytes, aux: str, stamp: float) -> bool:
        """Build the message here, so a bad value raises TypeError in the caller's thread."""
        msg = MOOSMsg.notification(name, value, time=self.time() if stamp == -1 else stamp, source_aux=aux)
        self._call("post", msg)
        self._published.add(name)
        return True

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
        return sorted(self._registered)

    def get_published(self) -> list[str]:
        return sorted(self._published)

    def is_registered_for(self, name: str) -> bool:
        return name in self._registered
