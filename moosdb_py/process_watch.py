"""uProcessWatch: notices when an app of the community is missing (crashed, never started, hung off).

It reads the MOOSDB's own list of connected clients (DB_CLIENTS), so it needs no help from the apps
it watches. The logic lives in `ProcessWatchState` (client lists in, posts out), the app only moves
mail and posts.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .app import MOOSApp
from .config import Param, Params
from .formats import wild_match
from .message import MOOSMsg
from .mission import Mission

DB_NAMES = {"MOOSDB", "moosdb"}
OUTPUTS = ("PROC_WATCH_SUMMARY", "PROC_WATCH_EVENT", "PROC_WATCH_FULL_SUMMARY", "PROC_WATCH_TIME_WARP",
           "PROC_WATCH_ALL_OK")
DEFAULT_SUMMARY_WAIT = 10.0

Post = tuple[str, str | float]


def matches(name: str, pattern: str) -> bool:
    """`uXMS*` matches every name starting uXMS; other patterns match exactly (case-sensitive)."""
    return wild_match(pattern, name) if pattern.endswith("*") else name == pattern


@dataclass
class Watched:
    """One watched name (or `prefix*` pattern): whether it is there and how often it came and went."""

    present: bool = False
    appeared: int = 0
    missing: int = 0
    awol: bool = False      # counted in the summary's AWOL list


@dataclass
class ProcessWatchState:
    """Which processes should be connected, and what to post when that changes."""

    own_name: str
    watch: list[str] = field(default_factory=list)       # names or `prefix*` patterns
    watch_all: bool = True                               # every client ever seen is watched
    nowatch: list[str] = field(default_factory=list)
    allow_retractions: bool = True                       # one that comes back leaves the AWOL list
    summary_wait: float = DEFAULT_SUMMARY_WAIT           # re-post the summary this often; < 0: on change only
    watched: dict[str, Watched] = field(default_factory=dict)
    last_summary: str | None = None
    last_summary_time: float | None = None
    clients_known: bool = False                          # no summary before the first DB_CLIENTS

    def __post_init__(self) -> None:
        for name in self.watch:
            self.watched.setdefault(name, Watched())

    def excluded(self, name: str) -> bool:
        return name == self.own_name or name in DB_NAMES or any(matches(name, p) for p in self.nowatch)

    def on_clients(self, clients_text: str) -> list[Post]:
        """DB_CLIENTS (`a,b,c,`): events for every watched name that came or went."""
        clients = [c.strip() for c in clients_text.split(",") if c.strip()]
        self.clients_known = True
        if self.watch_all:
            for client in clients:
                if not self.excluded(client) and not any(matches(client, w) for w in self.watched):
                    self.watched[client] = Watched()
        posts: list[Post] = []
        for name, state in self.watched.items():
            present = any(matches(c, name) for c in clients)
            if present and not state.present:
                if self.allow_retractions or state.appeared == 0:   # a late start is no return
                    state.awol = False
                state.appeared += 1
                posts.append(("PROC_WATCH_EVENT", f"Process [{name}] is noted to be present."))
            elif not present and (state.present or (state.appeared == 0 and not state.awol)):
                state.missing += 1
                state.awol = True
                posts.append(("PROC_WATCH_EVENT", f"Process [{name}] is noted to be missing."))
            state.present = present
        if posts:
            posts.append(("PROC_WATCH_FULL_SUMMARY", self.full_summary()))
        return posts

    def summary(self) -> str:
        awol = [name for name, state in self.watched.items() if state.awol]
        return "AWOL: " + ",".join(awol) if awol else "All Present"

    def full_summary(self) -> str:
        """`name(appeared/missing)` for every watched name: how often each came and went."""
        return ",".join(f"{n}({s.appeared}/{s.missing})" for n, s in self.watched.items())

    def iterate(self, now: float) -> list[Post]:
        if not self.clients_known:
            return []
        summary = self.summary()
        repeat = self.summary_wait >= 0 and self.last_summary_time is not None \
            and now - self.last_summary_time >= self.summary_wait
        if summary == self.last_summary and not repeat:
            return []
        self.last_summary, self.last_summary_time = summary, now
        return [("PROC_WATCH_SUMMARY", summary), ("PROC_WATCH_ALL_OK", "true" if summary == "All Present" else "false")]


def antler_names(mission: Mission | None) -> list[str]:
    """The MOOS names the mission's ANTLER block launches (`watch_all = antler`)."""
    if mission is None or mission.antler is None:
        return []
    return [run.moos_name for run in mission.antler.runs]


