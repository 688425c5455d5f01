"""uLoadWatch: notices apps that fall behind their AppTick, from the ITER_GAP every app posts.

Every MOOSApp posts `<APP>_ITER_GAP` (time since its last iteration over its AppTick period, 1.0 when on
time) and `<APP>_ITER_LEN` (time its iteration took over the same period). uLoadWatch reads them all by
wildcard and, when an app's gap exceeds its threshold more than `breach_trigger` times, posts a breach:
ULW_BREACH, ULW_BREACH_COUNT, ULW_BREACH_LIST and LOAD_WARNING, as MOOS-IvP's uLoadWatch does (names,
parameters and defaults from MOOS-IvP; docs/uLoadWatch.md says where this one differs).

`LoadWatchState` is pure: gaps and lengths in, posts out.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from .app import MOOSApp
from .config import Param, Params
from .formats import FormatError, format_number, parse_number, parse_pairs
from .message import MOOSMsg

GAP_SUFFIX, LEN_SUFFIX = "_ITER_GAP", "_ITER_LEN"
ANY = "ANY"                      # `thresh = app=any, gapthresh=2`: every app without a threshold of its own
DEFAULT_NEAR_BREACH = 0.9
DEFAULT_BREACH_TRIGGER = 1       # MOOS-IvP's default: the first offence of each app is forgiven

Post = tuple[str, str | float]


def parse_thresh(text: str) -> tuple[str, float]:
    """`app=pHelmIvP, gapthresh=1.5` -> ("PHELMIVP", 1.5): app names compare in upper case, as the
    ITER_GAP variable names carry them; a missing key or a gap threshold <= 0 is an error."""
    pairs = parse_pairs(text)
    unknown = set(pairs) - {"app", "gapthresh"}
    if unknown:
        raise ValueError(f"thresh '{text}': unknown key {sorted(unknown)[0]!r} (app, gapthresh)")
    if not pairs.get("app") or "gapthresh" not in pairs:
        raise ValueError(f"thresh '{text}' needs app=<name> and gapthresh=<number>")
    try:
        gap = parse_number(pairs["gapthresh"])
    except FormatError as exc:
        raise ValueError(f"thresh '{text}': gapthresh {exc}") from None
    if gap <= 0:
        raise ValueError(f"thresh '{text}': gapthresh must be positive")
    return pairs["app"].upper(), gap


@dataclass
class AppLoad:
    """What one app's ITER_GAP / ITER_LEN posts said so far."""

    gap_total: float = 0.0
    gap_count: int = 0
    gap_max: float = 0.0
    len_total: float = 0.0
    len_count: int = 0
    len_max: float = 0.0
    breaches: int = 0             # gaps above the threshold, forgiven ones included


@dataclass
class LoadWatchState:
    """Thresholds per app (upper-case name, or ANY) and the breaches seen."""

    community: str = ""
    thresholds: dict[str, float] = field(default_factory=dict)
    near_breach_thresh: float = DEFAULT_NEAR_BREACH
    breach_trigger: int = DEFAULT_BREACH_TRIGGER
    apps: dict[str, AppLoad] = field(default_factory=dict)
    breach_count: int = 0
    near_breach_count: int = 0
    breach_sources: list[str] = field(default_factory=list)      # MOOS names of the apps that breached
    near_breach_sources: list[str] = field(default_factory=list)

    def threshold(self, app: str) -> float | None:
        """The app's own threshold, else ANY's; none at or below 1.0 (an app always on time has gap 1)."""
        value = self.thresholds.get(app, self.thresholds.get(ANY))
        return value if value is not None and value > 1.0 else None

    def on_gap(self, key: str, gap: float, source: str) -> list[Post]:
        app = key.removesuffix(GAP_SUFFIX)
        load = self.apps.setdefault(app, AppLoad())
        load.gap_total += gap
        load.gap_count += 1
        load.gap_max = max(load.gap_max, gap)
        thresh = self.threshold(app)
        if thresh is None:
            return []
        posts: list[Post] = []
        if gap > 1.0 + (thresh - 1.0) * self.near_breach_thresh:
            if self.near_breach_count == 0:
                posts.append(("ULW_NEAR_BREACH", "true"))
            self.near_breach_count += 1
            posts.append(("ULW_NEAR_BREACH_COUNT", float(self.near_breach_count)))
            posts += self._listed(self.near_breach_sources, source, "ULW_NEAR_BREACH_LIST")
        if gap <= thresh:
            return posts
        load.breaches += 1
        if load.breaches <= self.breach_trigger:
            return posts
        self.breach_count += 1
        posts.append(("ULW_BREACH_COUNT", float(self.breach_count)))
        if self.breach_count == 1:
            posts.append(("ULW_BREACH", "true"))
        posts += self._listed(self.breach_sources, source, "ULW_BREACH_LIST")
        posts.append(("LOAD_WARNING", f"app={app}, maxgap={format_number(gap, 6)}, node={self.community}"))
        return posts

    @staticmethod
    def _listed(names: list[str], source: str, key: str) -> list[Post]:
        """The list, re-posted sorted and comma-separated when `source` is new to it."""
        if source in names:
            return []
        names.append(source)
        names.sort()
        return [(key, ",".join(names))]

    def on_len(self, key: str, length: float) -> None:
        load = self.apps.setdefault(key.removesuffix(LEN_SUFFIX), AppLoad())
        load.len_total += length
        load.len_count += 1
        load.len_max = max(load.len_max, length)


