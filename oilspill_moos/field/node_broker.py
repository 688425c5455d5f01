"""uFldNodeBroker: the vehicle half of the uField handshake.

The vehicle pings every shore it was told about (through its pShare), and when
a shore acknowledges, it asks its pShare to bridge the configured variables to
that shore.  The logic lives in `NodeBrokerState`, which takes mail and the
clock and returns what to post; the `NodeBroker` MOOSApp only moves mail in and
posts out, so the handshake can be tested without sockets.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

from moosdb_py.app import MOOSApp
from moosdb_py.host_info import HostRecord, format_warp, iroutes_from_summary
from moosdb_py.message import MOOSMsg
from moosdb_py.mission import db_address
from oilspill_moos.app_config import config_bool, parse_pairs, warn_unhandled

log = logging.getLogger(__name__)

PING_VAR = "NODE_BROKER_PING"
ACK_VAR = "NODE_BROKER_ACK"
PING_PERIOD = 20.0  # seconds between pings while a shore answers
PING_PERIOD_UNANSWERED = 5.0  # ... and while none has answered for this long
NODE_AUTO_BRIDGES = {
    "auto_bridge_appcast": ("APPCAST",),
    "auto_bridge_realmcast": ("REALMCAST", "WATCHCAST", "REALMCAST_CHANNELS"),
    "auto_bridge_pshare_vars": ("NODE_PSHARE_VARS",),
}

Post = tuple[str, str | float]


def strip_blanks(text: str) -> str:
    """MOOS deletes every blank inside a config line before an app reads it; do the same."""
    return "".join(text.split())


def pairs_at(text: str, where: str) -> dict[str, str]:
    """`a=1,b=2` -> {'a': '1', 'b': '2'}; an error names the place."""
    try:
        return parse_pairs(text)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def own_host_record(community: str, hostip: str, port_db: int, input_summary: str, time_warp: float) -> HostRecord:
    """The record pHostInfo would post, built from the mission and pShare's PSHARE_INPUT_SUMMARY.

    Used when no pHostInfo runs in the community; a PHI_HOST_INFO that arrives wins.
    """
    return HostRecord(
        community=community,
        hostip=hostip,
        port_db=str(port_db),
        pshare_iroutes=iroutes_from_summary(input_summary),
        timewarp=format_warp(time_warp),
    )


def parse_bridge(text: str, where: str) -> tuple[str, str]:
    """`src=VAR[,alias=VAR2]` -> (src, alias); the alias defaults to src."""
    pairs = pairs_at(strip_blanks(text), where)
    src = pairs.get("src", "")
    if not src:
        raise ValueError(f"{where}: bridge '{text}' has no src=")
    unknown = set(pairs) - {"src", "alias"}
    if unknown:
        raise ValueError(f"{where}: bridge '{text}' has unknown field(s) {', '.join(sorted(unknown))}")
    return src, pairs.get("alias") or src


def parse_shore_route(text: str, where: str) -> str:
    """`pshare_route=ip:port` -> `ip:port`."""
    pairs = pairs_at(strip_blanks(text), where)
    route = pairs.get("pshare_route", "")
    host, sep, port = route.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ValueError(f"{where}: '{text}' is not pshare_route=<ip>:<port>")
    return route


def parse_output_summary(summary: str) -> set[tuple[str, str, str]]:
    """PSHARE_OUTPUT_SUMMARY -> {(src, dest, host:port)}.

    Format: `src->dest:host:port & dest2:host:port, src2->...` (a multicast route
    carries a third `:multicast_N` part, kept in the route).
    """
    shares: set[tuple[str, str, str]] = set()
    for entry in summary.split(","):
        src, sep, routes = entry.strip().partition("->")
        if not sep:
            continue
        for route in routes.split("&"):
            dest, _, address = route.strip().partition(":")
            if address:
                shares.add((src, dest, address))
    return shares


def pshare_output_cmd(src: str, dest: str, route: str) -> str:
    return f"cmd=output,src_name={src},dest_name={dest},route={route}"


@dataclass
class ShoreContact:
    """What a node knows about a shore that acknowledged it."""

    route: str
    community: str = ""
    hostip: str = ""
    timewarp: str = ""
    last_ack: float | None = None
    bridged_at: float | None = None


@dataclass
class BrokerState:
    """What both brokers keep about their own community's host record."""

    community: str
    host_record: HostRecord | None = None
    host_record_from_phi: bool = False
    shared: set[tuple[str, str, str]] | None = None  # what pShare says it forwards; None until it says
    warnings: list[str] = field(default_factory=list)

    def on_output_summary(self, summary: str) -> None:
        self.shared = parse_output_summary(summary)

    def on_host_info(self, text: str, community: str) -> None:
        """PHI_HOST_INFO from our own pHostInfo (one from elsewhere is not ours). It wins over the
        record built from PSHARE_INPUT_SUMMARY once it carries pShare's routes and the time warp."""
        if community and community != self.community:
            return
        record = HostRecord.parse(text)
        if not (record.pshare_iroutes and record.timewarp):
            return
        self.host_record = replace(record, status="", time="", key="")
        self.host_record_from_phi = True

    def on_input_summary(self, summary: str, hostip: str, port_db: int, time_warp: float) -> None:
        """PSHARE_INPUT_SUMMARY: our iroutes, unless a pHostInfo already told us."""
        if not self.host_record_from_phi and summary.strip():
            self.host_record = own_host_record(self.community, hostip, port_db, summary, time_warp)