def parse_mapping(text: str, where: str) -> tuple[str, str]:
    """`post_mapping = PROC_WATCH_SUMMARY, UPW_SUMMARY` -> the pair; only our own outputs map."""
    old, sep, new = text.partition(",")
    old, new = old.strip().upper(), new.strip()
    if not sep or old not in OUTPUTS or not new:
        raise ValueError(f"{where}: post_mapping '{text}' is not <one of {', '.join(OUTPUTS)}>, <NEW_NAME>")
    return old, new


WATCH_PARAMS = Params(
    Param("watch_all", str, "true", "true (every client seen), antler (the ANTLER Run list) or false"),
    Param("watch", list, [], "a process that must be there (repeatable; NAME* is a prefix)"),
    Param("nowatch", list, [], "a process never watched (repeatable; NAME* is a prefix)"),
    Param("allow_retractions", bool, True, "a process that comes back leaves the AWOL list"),
    Param("summary_wait", float, DEFAULT_SUMMARY_WAIT, "seconds between repeats of an unchanged summary; -1: on "
                                                       "change only"),
    Param("post_mapping", list, [], "`OUTPUT, NEW_NAME`: post an output under another name (repeatable)"),
)


class ProcessWatch(MOOSApp):
    """uProcessWatch: watches the MOOSDB's client list (DB_CLIENTS) and reports missing processes.

    `watch = NAME` (or `NAME*`, a prefix) names a process that must be there; `watch_all = true`
    (the default) also watches every client that ever connects, `watch_all = antler` every MOOS name
    the mission's ANTLER block launches. `nowatch` excludes names. PROC_WATCH_SUMMARY is
    "All Present" or "AWOL: a,b"; each arrival or departure is a PROC_WATCH_EVENT.
    """

    default_name = "uProcessWatch"
    parameters = WATCH_PARAMS
    example_config = """\
ProcessConfig = uProcessWatch
{
  AppTick   = 4
  CommsTick = 4

  watch_all = true          // true (every client seen), antler (the ANTLER Run list), false (default true)
  watch     = pHelmIvP      // must be there (repeatable; NAME* is a prefix)
  nowatch   = uXMS*         // never watched (repeatable; NAME* is a prefix)
  nowatch   = uPokeDB*

  allow_retractions = true  // a process that comes back leaves the AWOL list (default true)
  summary_wait      = 10    // seconds between repeats of an unchanged summary; -1: on change only (default 10)

  post_mapping = PROC_WATCH_SUMMARY, UPW_SUMMARY   // post an output under another name (repeatable)
}
"""
    interface = """\
SUBSCRIPTIONS:
  DB_CLIENTS               the MOOSDB's connected clients (comma list)

PUBLICATIONS:
  PROC_WATCH_SUMMARY       "All Present" or "AWOL: pHelmIvP,uSimMarine" (on change, and every summary_wait s)
  PROC_WATCH_ALL_OK        true / false, with each summary
  PROC_WATCH_EVENT         "Process [pHelmIvP] is noted to be missing." / "... present."
  PROC_WATCH_FULL_SUMMARY  pHelmIvP(1/0),uSimMarine(2/1)  (times each process appeared/went missing)
  PROC_WATCH_TIME_WARP     the time warp (once, on connecting)
  (post_mapping renames any of these)
"""

    def on_startup(self) -> None:
        v = self.read_settings()
        watch_all = v["watch_all"].lower()
        if watch_all not in ("true", "false", "antler"):
            raise self.config.entry("watch_all").source.error(
                f"watch_all = {watch_all!r}: expected true, false or antler")
        watch, nowatch = v["watch"], v["nowatch"]
        if watch_all == "antler":
            watch += [n for n in antler_names(self.mission) if n not in watch]
        self.state = ProcessWatchState(self.name, watch, watch_all == "true", nowatch, v["allow_retractions"],
                                       v["summary_wait"])
        self.state.watched = {n: s for n, s in self.state.watched.items() if not self.state.excluded(n)}
        self.mapping = dict(parse_mapping(text, f"{self.config.source}: {self.name}") for text in v["post_mapping"])

    def post(self, posts: list[Post]) -> None:
        for key, value in posts:
            self.notify(self.mapping.get(key, key), value)

    def on_connect(self) -> None:
        self.register("DB_CLIENTS")
        self.post([("PROC_WATCH_TIME_WARP", self.time_warp)])

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        for msg in mail:
            if msg.key == "DB_CLIENTS" and msg.is_string():
                self.post(self.state.on_clients(msg.string))

    def iterate(self) -> None:
        self.post(self.state.iterate(self.moos_time()))

    def status_fields(self) -> dict:
        return {"watched": len(self.state.watched), "summary": f'"{self.state.summary()}"'}


main = ProcessWatch.main
