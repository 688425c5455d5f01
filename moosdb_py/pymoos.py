"""pymoos's API on the pure-Python client: a pymoos script runs with `from moosdb_py import pymoos`.

The calls, arguments and defaults are those of pymoos (python-moos, docs/spec/pymoos-api.md);
`comms` is `moosdb_py.comms.comms` (a `MOOSClient` on a background event-loop thread) plus what
pymoos adds: message objects with accessors, active queues, counters, tuning and comms status.
`app` drives the `MOOSApp` life cycle with the script's callbacks. Strings travel as UTF-8, as
pybind11 sends them. See docs/pymoos.md for porting notes.
"""
from __future__ import annotations

import asyncio
import dataclasses
import logging
import numbers
import queue
import socket
import sys
import threading
import weakref
from collections.abc import Callable

from . import comms as _comms
from .app import DEFAULT_APP_TICK, DEFAULT_COMMS_TICK, MOOSApp
from .client import MOOSClient
from .comms import call_back, notify_arguments, register_arguments
from .message import BINARY, MOOSMsg, moos_time

log = logging.getLogger("moosdb_py.pymoos")

_warp = 1.0          # process-wide, as MOOS's global time warp
_skew = 0.0          # process-wide, as MOOS's global clock skew (set from a DB's welcome)
_clients: weakref.WeakSet[MOOSClient] = weakref.WeakSet()   # follow set_moos_timewarp

CLIENT_SUMMARIES = "_ClientSummaries"   # the active queue CMOOSCommClient uses for comms status


# -- module functions ------------------------------------------------------------------------
def local_time(apply_timewarping: bool = True) -> float:
    """The local clock (time-warped unless asked not to), without skew correction."""
    return moos_time(_warp if apply_timewarping else 1.0)


def time(apply_timewarping: bool = True) -> float:
    """MOOS time: the local clock corrected by the skew a DB's welcome reported."""
    return local_time(apply_timewarping) + _skew


def set_moos_timewarp(warp: float) -> bool:
    global _warp
    warp = float(warp)
    if not warp > 0:
        raise ValueError(f"set_moos_timewarp({warp:g}): the time warp must be positive")
    _warp = warp
    for client in list(_clients):
        client.time_warp = warp
    return True


def get_moos_timewarp() -> float:
    return _warp


def is_little_end_in() -> bool:
    return sys.byteorder == "little"


def _moos_value(name: str, value) -> float | str:
    """pymoos's notify overloads: str and bytes post a string (str as UTF-8), numbers a double."""
    if isinstance(value, str):
        return value.encode("utf-8", "surrogateescape").decode("latin-1")
    if isinstance(value, (bytes, bytearray, memoryview)):
        return bytes(value).decode("latin-1")
    if isinstance(value, numbers.Real):
        return float(value)
    raise TypeError(f"notify({name!r}): pymoos values are float, str or bytes, not {type(value).__name__}")


# -- messages ----------------------------------------------------------------------------------
class moos_msg:  # noqa: N801 - pymoos's names throughout
    """A received message with CMOOSMsg's accessors (`msg.double()`, `msg.string()`, ...)."""

    __slots__ = ("_msg",)

    def __init__(self, msg: MOOSMsg):
        self._msg = msg

    def name(self) -> str:
        return self._msg.key

    key = name

    def is_name(self, name: str) -> bool:
        return self._msg.key == name

    def time(self) -> float:
        return self._msg.time

    def source(self) -> str:
        return self._msg.source

    def source_aux(self) -> str:
        return self._msg.source_aux

    def community(self) -> str:
        return self._msg.community

    def is_double(self) -> bool:
        return self._msg.is_double()

    def double(self) -> float:
        return self._msg.double

    def double_aux(self) -> float:
        return self._msg.double_aux

    def is_string(self) -> bool:
        return self._msg.is_string()

    def string(self) -> str:
        """The payload read as UTF-8; bytes that are not UTF-8 survive as surrogate escapes."""
        return self._msg.sval_bytes.decode("utf-8", "surrogateescape")

    def is_binary(self) -> bool:
        return self._msg.is_binary()

    def binary_data(self) -> bytes:
        return self._msg.sval_bytes

    def binary_data_size(self) -> int:
        return len(self._msg.binary) if self._msg.is_binary() else 0

    def mark_as_binary(self) -> None:
        msg = self._msg
        if not msg.is_binary():     # changed on a copy: hosted in-process, other apps share the message
            self._msg = msg = msg.copy()
            msg.binary, msg.string, msg.data_type = msg.sval_bytes, "", BINARY

    def trace(self) -> None:
        print(self)

    def __str__(self) -> str:
        return str(self._msg)

    def __repr__(self) -> str:
        return f"moos_msg({self._msg!r})"


