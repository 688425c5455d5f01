"""uFldNodeBroker: the vehicle half of the uField handshake.

The vehicle pings every shore it was told about (through its pShare), and when
a shore acknowledges, it asks its pShare to bridge the configured variables to
that shore.  The logic lives in `NodeBrokerState`, which takes mail and the
clock and returns what to post; the `NodeBroker` MOOSApp only moves mail in and
posts out, so the handshake can be tested without sockets.
"""
from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field, replace

from moosdb_py.config import Param, Params
from moosdb_py.host_info import HostRecord
from moosdb_py.message import MOOSMsg
from oilspill_moos.field.bridges import (
    HOSTIP,
    PING_VAR,
    BrokerApp,
    BrokerState,
    Post,
    bridge_switches,
    pairs_at,
    parse_bridge,
    pshare_output_cmd,
    strip_blanks,
)

log = logging.getLogger(__name__)

PING_PERIOD = 20.0  # seconds between pings while a shore answers
PING_PERIOD_UNANSWERED = 5.0  # ... and while none has answered for this long
NODE_AUTO_BRIDGES = {
    "auto_bridge_appcast": ("APPCAST",),
    "auto_bridge_realmcast": ("REALMCAST", "WATCHCAST", "REALMCAST_CHANNELS"),
    "auto_bridge_pshare_vars": ("NODE_PSHARE_VARS",),
}


def parse_shore_route(text: str, where: str) -> str:
    """`pshare_route=ip:port` -> `ip:port`."""
    pairs = pairs_at(strip_blanks(text), where)
    route = pairs.get("pshare_route", "")
    host, sep, port = route.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ValueError(f"{where}: '{text}' is not pshare_route=<ip>:<port>")
    return route


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
  UFLDNODEBROKER_PID    the process id, once at start-up (what uMemWatch measures)
"""
    parameters = Params(
        Param("try_shore_host", list, [], "`pshare_route=host:port` where a shoreside pShare listens (repeatable)"),
        Param("bridge", list, [], "`src=VAR[, alias=NAME]` bridged to every shore that acknowledges (repeatable); "
                                  "alias defaults to src"),
        *bridge_switches(NODE_AUTO_BRIDGES),
        HOSTIP,
    )
    handlers = {
        "PHI_HOST_INFO": "on_host_info",
        "PSHARE_INPUT_SUMMARY": "on_input_summary",
        "NODE_BROKER_ACK": "on_ack",
        "TRY_SHORE_HOST": "on_try_shore_host",
        "PSHARE_OUTPUT_SUMMARY": "on_output_summary",
    }

    def on_startup(self) -> None:
        settings = self.read_common()
        bridges = node_bridges(settings["bridge"], {name: settings[name] for name in NODE_AUTO_BRIDGES})
        self.state = NodeBrokerState(self.community, bridges=bridges)
        for i, line in enumerate(settings["try_shore_host"]):
            self.state.add_shore(parse_shore_route(line, f"try_shore_host #{i + 1}"))
        if not self.state.shores:
            log.warning("%s: no try_shore_host; waiting for TRY_SHORE_HOST mail", self.name)
        self.report_warnings()
        self.notify("UFLDNODEBROKER_PID", float(os.getpid()))   # as MOOS-IvP's, for uMemWatch (sent on connecting)

    def on_ack(self, msg: MOOSMsg) -> list[Post]:
        return self.state.on_ack(msg.string, msg.community, self.moos_time())

    def on_try_shore_host(self, msg: MOOSMsg) -> None:
        self.state.add_shore(parse_shore_route(msg.string, f"TRY_SHORE_HOST from {msg.source}"))

    def status_fields(self) -> dict:
        shores = [s.community or s.route for s in self.state.shores if s.last_ack is not None]
        return {"shores": len(self.state.shores), "acked_by": ":".join(shores)}


main = NodeBroker.main
