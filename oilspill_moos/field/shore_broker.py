"""uFldShoreBroker: the shoreside half of the uField handshake.

Every vehicle that pings is acknowledged, and the shore's pShare is asked to
bridge shoreside variables to it: `X_ALL` to every vehicle's `X`, `X_$V` to
vehicle V's `X` (qbridge), or any `bridge = src=..,alias=..`.  As in
`node_broker`, the logic is `ShoreBrokerState` (mail in, posts out) and the
`ShoreBroker` MOOSApp is a thin shell around it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from moosdb_py.config import Param, Params
from moosdb_py.host_info import HostRecord
from moosdb_py.message import MOOSMsg
from oilspill_moos.field.bridges import (
    ACK_VAR,
    HOSTIP,
    BrokerApp,
    BrokerState,
    Post,
    bridge_switches,
    pairs_at,
    parse_bridge,
    pshare_output_cmd,
    strip_blanks,
)

NODE_FRESH = 10.0  # a node is acked while its last ping is younger than this
BRIDGE_INTERVAL_START = 5.0  # bridge requests: first round after this ...
BRIDGE_INTERVAL_GROWTH = 3.0  # ... and each round waits this much longer
NODE_COUNT_PERIOD = 30.0
DEFAULT_VNODE_PORT = 9200
SHORE_AUTO_QBRIDGES = {"auto_bridge_realmcast": "REALMCAST_REQ", "auto_bridge_appcast": "APPCAST_REQ"}
SHORE_AUTO_BRIDGES = {"auto_bridge_mhash": "MISSION_HASH"}


def expand_source(src: str, vname: str, index: int) -> str:
    """`$V` -> vehicle name in upper case, `$v` -> as given, `$N` -> 1-based vehicle index."""
    return src.replace("$V", vname.upper()).replace("$v", vname).replace("$N", str(index))


def parse_qbridge(text: str, where: str) -> list[str]:
    names = [n for n in strip_blanks(text).split(",") if n]
    for name in names:
        if "=" in name:
            raise ValueError(f"{where}: qbridge name '{name}' must not contain '='")
    if not names:
        raise ValueError(f"{where}: qbridge without variable names")
    return names


def qbridge_pairs(var: str) -> list[tuple[str, str]]:
    return [(f"{var}_ALL", var), (f"{var}_$V", var)]


def parse_vnode_route(text: str, where: str) -> str:
    """`route=ip[:port]` -> `ip:port` (port 9200 when not given)."""
    route = pairs_at(strip_blanks(text), where).get("route", "")
    host, sep, port = route.partition(":")
    if not host or (sep and not port.isdigit()):
        raise ValueError(f"{where}: '{text}' is not route=<ip>[:<port>]")
    return f"{host}:{port or DEFAULT_VNODE_PORT}"


def status_for(record: HostRecord, keyword: str, shore_warp: str) -> str:
    if record.keyword != keyword:
        return "keyword_mismatch"
    if shore_warp and not _same_warp(record.timewarp, shore_warp):  # unknown yet is not a mismatch
        return f"timewarp ({shore_warp}!={record.timewarp})"
    return "ok"


def _same_warp(a: str, b: str) -> bool:
    try:
        return float(a) == float(b)
    except ValueError:
        return a == b


@dataclass
class NodeContact:
    """A vehicle the shore has heard from."""

    vname: str
    index: int
    routes: str
    status: str
    key: str
    last_seen: float


@dataclass
class ShoreBrokerState(BrokerState):
    """The shoreside handshake, free of I/O: pings in, acks and PSHARE_CMD bridges out."""

    bridges: list[tuple[str, str]] = field(default_factory=list)
    qbridge_vars: list[str] = field(default_factory=list)
    keyword: str = ""
    vnode_routes: list[str] = field(default_factory=list)
    nodes: dict[str, NodeContact] = field(default_factory=dict)
    ack_id: int = 0
    bridge_interval: float = BRIDGE_INTERVAL_START
    last_bridge_round: float | None = None
    last_count: int | None = None
    last_count_post: float | None = None
    last_vnode_offer: float | None = None
    summaries_posted: bool = False

    def node_bridges(self, node: NodeContact) -> list[tuple[str, str]]:
        """Every bridge for one node, `$V` expanded, starting with the one that carries its acks."""
        pairs = [(f"{ACK_VAR}_{node.vname.upper()}", ACK_VAR)]
        if node.status == "ok":
            pairs += [(expand_source(src, node.vname, node.index), alias) for src, alias in self.bridges]
        return pairs

    def on_ping(self, text: str, community: str, now: float) -> list[Post]:
        """NODE_BROKER_PING from a vehicle (a local one is ours and ignored)."""
        if community == self.community:
            return []
        record = HostRecord.parse(text)
        shore_warp = self.host_record.timewarp if self.host_record else ""
        status = status_for(record, self.keyword, shore_warp)
        routes = record.pshare_iroutes
        own_ip = self.host_record.hostip if self.host_record else ""
        if record.hostip and own_ip and record.hostip != own_ip:
            routes = routes.replace("localhost", record.hostip)
        node = self.nodes.get(record.community)
        if node is not None and node.routes == routes and node.status == status:
            node.last_seen, node.key = now, record.key
            return []
        if node is None:
            node = NodeContact(record.community, len(self.nodes) + 1, routes, status, record.key, now)
            self.nodes[node.vname] = node
        else:
            node.routes, node.status, node.key, node.last_seen = routes, status, record.key, now
        if status != "ok":
            self.warnings.append(f"node {node.vname}: {status}")
        self.bridge_interval = BRIDGE_INTERVAL_START
        self.last_bridge_round = now
        return self.bridge_requests(node)

    def bridge_requests(self, node: NodeContact) -> list[Post]:
        routes = [r for r in node.routes.split("&") if r]
        if not routes:
            self.warnings.append(f"node {node.vname} has no pshare_iroutes; nothing can be bridged to it")
            return []
        shared = self.shared or set()
        return [
            ("PSHARE_CMD", pshare_output_cmd(src, alias, node.routes))
            for src, alias in self.node_bridges(node)
            if not all((src, alias, route) in shared for route in routes)
        ]

    def iterate(self, now: float) -> list[Post]:
        posts: list[Post] = []
        if not self.summaries_posted:
            self.summaries_posted = True
            posts.append(("UFSB_QBRIDGE_VARS", ",".join(self.qbridge_vars)))
            posts.append(("UFSB_BRIDGE_VARS", ",".join(src for src, _ in self.bridges)))
        if self.host_record is not None:
            posts += self._acks(now)
            posts += self._vnode_offers(now)
        if self.last_bridge_round is None:
            self.last_bridge_round = now
        elif now - self.last_bridge_round >= self.bridge_interval:
            self.last_bridge_round = now
            self.bridge_interval += BRIDGE_INTERVAL_GROWTH
            for node in self.nodes.values():
                posts += self.bridge_requests(node)
        count = len(self.nodes)
        if count != self.last_count or self.last_count_post is None or now - self.last_count_post >= NODE_COUNT_PERIOD:
            self.last_count, self.last_count_post = count, now
            posts.append(("UFSB_NODE_COUNT", float(count)))
        return posts

    def _acks(self, now: float) -> list[Post]:
        fresh = [n for n in self.nodes.values() if now - n.last_seen <= NODE_FRESH]
        if not fresh:
            return []
        self.ack_id += 1
        spec = self.host_record.spec()
        posts: list[Post] = []
        for node in fresh:
            posts.append((f"{ACK_VAR}_{node.vname.upper()}", f"{spec},status={node.status},key={node.key},id={self.ack_id}"))
            posts.append(("NODE_BROKER_VACK", node.vname))
        return posts

    def _vnode_offers(self, now: float) -> list[Post]:
        """try_vnode: tell vehicles we were given by address where to ping us (their TRY_SHORE_HOST)."""
        routes = self.host_record.iroutes()
        if not self.vnode_routes or not routes:
            return []
        if self.last_vnode_offer is not None and now - self.last_vnode_offer < BRIDGE_INTERVAL_START:
            return []
        first = self.last_vnode_offer is None
        self.last_vnode_offer = now
        route = routes[0].replace("localhost", self.host_record.hostip or "localhost")
        posts: list[Post] = []
        if first:
            posts += [("PSHARE_CMD", pshare_output_cmd("TRY_SHORE_HOST", "TRY_SHORE_HOST", r)) for r in self.vnode_routes]
        posts.append(("TRY_SHORE_HOST", f"pshare_route={route}"))
        return posts


def shore_bridges(
    bridge_lines: list[str], qbridge_lines: list[str], auto: dict[str, bool]
) -> tuple[list[tuple[str, str]], list[str]]:
    """(every bridge, the qbridge variable names): qbridges first, then bridges, then the automatic ones."""
    qvars: list[str] = []
    for i, line in enumerate(qbridge_lines):
        qvars += [v for v in parse_qbridge(line, f"qbridge #{i + 1}") if v not in qvars]
    for switch, var in SHORE_AUTO_QBRIDGES.items():
        if auto.get(switch, True) and var not in qvars:
            qvars.append(var)
    bridges: list[tuple[str, str]] = []
    for var in qvars:
        bridges += [p for p in qbridge_pairs(var) if p not in bridges]
    for i, line in enumerate(bridge_lines):
        bridge = parse_bridge(line, f"bridge #{i + 1}")
        if bridge not in bridges:
            bridges.append(bridge)
    for switch, var in SHORE_AUTO_BRIDGES.items():
        if auto.get(switch, True) and (var, var) not in bridges:
            bridges.append((var, var))
    return bridges, qvars


class ShoreBroker(BrokerApp):
    """uFldShoreBroker: acknowledges every vehicle that pings (NODE_BROKER_PING, through pShare) and
    asks the shoreside pShare to bridge variables to it: `qbridge = X` sends shoreside X_ALL to every
    vehicle's X and X_<VNAME> to that vehicle's X; `bridge = src=..,alias=..` with $V (upper-case
    vehicle name), $v (as given) and $N (1-based vehicle index) in src.

    Usage: uFldShoreBroker mission.moos [alias]  (reads its ProcessConfig block)
    The acks carry this community's host record: pHostInfo's PHI_HOST_INFO once a complete one
    arrives, until then one built from the mission and pShare's PSHARE_INPUT_SUMMARY.
    """

    default_name = "uFldShoreBroker"
    example_config = """\
