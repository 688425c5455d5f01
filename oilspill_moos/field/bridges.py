"""What both uField brokers share: the handshake's variables and host records, pShare bridge
requests and summaries, and the MOOSApp shell that dispatches mail to a broker state.

uFldNodeBroker (node_broker) and uFldShoreBroker (shore_broker) each build on this; neither
imports the other.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace

from moosdb_py.app import MOOSApp
from moosdb_py.config import Param
from moosdb_py.formats import parse_pairs
from moosdb_py.host_info import HostRecord, format_warp, iroutes_from_summary
from moosdb_py.message import MOOSMsg
from moosdb_py.mission import db_address

log = logging.getLogger(__name__)

PING_VAR = "NODE_BROKER_PING"
ACK_VAR = "NODE_BROKER_ACK"

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


# --- the MOOSApp shells -------------------------------------------------------------------------

def bridge_switches(bridges: dict) -> tuple[Param, ...]:
    """The `auto_bridge_*` switches: one boolean each, on by default."""
    return tuple(Param(name, bool, True, f"bridge {', '.join(v if isinstance(v, tuple) else (v,))}")
                 for name, v in bridges.items())


HOSTIP = Param("hostip", str, "", "this community's address in host records; default: ServerHost (used when no "
                                  "pHostInfo runs)")


class BrokerApp(MOOSApp):
    """What both broker apps share: mail dispatch with per-message errors, posting, warnings."""

    state: BrokerState
    handlers: dict[str, str] = {}  # variable -> name of the method that takes its mail

    def read_common(self) -> dict:
        """The settings, with the community, DB port and host address both brokers put in host records."""
        settings = self.read_settings()
        self.community = self.mission.community if self.mission else "#1"
        server_host, self.port_db, _ = db_address(self.mission)
        self.hostip = settings["hostip"] or server_host
        return settings

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