@dataclass
class NodeBrokerState(BrokerState):
    """The vehicle side of the handshake, free of I/O: mail in, posts out."""

    bridges: list[tuple[str, str]] = field(default_factory=list)
    shores: list[ShoreContact] = field(default_factory=list)
    last_ping: float | None = None
    last_ack: float | None = None
    last_repair: float | None = None

    def add_shore(self, route: str) -> bool:
        if any(s.route == route for s in self.shores):
            self.warnings.append(f"shore route {route} given twice; ignored")
            return False
        self.shores.append(ShoreContact(route))
        return True

    @property
    def acknowledged(self) -> bool:
        return any(s.last_ack is not None for s in self.shores)

    def on_ack(self, text: str, community: str, now: float) -> list[Post]:
        """NODE_BROKER_ACK from a shore: remember it and, the first time, set up the bridges."""
        if community == self.community:
            return []
        record = HostRecord.parse(text)
        key = record.key
        if key.isdigit() and int(key) < len(self.shores):
            shore = self.shores[int(key)]
        else:
            self.warnings.append(f"ack from {record.community} with bad key '{key}'")
            shore = self._shore_for(record)
            if shore is None:
                return []
        shore.community, shore.hostip, shore.timewarp = record.community, record.hostip, record.timewarp
        shore.last_ack = now
        self.last_ack = now
        posts: list[Post] = [("NODE_PSHARE_VARS", ",".join(alias for _, alias in self.bridges))]
        if shore.bridged_at is None:
            shore.bridged_at = now
            posts += self.bridge_requests(shore)
        return posts

    def bridge_requests(self, shore: ShoreContact) -> list[Post]:
        return [("PSHARE_CMD", pshare_output_cmd(src, alias, shore.route)) for src, alias in self.bridges
                if self.shared is None or (src, alias, shore.route) not in self.shared]

    def repairs(self, now: float) -> list[Post]:
        """Bridges our pShare no longer shows (it was restarted on its own) are asked for again, the ping
        route included: an ack can arrive before our pShare ever had it (a shore that still remembered
        us acks a restarted vehicle at once), and without it a restarted shore would never hear us."""
        if self.shared is None or (self.last_repair is not None and now - self.last_repair < PING_PERIOD_UNANSWERED):
            return []
        posts: list[Post] = []
        for i, shore in enumerate(self.shores):
            if (f"{PING_VAR}_{i}", PING_VAR, shore.route) not in self.shared:
                posts.append(("PSHARE_CMD", pshare_output_cmd(f"{PING_VAR}_{i}", PING_VAR, shore.route)))
            if shore.bridged_at is not None and now - shore.bridged_at >= PING_PERIOD_UNANSWERED:
                posts += self.bridge_requests(shore)
        if posts:
            self.last_repair = now
        return posts

    def _shore_for(self, record: HostRecord) -> ShoreContact | None:
        """An ack without a usable key: match the shore by its iroutes, or take the only one."""
        for shore in self.shores:
            if shore.route in record.iroutes():
                return shore
        return self.shores[0] if len(self.shores) == 1 else None

    def iterate(self, now: float) -> list[Post]:
        posts: list[Post] = []
        if not self.acknowledged:
            posts += [
                ("PSHARE_CMD", pshare_output_cmd(f"{PING_VAR}_{i}", PING_VAR, shore.route))
                for i, shore in enumerate(self.shores)
            ]
        posts += self.repairs(now)
        if self.host_record is None or not self.host_record.pshare_iroutes:
            return posts
        answered = self.last_ack is not None and now - self.last_ack <= PING_PERIOD_UNANSWERED
        period = PING_PERIOD if answered else PING_PERIOD_UNANSWERED
        if self.last_ping is None or now - self.last_ping >= period:
            self.last_ping = now
            for i, _ in enumerate(self.shores):
                ping = replace(self.host_record, time=f"{now:.2f}", key=str(i))
                posts.append((f"{PING_VAR}_{i}", ping.spec()))
        return posts