ProcessConfig = uFldShoreBroker
{
  AppTick   = 1
  CommsTick = 1

  // qbridge = X is short for bridge = src=X_ALL,alias=X and bridge = src=X_$V,alias=X
  qbridge = DEPLOY, RETURN, STATION_KEEP, MOOS_MANUAL_OVERRIDE

  // src may hold $V (vehicle name in upper case), $v (as given), $N (vehicle index, from 1)
  bridge  = src=RETURN_$V, alias=RETURN

  auto_bridge_appcast   = true    // qbridge APPCAST_REQ
  auto_bridge_realmcast = true    // qbridge REALMCAST_REQ
  auto_bridge_mhash     = true    // bridge MISSION_HASH

  keyword  =                      // pings with another keyword get status=keyword_mismatch
  try_vnode = route=10.0.0.5:9201 // (repeatable) offer this shore to a vehicle by address
  hostip   = localhost            // default: ServerHost; used when no pHostInfo runs
}
"""
    interface = """\
SUBSCRIPTIONS:
  NODE_BROKER_PING       a vehicle's host record (bridged by its pShare); local ones are ignored
  PHI_HOST_INFO          this community's host record (from pHostInfo, if one runs)
  PSHARE_INPUT_SUMMARY   pShare's input routes (record used until PHI_HOST_INFO)
  PSHARE_OUTPUT_SUMMARY  what pShare already forwards (those bridges are not requested again)

