"""uMemWatch: the memory of the community's apps, one app per measurement, posted as <APP>_MEM.

An app makes itself measurable by posting its process id as `<APP>_PID` (pHelmIvP posts PHELMIVP_PID).
uMemWatch learns the clients from the MOOSDB's DB_CLIENTS, registers for each one's `_PID`, and every
`absolute_time_gap` real seconds measures the next app in turn: its resident memory in MB (as MOOS-IvP's
uMemWatch, 1 MB = 1000 kB), read from /proc. Apps sharing one process (pAntler --one-process) share
its figure.

`MemWatchState` is pure: clients, PIDs and measured sizes in, registrations and posts out.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

from .app import MOOSApp
from .config import Param, Params
from .message import MOOSMsg

log = logging.getLogger(__name__)

PID_SUFFIX = "_PID"
DEFAULT_TIME_GAP = 5.0     # real seconds between measurements (MOOS-IvP's default)
MIN_TIME_GAP = 1.0

Post = tuple[str, str | float]


def resident_kb(pid: int, proc: Path = Path("/proc")) -> float | None:
    """The process's resident set size in kB (VmRSS), or None when it is gone or /proc has none."""
    try:
        for line in (proc / str(pid) / "status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return float(line.split()[1])
    except (OSError, ValueError, IndexError):
        return None
    return None


def app_list(values: list[str], what: str) -> list[str]:
    """Every `watch_only` / `ignore` line split at commas; a blank name or one with spaces is an error."""
    names = []
    for value in values:
        for name in (n.strip() for n in value.split(",")):
            if not name or any(c.isspace() for c in name):
                raise ValueError(f"{what} = {value!r}: app names are comma-separated, without spaces")
            if name not in names:
                names.append(name)
    return names


@dataclass
class Measured:
    """One app with a known PID: its last size and the change since the measurement before."""

    app: str
    pid: int
    mem_mb: float = 0.0
    delta_mb: float = 0.0


@dataclass
class MemWatchState:
    watch_only: list[str] = field(default_factory=list)
    ignore: list[str] = field(default_factory=list)
    clients: list[str] = field(default_factory=list)      # every client the DB has named, in proper case
    measured: list[Measured] = field(default_factory=list)
    last_index: int = -1

    def on_clients(self, text: str) -> list[str]:
        """DB_CLIENTS -> the `<CLIENT>_PID` variables to register for (new clients only)."""
        new = [c for c in (c.strip() for c in text.split(",")) if c and c not in self.clients]
        self.clients += new
        return [f"{c.upper()}{PID_SUFFIX}" for c in new]

    def on_pid(self, key: str, pid: float) -> None:
        """`PHELMIVP_PID = 8730`: the app (named as the DB names it) joins the measured list once, unless
        a watch_only list leaves it out or the ignore list names it."""
        upper = key.removesuffix(PID_SUFFIX).lower()
        app = next((c for c in self.clients if c.lower() == upper), None)
        if app is None or any(m.app == app for m in self.measured) or pid <= 0:
            return
        if (self.watch_only and app not in self.watch_only) or app in self.ignore:
            return
        self.measured.append(Measured(app, int(pid)))

    def next_app(self) -> Measured | None:
        """The app to measure now: each in turn."""
        if not self.measured:
            return None
        self.last_index = (self.last_index + 1) % len(self.measured)
        return self.measured[self.last_index]

    def on_measure(self, item: Measured, kb: float) -> list[Post]:
        mb = kb / 1000.0
        if item.mem_mb > 0:
            item.delta_mb = mb - item.mem_mb
        item.mem_mb = mb
        return [(f"{item.app.upper()}_MEM", mb)]


MEM_WATCH_PARAMS = Params(
    Param("absolute_time_gap", float, DEFAULT_TIME_GAP, "real seconds between two measurements", lo=MIN_TIME_GAP),
    Param("watch_only", list, [], "apps to measure, comma-separated (repeatable); none: every app posting _PID"),
    Param("ignore", list, [], "apps never measured, comma-separated (repeatable)"),
)


class MemWatch(MOOSApp):
    """uMemWatch: measures the memory of every app that posts its <APP>_PID, one app each
    `absolute_time_gap` real seconds, and posts it in MB as <APP>_MEM.

    `watch_only` limits the measured apps to those named, `ignore` leaves apps out. The size is the
    process's resident memory, read from /proc.
    """

    default_name = "uMemWatch"
    parameters = MEM_WATCH_PARAMS
    example_config = """\
ProcessConfig = uMemWatch
{
  AppTick   = 0.4
  CommsTick = 0.4

  absolute_time_gap = 2          // real seconds between measurements, >= 1 (default 5)
  watch_only        = pHelmIvP   // only these apps, comma-separated (repeatable)
  ignore            = uXMS       // never these apps (repeatable)
}
"""
    interface = """\
SUBSCRIPTIONS:
  DB_CLIENTS               the MOOSDB's connected clients
  <APP>_PID                each client's process id (registered as clients appear)

PUBLICATIONS:
  <APP>_MEM                the app's resident memory in MB (1 MB = 1000 kB), one app per measurement
"""

    def on_startup(self) -> None:
        v = self.read_settings()
        lists = {}
        for key in ("watch_only", "ignore"):
            try:
                lists[key] = app_list(v[key], key)
            except ValueError as exc:
                raise self.config.entry(key).source.error(str(exc)) from None
        both = set(lists["watch_only"]) & set(lists["ignore"])
        if both:
            raise self.config.entry("ignore").source.error(f"{sorted(both)[0]} is both watched and ignored")
        self.state = MemWatchState(lists["watch_only"], lists["ignore"])
        self.time_gap = v["absolute_time_gap"]
        self.last_measure: float | None = None

    def on_connect(self) -> None:
        self.register("DB_CLIENTS")
        for client in self.state.clients:
            self.register(f"{client.upper()}{PID_SUFFIX}")

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        for msg in mail:
            if msg.key == "DB_CLIENTS" and msg.is_string():
                for key in self.state.on_clients(msg.string):
                    self.register(key)
            elif msg.key.endswith(PID_SUFFIX) and msg.is_double():
                self.state.on_pid(msg.key, msg.double)

    def iterate(self) -> None:
        now = self.moos_time()
        if self.last_measure is not None and (now - self.last_measure) / self.time_warp < self.time_gap:
            return
        self.last_measure = now
        item = self.state.next_app()
        if item is None:
            return
        kb = resident_kb(item.pid)
        if kb is None:
            log.warning("%s: no memory figure for %s (pid %d): the process is gone or /proc is missing",
                        self.name, item.app, item.pid)
            return
        for key, value in self.state.on_measure(item, kb):
            self.notify(key, value)

    def status_fields(self) -> dict:
        return {"measured": len(self.state.measured)}


main = MemWatch.main