def node_bridges(bridge_lines: list[str], auto: dict[str, bool]) -> list[tuple[str, str]]:
    """The configured bridges plus the automatic ones, without repeats, in that order.

    `auto` maps each auto_bridge_* switch to its value.
    """
    bridges: list[tuple[str, str]] = []
    for i, line in enumerate(bridge_lines):
        bridge = parse_bridge(line, f"bridge #{i + 1}")
        if bridge not in bridges:
            bridges.append(bridge)
    for switch, variables in NODE_AUTO_BRIDGES.items():
        if auto.get(switch, True):
            bridges += [(v, v) for v in variables if (v, v) not in bridges]
    sources = {src for src, _ in bridges}
    if {"NODE_MESSAGE_LOCAL", "MEDIATED_MESSAGE_LOCAL"} <= sources:
        raise ValueError("bridge: NODE_MESSAGE_LOCAL (unmediated) and MEDIATED_MESSAGE_LOCAL (mediated) exclude each other")
    return bridges


# --- the MOOSApp shells -------------------------------------------------------------------------

class BrokerApp(MOOSApp):
    """What both broker apps share: mail dispatch with per-message errors, posting, warnings."""

    state: BrokerState
    handlers: dict[str, str] = {}  # variable -> name of the method that takes its mail
    config_keys: frozenset[str] = frozenset()

    def read_common(self) -> None:
        warn_unhandled(self.config, self.config_keys)
        community = self.mission.community if self.mission else "#1"
        server_host, self.port_db, _ = db_address(self.mission)
        self.hostip = (self.config.get("hostip") or server_host).strip()
        self.community = community

    def on_connect(self) -> None:
        for var in self.handlers:
            self.register(var)

    def on_new_mail(self, mail: list[MOOSMsg]) -> None:
        for msg in mail:
            method = self.handlers.get(msg.key)
            if method is None:
                continue
            try:
                self.post(getattr(self, method)(msg) or [])
            except ValueError as exc:
                log.warning("%s: %s from %s dropped: %s", self.name, msg.key, msg.sender, exc)
        self.report_warnings()

    def iterate(self) -> None:
        self.post(self.state.iterate(self.moos_time()))
        self.report_warnings()

    def post(self, posts: list[Post]) -> None:
        for key, value in posts:
            self.notify(key, value)

    def report_warnings(self) -> None:
        while self.state.warnings:
            log.warning("%s: %s", self.name, self.state.warnings.pop(0))

    def on_host_info(self, msg: MOOSMsg) -> None:
        self.state.on_host_info(msg.string, msg.community)

    def on_input_summary(self, msg: MOOSMsg) -> None:
        self.state.on_input_summary(msg.string, self.hostip, self.port_db, self.time_warp)

    def on_output_summary(self, msg: MOOSMsg) -> None:
        self.state.on_output_summary(msg.string)

    def auto_switches(self, names) -> dict[str, bool]:
        return {name: config_bool(self.config, name, True) for name in names}