PUBLICATIONS:
  NODE_BROKER_ACK_<VNAME>  <shore host record>,status=<ok|timewarp (a!=b)|keyword_mismatch>,key=<k>,id=<n>
                           every Iterate for each vehicle heard from in the last 10 s
  NODE_BROKER_VACK         <vname>, with each ack
  PSHARE_CMD               cmd=output,src_name=<src, $V expanded>,dest_name=<alias>,route=<vehicle iroutes>
  TRY_SHORE_HOST           pshare_route=<this shore's route>   (only with try_vnode)
  UFSB_NODE_COUNT          number of vehicles known (on change, or every 30 s)
  UFSB_QBRIDGE_VARS        comma list of the qbridge variables
  UFSB_BRIDGE_VARS         comma list of every bridge source
"""
    parameters = Params(
        Param("qbridge", list, [], "`X[, Y...]`: short for bridge = src=X_ALL,alias=X and bridge = src=X_$V,alias=X"),
        Param("bridge", list, [], "`src=VAR, alias=NAME`; src may hold $V (vehicle name in upper case), $v (as "
                                  "given), $N (vehicle index, from 1)"),
        *bridge_switches({**SHORE_AUTO_QBRIDGES, **SHORE_AUTO_BRIDGES}),
        Param("keyword", str, "", "pings with another keyword get status=keyword_mismatch"),
        Param("try_vnode", list, [], "`route=host:port`: offer this shore to a vehicle by address (repeatable)"),
        HOSTIP,
    )
    handlers = {
        "NODE_BROKER_PING": "on_ping",
        "PHI_HOST_INFO": "on_host_info",
        "PSHARE_INPUT_SUMMARY": "on_input_summary",
        "PSHARE_OUTPUT_SUMMARY": "on_output_summary",
    }

    def on_startup(self) -> None:
        settings = self.read_common()
        switches = {name: settings[name] for name in [*SHORE_AUTO_QBRIDGES, *SHORE_AUTO_BRIDGES]}
        bridges, qvars = shore_bridges(settings["bridge"], settings["qbridge"], switches)
        vnodes = [parse_vnode_route(line, f"try_vnode #{i + 1}") for i, line in enumerate(settings["try_vnode"])]
        keyword = strip_blanks(settings["keyword"])
        self.state = ShoreBrokerState(self.community, bridges=bridges, qbridge_vars=qvars, keyword=keyword,
                                      vnode_routes=vnodes)

    def on_ping(self, msg: MOOSMsg) -> list[Post]:
        return self.state.on_ping(msg.string, msg.community, self.moos_time())

    def status_fields(self) -> dict:
        return {"nodes": ":".join(self.state.nodes)}


main = ShoreBroker.main