class moos_comms_status:  # noqa: N801
    """Another client's comms as the DB reports them (DB_QOS latencies in ms, DB_RWSUMMARY)."""

    Excellent, Good, Fair, Poor = range(4)     # ClientCommsStatus::Quality

    def __init__(self) -> None:
        self.name_ = ""
        self.recent_latency_ = -1.0
        self.max_latency_ = sys.float_info.min
        self.min_latency_ = sys.float_info.max
        self.avg_latency_ = sys.float_info.min
        self.subscribes_: list[str] = []
        self.publishes_: list[str] = []

    def appraise(self) -> int:
        """Excellent under 1 ms recent latency, Good under 10, Fair under 100, else Poor."""
        return next((q for q, limit in ((self.Excellent, 1), (self.Good, 10), (self.Fair, 100))
                     if self.recent_latency_ < limit), self.Poor)

    def copy_to(self, other: moos_comms_status) -> None:
        vars(other).update({k: list(v) if isinstance(v, list) else v for k, v in vars(self).items()})

    def print(self) -> None:
        print(f"\n--------  {self.name_}  --------\nLatencies:\n    recent {self.recent_latency_:g} ms\n"
              f"    max {self.max_latency_:g} ms\n    min {self.min_latency_:g} ms\n    avg {self.avg_latency_:g} ms\n"
              f"Subscribes:\n    {', '.join(self.subscribes_) or 'nothing'}\n"
              f"Publishes:\n    {', '.join(self.publishes_) or 'nothing'}\n")


moos_comms_status_list = list   # pymoos's bound vector type; a list does the same


