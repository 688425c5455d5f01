"""pRealm: a shadow of the local MOOSDB that answers viewers' requests with RealmCasts and WatchCasts.

MOOS-IvP runs one pRealm per community. It learns every app and the variables each one reads and
writes from the MOOSDB's DB_RWSUMMARY, registers for them, keeps the latest mail of each (a history
of doubles and of `hist_var` / `scope_set` variables), and, while a client's REALMCAST_REQ is fresh,
posts what that client asked for: a table of one app's subscriptions and publications or of a
history channel (REALMCAST), or the latest value of a few variables (WATCHCAST). REALMCAST_CHANNELS
tells clients which channels exist. Wire formats are MOOS-IvP's (docs/pRealm.md).

`RealmState` is pure: mail in (`on_mail`), postings out (`iterate`), times are MOOS times.
"""
from __future__ import annotations

import logging
from collections import deque
from dataclasses import dataclass, field

from .app import MOOSApp
from .config import Param, Params
from .formats import format_number, is_number, parse_number
from .message import MOOSMsg

log = logging.getLogger(__name__)

Post = tuple[str, str]
REALMCAST_SEP, REALMCAST_LINE_SEP = "!Q!", "!Z!"     # RealmCast fields / lines of its message text
WATCHCAST_SEP = "!X!"
PIPEWAY_FORGET = 30.0         # MOOS s after expiry before a client's request is dropped
FIRST_MINUTE = 60.0           # MOOS s after start during which REALMCAST_CHANNELS is posted every 0.5 s
FIRST_MINUTE_SUMMARY = 0.5
UNCHANGED_SUMMARY_FACTOR = 10  # an unchanged REALMCAST_CHANNELS waits 10 x summary_interval
RULE = "=" * 39
# Apps left out of REALMCAST_CHANNELS: the user's own probes.
PROBE_APPS = ("uQueryDB", "uPokeDB", "uXMS", "uMAC")
# Whose string values are not shown in subscription / publication tables (they are reports themselves).
FORMATTED_REPORTS = frozenset({"APPCAST", "REALMCAST", "BHV_IPF", "DB_RWSUMMARY", "DB_VARSUMMARY"})

REALM_PARAMS = Params(
    Param("relcast_interval", float, 0.8, "real seconds between casts to the clients", lo=0.4, hi=15),
    Param("summary_interval", float, 2.0, "real seconds between REALMCAST_CHANNELS posts (0.5 in the first "
                                          "minute, at once when a new app appears, 10x when unchanged)", lo=1, hi=10),
    Param("wrap_length", int, 90, "characters per line of a value a client asked to `wrap`", lo=1),
    Param("trunc_length", int, 270, "characters of a value a client asked to `trunc`", lo=1),
    Param("msg_max_hist", int, 10, "messages kept per double variable and per history variable", lo=1),
    Param("msg_max_history", int, None, "the same as msg_max_hist (MOOS-IvP reads both names)", lo=1),
    Param("hist_var", list, [], "a variable whose last msg_max_hist values are kept; also a history channel "
                                "of its own name"),
    Param("scope_set", list, [], "`name=N, vars=A:B:C`: a history channel N of those variables"),
)


class RealmConfigError(ValueError):
    """A hist_var or scope_set line that does not parse."""


def parse_scope_set(text: str) -> tuple[str, list[str]]:
    """`name=events, vars=DEPLOY:RETURN` -> ("events", ["DEPLOY", "RETURN"]); any other key is an error."""
    name, variables = "", []
    for part in text.split(","):
        key, _, value = part.partition("=")
        key, value = key.strip().lower(), value.strip()
        if key == "name":
            name = value
        elif key == "vars":
            variables = [v.strip() for v in value.split(":") if v.strip()]
        else:
            raise RealmConfigError(f"scope_set: unknown key '{key}' in '{text}' (name, vars)")
    if not name or not variables:
        raise RealmConfigError(f"scope_set needs name= and vars=: '{text}'")
    return name, variables


