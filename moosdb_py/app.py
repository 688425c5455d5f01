"""MOOSApp: the life cycle every MOOS application shares (CMOOSApp in C++).

Reads its `ProcessConfig` block from the mission file, connects with a `MOOSClient`, calls
`on_new_mail` and `iterate` AppTick times per *warped* second, publishes `<NAME>_STATUS` every
two seconds and listens to `<NAME>_CMD`. `main` gives every app the MOOS command line.
"""
from __future__ import annotations

import asyncio
import heapq
import inspect
import logging
import os
import random
import re
import resource
import signal
import sys
import time as _time
import weakref
from pathlib import Path

from .client import MOOSClient, resolve
from .config import Params, read_params
from .formats import print_page, version_page
from .message import MOOSMsg, moos_time
from .mission import Mission, ProcessConfig, Where, db_address, read_mission
from .source import MissionFileError

log = logging.getLogger("moosdb_py.app")

DEFAULT_APP_TICK = 5.0
DEFAULT_COMMS_TICK = 5.0
STATUS_PERIOD = 2.0
TICK_SLACK = 0.25   # share of its AppTick period by which an iteration may run early or late (apps sharing
                    # an event loop then wake together: each wake-up of a loaded machine costs ~0.1 ms of CPU)
TICK_PHASE = random.random()   # ticks fall on multiples of the period from this instant (monotonic s): the same
                               # for every app of a process, so they wake together; another process's vessels
                               # wake at other instants, not all at once when processes outnumber the cores
RETRY_NOTICE_PERIOD = 10.0   # seconds between "connecting ... retrying" lines while no DB answers
BEHIND_SHARE = 0.02   # an app that missed more than this share of the AppTicks due fell behind its AppTick
_STATUS_TICKS = re.compile(r"MOOSName=([^,]*),Iterations=(\d+),TicksMissed=(\d+)")
USAGE_OPTIONS = """\
Options:
  --moos_file=FILE                 mission file (instead of the first positional argument)
  --alias=NAME, --moos_name=NAME   MOOS name (and ProcessConfig block) to use
  --moos_host=HOST                 DB host (default: ServerHost, else 127.0.0.1)
  --moos_port=PORT                 DB port (default: ServerPort, else 9000)
  --moos_time_warp=WARP            time warp (default: MOOSTimeWarp, else 1)
  --verbose                        log connections and warnings
  --help, --example, --interface   this text / a ProcessConfig block / variables used (also -h, -e, -i)
  --version                        the app's name and release"""