# -- comms -------------------------------------------------------------------------------------
class _ActiveQueue:
    """One active queue: its messages go one by one to `func(msg)` on its own thread."""

    def __init__(self, owner: comms, name: str, func: Callable[[moos_msg], object]):
        self.owner, self.name, self.func = owner, name, func
        self.mail: queue.SimpleQueue[moos_msg | None] = queue.SimpleQueue()
        self.thread = threading.Thread(target=self._serve, name=f"ActiveQueue {name}", daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while (msg := self.mail.get()) is not None:
            call_back(f"{self.owner.where()} ActiveQueue {self.name}", self.func, msg)

    def stop(self) -> None:
        """Let it finish what it holds, then end its thread."""
        self.mail.put(None)
        if threading.current_thread() is not self.thread:
            self.thread.join(2.0)


class comms(_comms.comms):  # noqa: N801
    """pymoos's asynchronous client. Calls before `run` raise RuntimeError; after it, calls made
    while (re)connecting are kept: registrations are applied and notifications sent on connection."""

    def __init__(self) -> None:
        super().__init__()
        self._queues: dict[str, _ActiveQueue] = {}
        self._routes: dict[str, set[str]] = {}           # message name -> queue names
        self._queue_lock = threading.Lock()
        self._statuses: dict[str, moos_comms_status] = {}
        self._monitor_status = False
        self._time_correction: bool | None = None       # None: on when the DB runs on another host
        self._comms_tick = 0
        self._timewarp_scale_factor = 0.2

    def run(self, server: str, port: int, name: str) -> bool:
        """Start connecting in the background and return at once."""
        self.time_warp = _warp
        super().run(server, port, name)
        _clients.add(self._client)
        return True

    def close(self, nice: bool = True) -> bool:
        """Shut down: the active queues finish what they hold and go, then the connection."""
        with self._queue_lock:
            queues, self._queues, self._routes = list(self._queues.values()), {}, {}
        for active in queues:
            active.stop()
        return super().close(nice)

    def time(self) -> float:
        return time()

    def _connected(self) -> None:
        global _skew
        client = self._client
        correct = self._time_correction
        if correct is None:      # CMOOSCommClient: skew estimation is "not needed" on the DB's own host
            correct = client.db_hostname not in ("", socket.gethostname())
        if correct:
            _skew = client.db_skew
        super()._connected()
        if self._monitor_status:
            self._control_status_monitoring()

    def _mail(self, mail: list[MOOSMsg]) -> None:
        """Mail routed to active queues goes there only; the rest waits for `fetch`."""
        rest = []
        with self._queue_lock:
            for msg in mail:
                targets = [self._queues[q] for q in self._routes.get(msg.key, ()) if q in self._queues]
                for active in targets:
                    active.mail.put(moos_msg(dataclasses.replace(msg)))
                if not targets:
                    rest.append(msg)
        if rest:
            super()._mail(rest)

    def fetch(self) -> list[moos_msg]:
        return [moos_msg(m) for m in super().fetch()]

    def notify(self, name: str, value, *args, aux_src: str | None = None, time: float = -1.0) -> bool:
        """`notify(name, value, time=-1)` or `notify(name, value, aux_src, time=-1)`; -1 means now."""
        aux, stamp = notify_arguments(name, args, aux_src, time)
        return self._notify(name, _moos_value(name, value), aux, stamp)

    # -- active queues ------------------------------------------------------------------------
    def add_active_queue(self, queue_name: str, func: Callable[[moos_msg], object]) -> bool:
        with self._queue_lock:
            if queue_name in self._queues:
                log.warning("%s: active queue %r already exists", self.where(), queue_name)
                return False
            self._queues[queue_name] = _ActiveQueue(self, queue_name, func)
        return True

    def add_message_route_to_active_queue(self, queue_name: str, msg_name: str) -> bool:
        with self._queue_lock:
            if queue_name not in self._queues:
                log.warning("%s: no active queue %r to route %s to", self.where(), queue_name, msg_name)
                return False
            self._routes.setdefault(msg_name, set()).add(queue_name)
        return True

    def remove_message_route_to_active_queue(self, queue_name: str, msg_name: str) -> bool:
        with self._queue_lock:
            queues = self._routes.get(msg_name, set())
            if queue_name not in queues:
                return False
            queues.discard(queue_name)
        return True

    def remove_active_queue(self, queue_name: str) -> bool:
        with self._queue_lock:
            active = self._queues.pop(queue_name, None)
            for queues in self._routes.values():
                queues.discard(queue_name)
        if active is None:
            return False
        active.stop()
        return True

    def has_active_queue(self, queue_name: str) -> bool:
        return queue_name in self._queues

    def print_message_to_active_queue_routing(self) -> None:
        with self._queue_lock:
            routes = sorted((name, sorted(queues)) for name, queues in self._routes.items() if queues)
            idle = sorted(set(self._queues) - {q for _, queues in routes for q in queues})
        for name, queues in routes:
            print(f"  {name} -> {', '.join(queues)}")
        for queue_name in idle:
            print(f"  (nothing) -> {queue_name}")

    # -- state, counters, tuning --------------------------------------------------------------
    def is_running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def is_asynchronous(self) -> bool:
        return True

    def get_description(self) -> str:
        return f"{self._client.host}:{self._client.port}" if self._client else ""

    def get_number_of_unread_messages(self) -> int:
        with self._lock:
            return len(self._inbox)

    def get_number_of_unsent_messages(self) -> int:
        return self._client.unsent_messages if self._client else 0

    def get_number_bytes_sent(self) -> int:
        return self._client.bytes_sent if self._client else 0

    def get_number_bytes_read(self) -> int:
        return self._client.bytes_read if self._client else 0

    def get_number_messages_sent(self) -> int:
        return self._client.messages_sent if self._client else 0

    def get_number_message_read(self) -> int:
        return self._client.messages_read if self._client else 0

    def set_quiet(self, quiet: bool) -> None:
        """Connection warnings off (process-wide: they come from the `moosdb_py.client` logger)."""
        logging.getLogger("moosdb_py.client").setLevel(logging.ERROR if quiet else logging.NOTSET)

    def set_verbose_debug(self, verbose: bool) -> None:
        """Every connection event on (process-wide, like `set_quiet`)."""
        logging.getLogger("moosdb_py.client").setLevel(logging.DEBUG if verbose else logging.NOTSET)

    def set_comms_tick(self, comms_tick: int) -> bool:
        """Kept only: an asynchronous client sends when it has mail (pymoos ignores it too)."""
        self._comms_tick = int(comms_tick)
        return True

    def do_local_time_correction(self, correct: bool) -> None:
        """Whether `time()` takes the DB's skew at each connection (default: when the DB's host differs)."""
        self._time_correction = bool(correct)

    def set_comms_control_timewarp_scale_factor(self, scale_factor: float) -> None:
        """Kept only: this client does not delay its writes under time warp to bunch messages."""
        self._timewarp_scale_factor = float(scale_factor)

    def get_comms_control_timewarp_scale_factor(self) -> float:
        return self._timewarp_scale_factor

    # -- comms status across the community ---------------------------------------------------
    def enable_comms_status_monitoring(self, enable: bool) -> None:
        """Follow DB_QOS and DB_RWSUMMARY (on their own active queue) for `get_client_comms_status`."""
        self._monitor_status = bool(enable)
        if self._client is not None:
            self._control_status_monitoring()

    def _control_status_monitoring(self) -> None:
        if not self._monitor_status:
            self.remove_active_queue(CLIENT_SUMMARIES)
            return
        if not self.has_active_queue(CLIENT_SUMMARIES):
            self.add_active_queue(CLIENT_SUMMARIES, self._client_summary)
        for key in ("DB_QOS", "DB_RWSUMMARY"):
            self.add_message_route_to_active_queue(CLIENT_SUMMARIES, key)
            self.register(key, 0.0)

    def _client_summary(self, msg: moos_msg) -> None:
        """`DB_QOS` = `name=recent:max:min:avg,...`; `DB_RWSUMMARY` = `name=sub:sub&pub:pub,...`."""
        for entry in filter(None, msg.string().split(",")):
            client, _, fields = entry.partition("=")
            with self._queue_lock:
                status = self._statuses.setdefault(client, moos_comms_status())
                status.name_ = client
                if msg.name() == "DB_RWSUMMARY":
                    subscribes, _, publishes = fields.partition("&")
                    status.subscribes_ = [v for v in subscribes.split(":") if v]
                    status.publishes_ = [v for v in publishes.split(":") if v]
                    continue
                try:
                    (status.recent_latency_, status.max_latency_, status.min_latency_,
                     status.avg_latency_) = (float(v) for v in fields.split(":"))
                except ValueError:
                    log.warning("%s: DB_QOS from %s: bad entry %r", self.where(), msg.source(), entry)

    def get_client_comms_status(self, client: str, status: moos_comms_status) -> bool:
        with self._queue_lock:
            found = self._statuses.get(client)
            if found is not None:
                found.copy_to(status)
        return found is not None

    def get_client_comms_statuses(self, statuses: list) -> list:
        with self._queue_lock:
            for found in self._statuses.values():
                found.copy_to(copy := moos_comms_status())
                statuses.append(copy)
        return statuses


# -- app -----------------------------------------------------------------------------------------
class _StartUpFailed(Exception):
    """The script's OnStartUp callback returned false (or raised): CMOOSApp then quits."""


class _ScriptApp(MOOSApp):
    """The MOOSApp life cycle calling a pymoos `app`'s callbacks."""

    posts_iteration_load = False   # python-moos apps post no ITER_GAP / ITER_LEN

    def __init__(self, owner: app, mission_file: str, name: str, host: str, port: int):
        super().__init__(mission_file or None, name, host=host, port=port, time_warp=_warp)
        self.owner = owner
        self.inbox: list[MOOSMsg] = []
        self.inbox_lock = threading.Lock()
        _clients.add(self.client)

    def on_startup(self) -> None:
        if not self.owner._call_back("OnStartUp"):
            raise _StartUpFailed(f"{self.name}: OnStartUp returned false... quitting")

    def on_connect(self) -> None:
        self.owner._call_back("OnConnectToServer")

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        if self.owner._callbacks["OnNewMail"] is None:
            with self.inbox_lock:
                self.inbox.extend(mail)
        else:
            self.owner._call_back("OnNewMail", [moos_msg(m) for m in mail])

    def iterate(self) -> None:
        self.owner._call_back("Iterate")


class app:  # noqa: N801
    """pymoos's MOOS application: `run` blocks, calling the callbacks AppTick times a (warped) second.

    Without an on-new-mail callback, mail waits for `fetch()`. `request_quit()` ends `run`."""

    def __init__(self) -> None:
        self._callbacks: dict[str, Callable | None] = dict.fromkeys(
            ("OnStartUp", "OnConnectToServer", "Iterate", "OnNewMail"))
        self._app_freq: float | None = None
        self._comms_freq: float | None = None
        self._moos_app: _ScriptApp | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._loop_thread: int | None = None
        self._quit_requested = False

    # -- callbacks ----------------------------------------------------------------------------
    def set_on_start_up_callback(self, func: Callable[[], object]) -> bool:
        self._callbacks["OnStartUp"] = func
        return True

    def set_on_connect_to_server_callback(self, func: Callable[[], object]) -> bool:
        self._callbacks["OnConnectToServer"] = func
        return True

    def set_iterate_callback(self, func: Callable[[], object]) -> bool:
        self._callbacks["Iterate"] = func
        return True

    def set_on_new_mail_callback(self, func: Callable[[list[moos_msg]], object]) -> bool:
        self._callbacks["OnNewMail"] = func
        return True

    def _call_back(self, what: str, *args) -> object:
        func = self._callbacks[what]
        return True if func is None else call_back(f"{self.get_app_name()} {what}", func, *args)

    # -- life cycle -----------------------------------------------------------------------------
    def run(self, server: str, port: int, name: str, mission_file: str = "") -> bool:
        """Read the mission file (if any), start up, connect and run until `request_quit()`.

        Returns False when OnStartUp fails; a broken mission file raises MissionFileError."""
        moos_app = _ScriptApp(self, mission_file, name, server, int(port))
        mission = moos_app.mission
        if mission is not None and mission.get_global("MOOSTimeWarp") is not None:
            set_moos_timewarp(mission.time_warp)       # process-wide, as CMOOSApp does
            moos_app.time_warp = mission.time_warp
        if self._app_freq is not None and moos_app.config.entry("AppTick") is None:
            moos_app.app_tick = self._app_freq
        if self._comms_freq is not None and moos_app.config.entry("CommsTick") is None:
            moos_app.comms_tick = self._comms_freq
        self._moos_app = moos_app
        if self._quit_requested:
            moos_app.stop()
        try:
            asyncio.run(self._serve(moos_app))
        except _StartUpFailed as exc:
            log.error("%s", exc)
            return False
        finally:
            self._loop = self._loop_thread = None
            self._quit_requested = False
        return True

    async def _serve(self, moos_app: _ScriptApp) -> None:
        self._loop, self._loop_thread = asyncio.get_running_loop(), threading.get_ident()
        await moos_app.run_async()

    def request_quit(self) -> bool:
        """End `run` (CMOOSApp::RequestQuit); callable from any thread or callback."""
        self._quit_requested = True
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._moos_app.stop)
        return True

    def _in_loop(self, method: str, *args) -> bool:
        """`self._moos_app.<method>(*args)` in the app's thread (at once from a callback)."""
        if self._moos_app is None:
            raise RuntimeError(f"app is not running: call run() first ({method})")
        func = getattr(self._moos_app, method)
        if self._loop is None or self._loop_thread == threading.get_ident():
            func(*args)
        else:
            self._loop.call_soon_threadsafe(func, *args)
        return True

    # -- posting and mail -----------------------------------------------------------------------
    def register(self, *args, **kwargs) -> bool:
        """`register(name, interval=0)`, or the wildcard form `register(var_pattern, app_pattern, interval)`."""
        name, app_pattern, interval = register_arguments(args, kwargs)
        if app_pattern is None:
            return self._in_loop("register", name, interval)
        return self._in_loop("register_wildcard", name, app_pattern, interval)

    def notify(self, name: str, value, *args, aux_src: str | None = None, time: float = -1.0) -> bool:
        """`notify(name, value, time=-1)`; -1 means now."""
        aux, stamp = notify_arguments(name, args, aux_src, time)
        return self._post(name, _moos_value(name, value), aux, stamp)

    def notify_binary(self, name: str, binary_data: bytes, time: float = -1.0) -> bool:
        return self._post(name, bytes(binary_data), "", float(time))

    def _post(self, name: str, value: float | str | bytes, aux: str, stamp: float) -> bool:
        return self._in_loop("notify", name, value, time() if stamp == -1 else stamp, aux)

    def fetch(self) -> list[moos_msg]:
        """Mail received since the last fetch (collected only while no on-new-mail callback is set)."""
        if self._moos_app is None:
            return []
        with self._moos_app.inbox_lock:
            mail, self._moos_app.inbox = self._moos_app.inbox, []
        return [moos_msg(m) for m in mail]

    # -- state and frequencies ------------------------------------------------------------------
    def get_app_name(self) -> str:
        return self._moos_app.name if self._moos_app else ""

    def get_community_name(self) -> str:
        return self._moos_app.client.community if self.is_connected() else ""

    def is_connected(self) -> bool:
        return self._moos_app is not None and self._moos_app.client.connected

    def is_registered_for(self, name: str) -> bool:
        return self._moos_app is not None and name in self._moos_app.client.registrations

    def set_app_freq(self, freq: float) -> bool:
        """Iterations per (warped) second; the mission file's AppTick wins over a call before `run`."""
        self._app_freq = _positive("set_app_freq", freq)
        if self._moos_app is not None:
            self._moos_app.app_tick = self._app_freq
        return True

    def get_app_freq(self) -> float:
        return self._moos_app.app_tick if self._moos_app else self._app_freq or DEFAULT_APP_TICK

    def set_comms_freq(self, freq: float) -> bool:
        """Kept only: the asynchronous client sends when it has mail."""
        self._comms_freq = _positive("set_comms_freq", freq)
        if self._moos_app is not None:
            self._moos_app.comms_tick = self._comms_freq
        return True

    def get_comms_freq(self) -> float:
        return self._moos_app.comms_tick if self._moos_app else self._comms_freq or DEFAULT_COMMS_TICK


def _positive(what: str, value: float) -> float:
    value = float(value)
    if not value > 0:
        raise ValueError(f"{what}({value:g}): must be positive")
    return value