@dataclass
class PipeWay:
    """One client's standing request (REALMCAST_REQ): a channel, or variables to watch, for `duration`
    real seconds, with the table options the client chose."""

    client: str = ""
    channel: str = ""
    variables: tuple[str, ...] = ()
    duration: float = 0.0
    show_source: bool = True
    show_community: bool = True
    show_subscriptions: bool = True
    show_masked: bool = True
    wrap: bool = False
    trunc: bool = False
    utc: bool = False
    force: bool = False
    expire_time: float = field(default=0.0, compare=False)

    FLAGS = {"nosrc": ("show_source", False), "nocom": ("show_community", False),
             "nosubs": ("show_subscriptions", False), "mask": ("show_masked", False), "wrap": ("wrap", True),
             "trunc": ("trunc", True), "utc": ("utc", True), "force": ("force", True)}

    @classmethod
    def parse(cls, text: str) -> "PipeWay":
        """`client=pMarineViewer,channel=pHelmIvP,duration=3,nosrc,...` or `...,vars=DEPLOY:RETURN,...`.
        Raises ValueError for an unknown part or a request without client, duration or content."""
        way = cls()
        for part in text.split(","):
            key, _, value = part.partition("=")
            key, value = key.strip().lower(), value.strip()
            if key == "client":
                way.client = value
            elif key == "channel":
                way.channel = value
            elif key == "duration" and is_number(value):
                way.duration = parse_number(value)
            elif key == "vars":
                way.variables = tuple(sorted({v.strip() for v in value.split(":") if v.strip()}))
            elif key in cls.FLAGS:
                attr, setting = cls.FLAGS[key]
                setattr(way, attr, setting)
            else:
                raise ValueError(f"unknown part '{part.strip()}'")
        if not way.client or way.duration == 0 or not (way.channel or way.variables):
            raise ValueError("needs client=, duration= (not 0) and channel= or vars=")
        return way

    def descriptor(self, length: int = 40) -> str:
        return (self.channel or "vars=" + ",".join(self.variables))[:length]


def format_table(header: list[str], rows: list[list[str]]) -> str:
    """Columns left-aligned, two blanks apart, a dashed line under the header, trailing blanks cut."""
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = [header, ["-" * w for w in widths], *rows]
    return "\n".join("  ".join(c.ljust(w) for c, w in zip(line, widths)).rstrip() for line in lines)