LOAD_WATCH_PARAMS = Params(
    Param("thresh", list, [], "`app=<name>, gapthresh=<gap>`: the ITER_GAP above which the app is behind "
                              "(repeatable; app=any for every app without its own)"),
    Param("near_breach_thresh", float, DEFAULT_NEAR_BREACH, "share of (threshold - 1) above 1 counted as a near "
                                                            "breach", lo=0, hi=1),
    Param("breach_trigger", int, DEFAULT_BREACH_TRIGGER, "offences of each app forgiven before a breach is posted",
          lo=0),
)


class LoadWatch(MOOSApp):
    """uLoadWatch: reads every app's <APP>_ITER_GAP and <APP>_ITER_LEN and posts a breach when an app
    keeps falling behind its AppTick.

    `thresh = app=pHelmIvP, gapthresh=3` says pHelmIvP is behind when the time between two of its
    iterations exceeds 3 AppTick periods; `app=any` sets the threshold of every other app. After
    `breach_trigger` forgiven offences per app, each further one raises ULW_BREACH_COUNT, posts
    LOAD_WARNING and, the first time, ULW_BREACH = true.
    """

    default_name = "uLoadWatch"
    parameters = LOAD_WATCH_PARAMS
    example_config = """\
ProcessConfig = uLoadWatch
{
  AppTick   = 1
  CommsTick = 1

  thresh = app=pHelmIvP,  gapthresh=3     // behind when ITER_GAP > 3 (repeatable)
  thresh = app=any,       gapthresh=2.0   // every app without a threshold of its own

  near_breach_thresh = 0.9   // near breach above 1 + (thresh - 1) x this (default 0.9)
  breach_trigger     = 1     // offences per app forgiven before a breach (default 1)
}
"""
    interface = """\
SUBSCRIPTIONS:
  *_ITER_GAP               every app's time between iterations over its AppTick period
  *_ITER_LEN               every app's iteration length over its AppTick period

PUBLICATIONS:
  ULW_BREACH               true, at the first breach
  ULW_BREACH_COUNT         breaches so far
  ULW_BREACH_LIST          the apps that breached, comma-separated
  ULW_NEAR_BREACH          true, at the first near breach
  ULW_NEAR_BREACH_COUNT    near breaches so far
  ULW_NEAR_BREACH_LIST     the apps that nearly breached, comma-separated
  LOAD_WARNING             app=PHELMIVP, maxgap=3.4, node=alpha   (each breach)
"""

    def on_startup(self) -> None:
        v = self.read_settings()
        thresholds = {}
        for entry in self.config.entries:
            if entry.key.lower() == "thresh":
                try:
                    app, gap = parse_thresh(entry.moos_value)
                except ValueError as exc:
                    raise entry.source.error(str(exc)) from None
                thresholds[app] = gap
        community = self.mission.community if self.mission is not None else ""
        self.state = LoadWatchState(community, thresholds, v["near_breach_thresh"], v["breach_trigger"])

    def on_connect(self) -> None:
        self.register_wildcard(f"*{GAP_SUFFIX}")
        self.register_wildcard(f"*{LEN_SUFFIX}")

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        for msg in mail:
            if not msg.is_double():
                continue
            if msg.key.endswith(GAP_SUFFIX):
                for key, value in self.state.on_gap(msg.key, msg.double, msg.source):
                    self.notify(key, value)
            elif msg.key.endswith(LEN_SUFFIX):
                self.state.on_len(msg.key, msg.double)

    def status_fields(self) -> dict:
        return {"apps": len(self.state.apps), "breaches": self.state.breach_count}


main = LoadWatch.main