class MOOSApp:
    """A MOOS application (subclasses replace this docstring: it is their --help text)."""

    default_name = "pMyApp"
    example_config = ""
    interface = ""
    parameters: Params | None = None   # the app's ProcessConfig parameters; None: the app reads its block itself
    # Posts <NAME>_ITER_GAP and <NAME>_ITER_LEN every iteration, as MOOS-IvP's AppCastingMOOSApp does (what
    # uLoadWatch reads); core-MOOS apps (pLogger, pShare) and pymoos scripts do not.
    posts_iteration_load = True

    def __init__(self, mission_file: str | Path | None = None, name: str | None = None, *,
                 host: str | None = None, port: int | None = None, time_warp: float | None = None):
        self.name = name or self.default_name
        self.mission: Mission | None = read_mission(mission_file) if mission_file else None
        self.config: ProcessConfig = self._find_config()
        if self.parameters is not None:
            self.parameters.warn_unhandled(self.config)
        host, port, self.time_warp = db_address(self.mission, host, port, time_warp)
        self.app_tick = self._positive("AppTick", DEFAULT_APP_TICK)
        self.comms_tick = self._positive("CommsTick", DEFAULT_COMMS_TICK)   # read as MOOS does; async comms ignore it
        self.command_key = f"{self.name.upper()}_CMD"
        self._iter_gap_key, self._iter_len_key = f"{self.name.upper()}_ITER_GAP", f"{self.name.upper()}_ITER_LEN"
        self._last_iterate: float | None = None   # MOOS time of the previous iteration
        self.client = MOOSClient(self.name, "127.0.0.1" if host == "localhost" else host, port,
                                 on_mail=self._on_mail, on_connect=self._on_connect, time_warp=self.time_warp)
        self.client.shared_mail = True   # hosted in-process, its mail is shared with the other apps: read, not changed
        self.start_time = self.moos_time()
        self.iterations = 0
        self.ticks_missed = 0   # AppTick periods that passed with no iteration: the app fell behind its AppTick
        self.app_error = False
        self._started_mono = _time.monotonic()
        self._mail: list[MOOSMsg] = []
        self._stop: asyncio.Event | None = None
        self._ticking: asyncio.Future | None = None   # resolved by stop(), or failed by a tick that raised
        self._next_tick = self._next_status = 0.0   # loop times of the next AppTick and status post
        self._tick_slack = 0.0
        self._ticker: AppTicker | None = None
        self._comms: asyncio.Task | None = None
        self._stopping = False

    def _find_config(self) -> ProcessConfig:
        """The block named by the alias, else by the app's own name (MOOS-IvP's `~` aliases)."""
        found = None
        if self.mission is not None:
            found = self.mission.process_config(self.name) or self.mission.process_config(self.default_name)
        where = Where(file=self.mission.path if self.mission else Path("<no mission file>"), line=0)
        return found or ProcessConfig(name=self.name, entries=[], source=where)

    def _positive(self, key: str, default: float) -> float:
        entry = self.config.entry(key)
        if entry is None:
            return default
        try:
            value = float(entry.moos_value)
        except ValueError:
            value = -1.0
        if value <= 0:
            raise entry.source.error(f"{key} = {entry.value!r} is not a positive number")
        return value

    def read_settings(self) -> dict:
        """Every declared parameter's typed value (or default); a bad value raises naming its file:line."""
        return read_params(self.config, self.parameters.read)

    # -- hooks for subclasses ------------------------------------------------------------------
    def on_startup(self) -> None:
        """Read the configuration; raise ValueError naming the bad parameter."""

    def on_connect(self) -> None:
        """Register for mail; called on every (re)connection."""

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        """Mail received since the last tick, in arrival order (`<NAME>_CMD` included)."""

    def iterate(self) -> None:
        """The app's work, AppTick times per warped second."""

    def status_fields(self) -> dict:
        """Extra `key=value` fields appended to <NAME>_STATUS."""
        return {}

    # -- services ------------------------------------------------------------------------------
    def register(self, key: str, interval: float = 0.0) -> None:
        self.client.register(key, interval)

    def register_wildcard(self, var_pattern: str, app_pattern: str = "*", interval: float = 0.0) -> None:
        self.client.register_wildcard(var_pattern, app_pattern, interval)

    def notify(self, key: str, value: float | str | bytes, time: float | None = None, source_aux: str = "") -> None:
        self.client.notify(key, value, time, source_aux)

    def moos_time(self) -> float:
        return self.client.moos_time()

    # -- life cycle ----------------------------------------------------------------------------
    def _on_connect(self) -> None:
        self.client.register(self.command_key)
        self.on_connect()

    def _on_mail(self, mail: list[MOOSMsg]) -> None:
        self._mail.extend(mail)

    def status(self) -> str:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        uptime = self.moos_time() - self.start_time
        cpu = 100.0 * (usage.ru_utime + usage.ru_stime) / max(_time.monotonic() - self._started_mono, 1e-9)
        fields = [f"AppErrorFlag={'true' if self.app_error else 'false'}", f"Uptime={uptime:g}",
                  f"cpuload={cpu:.4g}", f"memory_kb={_memory_kb()}", f"memory_max_kb={usage.ru_maxrss:g}",
                  f"MOOSName={self.name}", f"Iterations={self.iterations}", f"TicksMissed={self.ticks_missed}",
                  'Publishing="' + "".join(f"{k}," for k in sorted(self.client.published)) + '"',
                  'Subscribing="' + "".join(f"{k}," for k in sorted(self.client.registrations)) + '"']
        fields += [f"{k}={v}" for k, v in self.status_fields().items()]
        return ",".join(fields)

    async def run_async(self) -> None:
        """Run until `stop()`; several apps can share one event loop (and its `AppTicker`)."""
        self._stop = asyncio.Event()
        if self._stopping:
            self._stop.set()
        self._started_mono = _time.monotonic()
        self.on_startup()
        comms = asyncio.create_task(self.client.run(), name=f"{self.name} comms")
        try:
            next_notice = 0.0
            while not self._stop.is_set() and not await self.client.wait_connected(0.5):
                if comms.done():
                    raise ConnectionError(f"{self.name}: {self.client.poisoned or 'cannot connect'}")
                if _time.monotonic() >= next_notice:   # say so, as MOOS apps do, rather than wait silently
                    next_notice = _time.monotonic() + RETRY_NOTICE_PERIOD
                    print(f"{self.name}: connecting to {self.client.host}:{self.client.port} ... retrying",
                          file=sys.stderr, flush=True)
            loop = asyncio.get_running_loop()
            self._ticking = loop.create_future()
            now = _time.monotonic()
            self._next_status = now
            period = self._tick_period()
            self._next_tick = (now - TICK_PHASE) // period * period + TICK_PHASE
            self._comms = comms
            if not self._stop.is_set():
                self._tick(now)
                if not self._ticking.done():
                    self._ticker = AppTicker.of(loop)
                    self._ticker.add(self)
                await self._ticking
            mail, self._mail = self._mail, []
            if mail:   # mail that arrived with the stop request is still handled (pLogger writes it)
                self.on_new_mail(mail)
        finally:
            if self._ticker is not None:
                self._ticker.remove(self)
                self._ticker = None
            self.client.close()
            try:
                async with asyncio.timeout(2.0):
                    await comms
            except TimeoutError:
                comms.cancel()

    def _tick_period(self) -> float:
        return 1.0 / (self.app_tick * self.time_warp)

    def _tick(self, now: float) -> None:
        """One AppTick at monotonic time `now` (mail, iterate, status), run by the `AppTicker`; what it raises
        ends `run_async` with it.

        Ticks are due on multiples of the period (from TICK_PHASE on the monotonic clock). When late, the latest
        tick due runs at once and the whole periods before it count as missed."""
        self.client.hold_posts()       # the tick's posts go as one batch when it ends (in-process: when the wake-up ends)
        try:
            if self._comms.done():   # a mail callback raised, or the DB refused us on reconnecting: not deaf
                self._comms.result()
                raise ConnectionError(f"{self.name}: {self.client.poisoned or 'comms ended'}")
            mail, self._mail = self._mail, []
            if mail:
                self.on_new_mail(mail)
            if self.posts_iteration_load:
                self._iterate_with_load()
            else:
                self.iterate()
            self.iterations += 1
            if now >= self._next_status:
                self._next_status = now + STATUS_PERIOD
                self.notify(f"{self.name.upper()}_STATUS", self.status())
            period = self._tick_period()   # AppTick may change
            self._tick_slack = TICK_SLACK * period
            self._next_tick += period
            now = _time.monotonic()
            if now >= self._next_tick:   # late: the latest tick due runs at once, whole periods before it missed
                late = int((now - self._next_tick) / period)
                self.ticks_missed += late
                self._next_tick += late * period
        except Exception as exc:
            if not self._ticking.done():
                self._ticking.set_exception(exc)
        finally:
            self.client.send_held()

    def _iterate_with_load(self) -> None:
        """`iterate`, with its gap since the last one and its length, both over the AppTick period (1.0:
        a whole period) in MOOS time, posted as <NAME>_ITER_GAP (from the second iteration) and _ITER_LEN."""
        client, warp = self.client, self.time_warp
        start = moos_time(warp)
        if self._last_iterate is not None:
            client.notify(self._iter_gap_key, (start - self._last_iterate) * self.app_tick, start)
        self._last_iterate = start
        self.iterate()
        now = moos_time(warp)
        client.notify(self._iter_len_key, (now - start) * self.app_tick, now)

    def stop(self) -> None:
        self._stopping = True
        if self._stop is not None:
            self._stop.set()
        if self._ticker is not None:
            self._ticker.remove(self)
        if self._ticking is not None:
            resolve(self._ticking)

    def run(self) -> None:
        async def runner():
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, self.stop)
            await self.run_async()
        asyncio.run(runner())

    # -- command line --------------------------------------------------------------------------
    @classmethod
    def usage(cls) -> str:
        doc = inspect.cleandoc(cls.__doc__ or "")
        return f"Usage: {cls.default_name} [mission.moos] [alias] [options]\n\n{doc}\n\n{USAGE_OPTIONS}\n"

    @classmethod
    def main(cls, argv: list[str] | None = None, **settings) -> int:
        """`APP [mission.moos] [alias] [--alias=N] [--moos_host=H] [--moos_port=P] [--help|--example|--interface]`

        `settings` become attributes of the app before it runs: how a subclass's `main` hands on
        the command-line options of its own that it took out of `argv`."""
        argv = sys.argv[1:] if argv is None else list(argv)
        pages = {"--help": cls.usage, "-h": cls.usage, "--example": lambda: cls.example_config,
                 "-e": lambda: cls.example_config, "--interface": lambda: cls.interface, "-i": lambda: cls.interface}
        for arg in argv:
            if arg == "--version":
                print_page(version_page(cls.default_name))
                return 0
            if arg in pages:
                text = pages[arg]()
                print_page((text if arg in ("--help", "-h") else inspect.cleandoc(text)) + "\n")
                return 0
        options, positional = {}, []
        for arg in argv:
            if arg.startswith("-"):
                key, _, value = arg.lstrip("-").partition("=")
                options[key] = value
            else:
                positional.append(arg)
        name = options.pop("alias", None) or options.pop("moos_name", None) or (positional[1] if len(positional) > 1 else None)
        mission = options.pop("moos_file", None) or (positional[0] if positional else None)
        logging.basicConfig(level=logging.INFO if "verbose" in options else logging.WARNING,
                            format=f"%(asctime)s {name or cls.default_name}: %(message)s", stream=sys.stderr)
        options.pop("verbose", None)
        try:
            unknown = sorted(set(options) - {"moos_host", "moos_port", "moos_time_warp"})
            if unknown or len(positional) > 2:
                raise ValueError(f"unknown arguments {unknown or positional[2:]} (see --help)")
            app = cls(mission, name, host=options.get("moos_host") or None,
                      port=int(options["moos_port"]) if options.get("moos_port") else None,
                      time_warp=float(options["moos_time_warp"]) if options.get("moos_time_warp") else None)
            for key, value in settings.items():
                setattr(app, key, value)
            app.run()
        except (MissionFileError, ValueError, OSError, ConnectionError) as exc:
            print(f"{name or cls.default_name}: {exc}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            pass
        return 0


class AppTicker:
    """The AppTicks of every MOOSApp in one event loop, run from one timer (pAntler --one-process hosts
    several apps): a wake-up runs every app whose tick is due within its slack (TICK_SLACK of its
    period, early or late), so that apps whose periods do not meet still share wake-ups. Each app's
    ticks stay on the multiples of its period: its rate is exact, only the phase of an iteration
    moves, by less than a quarter period.

    A pass runs its apps by deadline, earliest first: two periods after the tick, when a tick not yet run
    counts as missed (MOOSApp._tick), so the fastest kinds (a PID at 10 Hz) run first and a saturated
    pass leaves the ticks with the longest to go. The apps of one kind tick in step, so they share a
    deadline and run together, kinds of one deadline in the order they were added (vessels hosted
    together: every vessel's helm while its code is in the caches; a vessel's simulator before its
    helm), apps of one kind in the order they were added; but of apps with one deadline, one that has
    missed more ticks runs first. A pass held up (a machine whose other jobs take the processor) makes
    its last apps late: in launch order those were always the kinds launched last among their
    deadline's (a demo run of the seventh session: pContactMgrV20, last of the vessels' 4 Hz kinds,
    uFldNodeBroker and pNodeReporter, last of the 2 Hz ones, just over 2 % of their ticks missed); the
    app that missed most going first spreads such misses over the kinds that share the deadline. While
    no app misses a tick, the launch order stands. A pass posts nothing until it ends (the
    wake-up's posts are routed together), so the order within it changes no app's mail. While the
    pass lasts, an app whose next tick falls due (without slack) joins it by its deadline, even one
    that already ran (many vessels' helms take longer than a PID's period: the PIDs run between them
    instead of missing ticks), up to PASS_TICKS ticks per app so that a saturated process still
    returns to its loop. An app a saturated pass left behind keeps its early deadline, so the next
    wake-up runs it before the apps due since: the kind launched last does not wait behind the
    others' ticks in every pass.

    Waiting apps are kept in cohorts, one per (due, slack) pair: the apps of a kind tick in step, so
    fifteen vessels' 75 apps make about nine cohorts, and a wake-up looks at those and at the apps it
    runs, never at every app (a scan of every app was 7 % of such a process)."""

    PASS_TICKS = 2

    _of_loop: "weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, AppTicker]" = weakref.WeakKeyDictionary()

    def __init__(self, loop: asyncio.AbstractEventLoop):
        self.loop = loop
        self.apps: dict[MOOSApp, tuple[int, int]] = {}   # app -> (its kind's rank, its own): the order of a pass
        self._kinds: dict[type, int] = {}
        self._added = 0
        self._cohorts: dict[tuple[float, float], dict[MOOSApp, None]] = {}   # (due, slack) -> the apps waiting
        self._cohort_of: dict[MOOSApp, tuple[float, float]] = {}             # a waiting app's cohort
        self._timer: asyncio.TimerHandle | None = None
        self._wake = 0.0            # when the timer is due (the loop may call it a little early)
        self._running = False

    @classmethod
    def of(cls, loop: asyncio.AbstractEventLoop) -> "AppTicker":
        ticker = cls._of_loop.get(loop)
        if ticker is None:
            ticker = cls._of_loop[loop] = cls(loop)
        return ticker

    def add(self, app: MOOSApp) -> None:
        self._added += 1
        self.apps[app] = (self._kinds.setdefault(type(app), len(self._kinds)), self._added)
        self._wait(app)
        self._schedule()

    def remove(self, app: MOOSApp) -> None:
        if self.apps.pop(app, None) is not None:
            self._unwait(app)
            self._schedule()

    def _wait(self, app: MOOSApp) -> None:
        """Into the cohort of its next tick."""
        key = self._cohort_of[app] = (app._next_tick, app._tick_slack)
        cohort = self._cohorts.get(key)
        if cohort is None:
            self._cohorts[key] = {app: None}
        else:
            cohort[app] = None

    def _unwait(self, app: MOOSApp) -> None:
        key = self._cohort_of.pop(app, None)
        if key is not None:
            cohort = self._cohorts[key]
            del cohort[app]
            if not cohort:
                del self._cohorts[key]

    def _schedule(self) -> None:
        """The timer for the next wake-up."""
        if self._running:
            return
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._cohorts:
            self._wake = next_wake(list(self._cohorts))
            self._timer = self.loop.call_at(self._wake, self._run)    # asyncio's clock is time.monotonic

    def _run(self) -> None:
        self._timer = None
        self._running = True
        apps, cohorts, cohort_of = self.apps, self._cohorts, self._cohort_of
        due = []      # heap: to run in this pass
        try:
            now = max(_time.monotonic(), self._wake)
            for key in [key for key in cohorts if key[0] - key[1] <= now]:
                deadline = key[0] + 2 * key[1] / TICK_SLACK    # two periods after the tick: then it counts missed
                for app in cohorts.pop(key):
                    del cohort_of[app]
                    due.append((deadline, -app.ticks_missed, *apps[app], app))
            heapq.heapify(due)
            budget = self.PASS_TICKS * len(apps)
            while due and budget:
                app = due[0][-1]
                if app not in apps:    # stopped by an app ticked before it
                    heapq.heappop(due)
                    continue
                app._tick(now)
                heapq.heappop(due)     # after the tick: should the tick raise past `_tick`, the app is waited for below
                budget -= 1
                if app._ticking.done():    # failed
                    del apps[app]
                    continue
                self._wait(app)
                now = _time.monotonic()
                if min(cohorts)[0] <= now:    # fell due while the pass ran: into it, by deadline
                    for key in [key for key in cohorts if key[0] <= now]:
                        deadline = key[0] + 2 * key[1] / TICK_SLACK
                        for waiting in cohorts.pop(key):
                            del cohort_of[waiting]
                            heapq.heappush(due, (deadline, -waiting.ticks_missed, *apps[waiting], waiting))
        finally:
            for entry in due:     # not run: the budget ran out (or a tick raised)
                if entry[-1] in apps:
                    self._wait(entry[-1])
            self._running = False
            self._schedule()


def status_ticks(status: str) -> tuple[str, int, int] | None:
    """(MOOSName, Iterations, TicksMissed) of a <NAME>_STATUS value (`MOOSApp.status`); None without them."""
    match = _STATUS_TICKS.search(status)
    return (match.group(1), int(match.group(2)), int(match.group(3))) if match else None


def fell_behind(before: dict, after: dict) -> list[tuple]:
    """(app, AppTicks missed, AppTicks due) of each app of `after` that missed more than BEHIND_SHARE of
    the AppTicks due since `before`, both mapping an app to its (Iterations, TicksMissed) (`status_ticks`;
    an app not in `before` counts from zero), in the apps' order."""
    late = []
    for app, (iterations, missed_now) in sorted(after.items()):
        iterations_then, missed_then = before.get(app, (0, 0))
        missed = missed_now - missed_then
        due = iterations - iterations_then + missed
        if missed > BEHIND_SHARE * due:
            late.append((app, missed, due))
    return late


def next_wake(ticks: list[tuple[float, float]]) -> float:
    """When to wake for AppTicks each due at `due` give or take `slack` (pairs): as late as every tick
    of the batch that wake-up runs allows (no tick later than its slack), as early as they are due and
    their slack allows (on time when one tick alone is due)."""
    close = min(due + slack for due, slack in ticks)
    batch = [(due, slack) for due, slack in ticks if due - slack <= close]
    return max(min(due for due, _ in batch), max(due - slack for due, slack in batch))


def _memory_kb() -> int:
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") // 1024
    except (OSError, ValueError, IndexError):
        return 0