def realmcast_string(node: str, proc: str, text: str) -> str:
    """REALMCAST: `node=N!Q!proc=P!Q!messages=line!Z!line!Z!` (each line of the text, then !Z!)."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return (f"node={node}{REALMCAST_SEP}proc={proc}{REALMCAST_SEP}messages="
            + "".join(line + REALMCAST_LINE_SEP for line in lines))


class RealmState:
    """What pRealm knows of its community and its clients."""

    def __init__(self, community: str, settings: dict, start_time: float, time_warp: float = 1.0):
        self.community = community
        self.moosdb = f"MOOSDB_{community}"
        self.relcast_interval = settings["relcast_interval"]
        self.summary_interval = settings["summary_interval"]
        self.wrap_length = settings["wrap_length"]
        self.trunc_length = settings["trunc_length"]
        self.max_hist = settings["msg_max_history"] or settings["msg_max_hist"]
        self.start_time = start_time
        self.time_warp = time_warp
        self.apps: set[str] = {self.moosdb}
        self.subs: dict[str, set[str]] = {}
        self.pubs: dict[str, set[str]] = {}
        self.hist_vars: set[str] = set()
        self.scope_sets: dict[str, set[str]] = {}
        self.registered: set[str] = {"DB_RWSUMMARY", "REALMCAST_REQ"}
        self.data: dict[str, deque[MOOSMsg]] = {}
        self.pipeways: dict[str, PipeWay] = {}
        self.last_watchcast: dict[str, float] = {}
        self.last_cast = 0.0
        self.last_summary = 0.0
        self.last_summary_text = ""
        self.new_app = False
        self.realmcasts = self.watchcasts = self.summaries = 0
        self.warnings: list[str] = []
        for var in settings["hist_var"]:
            if any(c.isspace() for c in var):
                raise RealmConfigError(f"hist_var: '{var}' is not a variable name")
            self._add_scope(var, [var])
        for text in settings["scope_set"]:
            self._add_scope(*parse_scope_set(text))

    def _add_scope(self, name: str, variables: list[str]) -> None:
        self.hist_vars.update(variables)
        self.registered.update(variables)
        self.scope_sets.setdefault(name, set()).update(variables)

    # -- mail ---------------------------------------------------------------------------------
    def on_mail(self, msg: MOOSMsg, now: float) -> list[str]:
        """Take one mail; returns the variables newly worth registering for."""
        new: list[str] = []
        if msg.key == "DB_RWSUMMARY" and msg.is_string():
            new = self._on_rwsummary(msg.string)
        elif msg.key == "REALMCAST_REQ" and msg.is_string():
            self._on_request(msg.string, now, msg.sender)
        if msg.source == self.moosdb:
            self.pubs.setdefault(self.moosdb, set()).add(msg.key)
        kept = self.data.setdefault(msg.key, deque())
        kept.appendleft(msg)
        limit = self.max_hist if msg.is_double() or msg.key in self.hist_vars else 1
        while len(kept) > limit:
            kept.pop()
        return new

    def _on_rwsummary(self, text: str) -> list[str]:
        """`app=sub:sub&pub:pub,app=...`: learn apps and variables; register for every one listed."""
        new = []
        for entry in text.split(","):
            app, _, rest = entry.partition("=")
            app = app.strip()
            if not app:
                continue
            if app not in self.apps:
                self.apps.add(app)
                self.new_app = True
            subs, _, pubs = rest.partition("&")
            for names, table in ((subs, self.subs), (pubs, self.pubs)):
                for var in (v.strip() for v in names.split(":")):
                    if not var:
                        continue
                    table.setdefault(app, set()).add(var)
                    if var not in self.registered:
                        self.registered.add(var)
                        new.append(var)
        return new

    def _on_request(self, text: str, now: float, sender: str) -> None:
        try:
            way = PipeWay.parse(text)
        except ValueError as err:
            self.warnings.append(f"Bad RealmCastReq from {sender}: {err}: '{text}'")
            return
        old = self.pipeways.get(way.client)
        if old is not None and old != way:
            self.warnings.append(f"Client {way.client}, new pipe: {way.descriptor()}")
        way.expire_time = now + way.duration * self.time_warp
        self.pipeways[way.client] = way

    # -- casts --------------------------------------------------------------------------------
    def iterate(self, now: float) -> list[Post]:
        return self._casts(now) + self._summary(now)

    def _casts(self, now: float) -> list[Post]:
        if (now - self.last_cast) / self.time_warp < self.relcast_interval:
            return []
        posts: list[Post] = []
        for client, way in list(self.pipeways.items()):
            left = way.expire_time - now
            if left > 0:
                cast = [self._realmcast(way)] if way.channel else self._watchcasts(way, now)
                if cast:
                    posts += cast
                    self.last_cast = now
            elif left < -PIPEWAY_FORGET:
                del self.pipeways[client]
        return posts

    def _watchcasts(self, way: PipeWay, now: float) -> list[Post]:
        """WATCHCAST `node=N!X!var=V!X!src=S!X!comm=C!X!loc_time=T!X!utc_time=U!X!dval=D` (or sval=) for
        each watched variable written since its last watchcast (every one when the client said `force`)."""
        posts = []
        for var in way.variables:
            kept = self.data.get(var)
            msg = kept[0] if kept else None
            if not way.force and (msg is None or msg.time < self.last_watchcast.get(var, 0.0)):
                continue
            fields = [f"node={self.community}", f"var={var}"]
            if msg is None:
                fields += ["src=n/a", "comm=n/a", "loc_time=-1", "utc_time=0", "sval=n/a"]
            else:
                fields += [f"src={msg.source}", f"comm={msg.community}",
                           f"loc_time={format_number(msg.time - self.start_time, 2)}",
                           f"utc_time={format_number(msg.time, 2)}",
                           f"dval={format_number(msg.double, 3)}" if msg.is_double() else f"sval={msg.string}"]
                self.last_watchcast[var] = now
            posts.append(("WATCHCAST", WATCHCAST_SEP.join(fields)))
            self.watchcasts += 1
        return posts

    def _realmcast(self, way: PipeWay) -> Post:
        """The channel's tables: a history channel's messages newest first, else the app's
        subscriptions (with `-` rows for those never written, unless `mask`) and publications."""
        channel = way.channel
        parts = []
        history = channel in self.scope_sets
        if history:
            variables = self.scope_sets[channel]
            msgs = sorted((m for v in variables for m in self.data.get(v, ())), key=lambda m: m.time, reverse=True)
            parts.append(f"History Channel [{channel}]: {','.join(sorted(variables))}\n{RULE}\n"
                         + self._table(way, [self._row(m, way, always=True) for m in msgs]) + "\n\n")
        if way.show_subscriptions and channel in self.subs:
            rows = []
            for var in sorted(self.subs[channel]):
                kept = self.data.get(var)
                if kept:
                    rows.append(self._row(kept[0], way))
                elif way.show_masked:
                    rows.append([var, "-", "never", "-", "-"])
            parts.append(f"Subscriptions\n{RULE}\n" + self._table(way, rows) + "\n\n")
        if channel in self.pubs and not history:
            rows = [self._row(self.data[v][0], way) for v in sorted(self.pubs[channel]) if self.data.get(v)]
            rule = f"{RULE}\n" if way.show_subscriptions else ""
            parts.append(f"{rule}Publications\n{RULE}\n" + self._table(way, rows) + "\n")
        self.realmcasts += 1
        proc = "uQueryDB" if "uQueryDB" in channel else channel
        return "REALMCAST", realmcast_string(self.community, proc, "".join(parts))

    def _row(self, msg: MOOSMsg, way: PipeWay, always: bool = False) -> list[str]:
        when = msg.time if way.utc else msg.time - self.start_time
        if msg.is_double():
            value = format_number(msg.double, 6)
        elif msg.is_binary():
            value = "binary"
        elif always or msg.key not in FORMATTED_REPORTS:
            value = msg.string
        else:
            value = "formatted report"
        return [msg.key, msg.source, f"{when:.2f}", msg.community, value]

    def _table(self, way: PipeWay, rows: list[list[str]]) -> str:
        """Rows of (variable, source, time, community, value); `nosrc` / `nocom` drop their columns,
        `trunc` cuts values to trunc_length, `wrap` breaks them into wrap_length lines."""
        keep = [True, way.show_source, True, way.show_community, True]
        header = [h for h, k in zip(("Variable", "Source", "Time", "Comm", "Value"), keep) if k]
        out = []
        for var, src, when, comm, value in rows:
            if way.trunc:
                value = value[:self.trunc_length]
            if var.endswith("_STATUS") and "MOOSName" in value:
                value = value.partition("MOOSName")[0]
            pieces = [value[i:i + self.wrap_length] for i in range(0, len(value), self.wrap_length)] \
                if way.wrap and value else [value]
            for i, piece in enumerate(pieces):
                cells = [var, src, when, comm, piece] if i == 0 else ["", "", "", "", piece]
                out.append([c for c, k in zip(cells, keep) if k])
        return format_table(header, out)

    def _summary(self, now: float) -> list[Post]:
        """REALMCAST_CHANNELS `node=N#channels=app,app,...,` then the history channels (MOOS-IvP
        always writes the comma before them)."""
        elapsed = (now - self.last_summary) / self.time_warp
        interval = FIRST_MINUTE_SUMMARY if now - self.start_time < FIRST_MINUTE else self.summary_interval
        if self.new_app:
            interval, self.new_app = 0.0, False
        if elapsed < interval:
            return []
        apps = [a for a in sorted(self.apps) if not any(p in a for p in PROBE_APPS)]
        text = f"node={self.community}#channels={','.join(apps)},{','.join(sorted(self.scope_sets))}"
        if text == self.last_summary_text and elapsed < interval * UNCHANGED_SUMMARY_FACTOR:
            return []
        self.last_summary_text, self.last_summary = text, now
        self.summaries += 1
        return [("REALMCAST_CHANNELS", text)]


class Realm(MOOSApp):
    """pRealm: shadows the local MOOSDB (every variable DB_RWSUMMARY names) and answers REALMCAST_REQ
    with REALMCAST (one app's or one history channel's table) or WATCHCAST (watched variables);
    REALMCAST_CHANNELS lists the channels. One per community, shoreside and vehicles, as in MOOS-IvP.
    """

    default_name = "pRealm"
    parameters = REALM_PARAMS
    example_config = """\