class NodeBroker(BrokerApp):
    """uFldNodeBroker: pings the shoreside(s) through pShare until one acknowledges, then asks pShare
    to bridge the configured variables (NODE_REPORT_LOCAL -> NODE_REPORT, ...) to that shore.

    Usage: uFldNodeBroker mission.moos [alias]  (reads its ProcessConfig block)
    The host record in the pings is pHostInfo's PHI_HOST_INFO once a complete one arrives; until then
    it is built from the mission (Community, ServerHost, ServerPort, MOOSTimeWarp) and pShare's
    PSHARE_INPUT_SUMMARY.
    """

    default_name = "uFldNodeBroker"
    example_config = """\
ProcessConfig = uFldNodeBroker
{
  AppTick   = 1
  CommsTick = 1

  // Where a shoreside pShare listens (repeatable; a repeat is a warning)
  try_shore_host = pshare_route=localhost:9200

  // Variables bridged to every shore that acknowledges (repeatable); alias defaults to src
  bridge = src=NODE_REPORT_LOCAL, alias=NODE_REPORT
  bridge = src=NODE_MESSAGE_LOCAL, alias=NODE_MESSAGE

  auto_bridge_appcast     = true   // bridge APPCAST
  auto_bridge_realmcast   = true   // bridge REALMCAST, WATCHCAST, REALMCAST_CHANNELS
  auto_bridge_pshare_vars = true   // bridge NODE_PSHARE_VARS

  hostip = localhost               // default: ServerHost; used when no pHostInfo runs
}
"""
    interface = """\
SUBSCRIPTIONS:
  PHI_HOST_INFO         this community's host record (from pHostInfo, if one runs)
  PSHARE_INPUT_SUMMARY  pShare's input routes (record used until PHI_HOST_INFO)
  NODE_BROKER_ACK       a shore's acknowledgement (host record,status=..,key=<i>,id=..);
                        acks from this vehicle's own community are ignored
  TRY_SHORE_HOST        pshare_route=<ip>:<port>: one more shore to ping
  PSHARE_OUTPUT_SUMMARY what pShare forwards: bridges it lost (a pShare restart) are asked for again

PUBLICATIONS:
  PSHARE_CMD            cmd=output,src_name=NODE_BROKER_PING_<i>,dest_name=NODE_BROKER_PING,route=<shore>
                        (until a shore answers), then one per bridge:
                        cmd=output,src_name=<src>,dest_name=<alias>,route=<shore>
  NODE_BROKER_PING_<i>  <host record>,time=<utc>,key=<i>  every 20 s (5 s while unanswered)
  NODE_PSHARE_VARS      comma list of the bridged aliases
"""
    config_keys = frozenset({"try_shore_host", "bridge", "hostip", *NODE_AUTO_BRIDGES})
    handlers = {
        "PHI_HOST_INFO": "on_host_info",
        "PSHARE_INPUT_SUMMARY": "on_input_summary",
        "NODE_BROKER_ACK": "on_ack",
        "TRY_SHORE_HOST": "on_try_shore_host",
        "PSHARE_OUTPUT_SUMMARY": "on_output_summary",
    }

    def on_startup(self) -> None:
        self.read_common()
        bridges = node_bridges(self.config.get_all("bridge"), self.auto_switches(NODE_AUTO_BRIDGES))
        self.state = NodeBrokerState(self.community, bridges=bridges)
        for i, line in enumerate(self.config.get_all("try_shore_host")):
            self.state.add_shore(parse_shore_route(line, f"try_shore_host #{i + 1}"))
        if not self.state.shores:
            log.warning("%s: no try_shore_host; waiting for TRY_SHORE_HOST mail", self.name)
        self.report_warnings()

    def on_ack(self, msg: MOOSMsg) -> list[Post]:
        return self.state.on_ack(msg.string, msg.community, self.moos_time())

    def on_try_shore_host(self, msg: MOOSMsg) -> None:
        self.state.add_shore(parse_shore_route(msg.string, f"TRY_SHORE_HOST from {msg.source}"))

    def status_fields(self) -> dict:
        shores = [s.community or s.route for s in self.state.shores if s.last_ack is not None]
        return {"shores": len(self.state.shores), "acked_by": ":".join(shores)}


main = NodeBroker.main