ProcessConfig = pRealm
{
  AppTick   = 4
  CommsTick = 4

  relcast_interval = 0.8       //  [0.4, 15] Default is 0.8
  summary_interval = 2.0       //  [1, 10] Default is 2
  wrap_length = 90             //  [1,inf] Default is 90
  trunc_length = 270           //  [1,inf] Default is 270
  msg_max_hist = 10            //  [1,inf] Default is 10

  hist_var  = TASK_BID
  scope_set = name=events, vars=DEPLOY:RETURN:STATION
}
"""
    interface = """\
SUBSCRIPTIONS:
  DB_RWSUMMARY   app=sub:sub&pub:pub,...  (from the MOOSDB): pRealm then registers for every
                 variable it names
  REALMCAST_REQ  client=pMarineViewer,channel=pHelmIvP,duration=3[,nosrc,nocom,nosubs,mask,wrap,trunc,utc]
                 client=pMarineViewer,vars=DEPLOY:RETURN,duration=3[,force]
  hist_var and scope_set variables

PUBLICATIONS:
  REALMCAST           node=abe!Q!proc=pHelmIvP!Q!messages=Subscriptions!Z!=====...!Z!...
  REALMCAST_CHANNELS  node=abe#channels=MOOSDB_abe,pHelmIvP,pNodeReporter,...,events
  WATCHCAST           node=abe!X!var=DEPLOY!X!src=uPokeDB!X!comm=abe!X!loc_time=12.5!X!utc_time=1733100000.5!X!sval=true
"""

    def on_startup(self) -> None:
        settings = self.read_settings()
        community = self.mission.community if self.mission else self.name
        try:
            self.state = RealmState(community, settings, self.moos_time(), self.time_warp)
        except RealmConfigError as err:
            entry = self.config.entry("scope_set" if "scope_set" in str(err) else "hist_var")
            raise (entry.source.error(str(err)) if entry else err) from None

    def on_connect(self) -> None:
        for key in sorted(self.state.registered):
            self.register(key)

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        now = self.moos_time()
        for msg in mail:
            for key in self.state.on_mail(msg, now):
                self.register(key)
        while self.state.warnings:
            log.warning("%s: %s", self.name, self.state.warnings.pop(0))

    def iterate(self) -> None:
        for key, value in self.state.iterate(self.moos_time()):
            self.notify(key, value)

    def status_fields(self) -> dict:
        s = self.state
        return {"apps": len(s.apps), "vars": len(s.registered), "clients": len(s.pipeways),
                "realmcasts": s.realmcasts, "watchcasts": s.watchcasts, "summaries": s.summaries}


main = Realm.main
