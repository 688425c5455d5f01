"""uFldNodeComms: the shoreside relay that decides which vehicle hears which.

Vehicles send their NODE_REPORT and NODE_MESSAGE to the shore; `NodeCommsRelay` passes each on to
the other vehicles as NODE_REPORT_<VNAME> / NODE_MESSAGE_<VNAME> (upper-case name; the shore broker
bridges those to the vehicle's NODE_REPORT / NODE_MESSAGE) only if the receiver reported within
`stale_time`, is within `comms_range` (scaled by the sender's stealth and the receiver's earange),
shares the sender's group (with `groups`), survives `drop_percentage`, and its last report from
that sender is `min_rpt_interval` old; within `critical_range` a report always goes through.
Messages also obey `min_msg_interval` (per sender) and `max_msg_length`. The relay is pure (mail
and the clock in, postings out); its random drops come from a numpy Generator it is given.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from moosdb_py.formats import parse_pairs
from moosdb_py.config import ConfigValueError, Param, Params, config_float, read_params
from moosdb_py.geodesy import mission_grid
from oilspill_moos.machine_app import MachineApp
from behaviors.contacts import NodeRecord, NodeRecordError
from oilspill_moos.node_message import NodeMessage


Post = tuple[str, str | float]
MIN_STEALTH, MAX_EARANGE = 0.1, 10.0
STALE_FORGET_FACTOR = 20   # a vehicle silent for 20 x stale_time is forgotten


def parse_vname_factor(text: str, key: str, lo: float, hi: float) -> tuple[str, float]:
    """`vname=alpha, stealth=0.8` -> ('ALPHA', 0.8), clipped into [lo, hi] as the C++ app does."""
    try:
        pairs = parse_pairs(text)
    except ValueError as exc:
        raise ConfigValueError(key, str(exc)) from None
    vname, raw = pairs.get("vname", ""), pairs.get(key, pairs.get("earrange" if key == "earange" else key))
    try:
        value = float(raw) if raw is not None else math.nan
    except ValueError:
        value = math.nan
    if not vname or not math.isfinite(value):
        raise ConfigValueError(key, f"expected 'vname=<name>, {key}=<number>', got {text!r}")
    return vname.upper(), min(max(value, lo), hi)


NODE_COMMS_PARAMS = Params(
    Param("comms_range", str, "100", "m (nolimit or < 0: no limit; 0: nothing passes)"),
    Param("critical_range", float, 30.0, "m: reports always pass within this range", lo=0.0),
    Param("stale_time", float, 5.0, "s: receivers silent longer hear nothing (< 0: never stale)"),
    Param("max_msg_length", int, 1000, "characters of a message's string_val (0: no limit)", lo=0),
    Param("min_msg_interval", float, 30.0, "s between messages from one sender", lo=0.0),
    Param("min_rpt_interval", float, -1.0, "s between reports from one vehicle to another (< 0: every one)"),
    Param("groups", bool, False, "reports pass only within a group (GROUP= of the reports)"),
    Param("msg_groups", bool, False, "messages likewise"),
    Param("ignore_group", str, "", "reports of this group are not relayed"),
    Param("stealth", list, [], "`vname=alpha, stealth=0.8`: alpha is heard only within 0.8 x comms_range (>= 0.1)"),
    Param("earange", list, [], "`vname=alpha, earange=4.5`: alpha hears from 4.5 x comms_range (<= 10)"),
    Param("drop_percentage", float, 0.0, "% of otherwise passing reports and messages dropped at random", 0.0, 100.0),
    Param("drop_seed", str, "", "whole-number seed for the drops (project addition; default: unseeded)"),
    Param("shared_node_reports", str, "false", "true (or real s): also post NODE_REPORT_UNC for a shoreside viewer"),
    *(Param(key, str, "", "drawing switch of the C++ app: accepted, nothing to draw here")
      for key in ("view_node_rpt_pulses", "pulse_duration", "msg_color", "msg_repeat_color")),
)


@dataclass
class NodeCommsParams:
    """The uFldNodeComms block, with the documented defaults (ranges in metres, times in seconds)."""

    comms_range: float = 100.0        # < 0: no limit, 0: nothing passes
    critical_range: float = 30.0
    stale_time: float = 5.0           # < 0: never stale
    min_msg_interval: float = 30.0
    min_rpt_interval: float = -1.0
    max_msg_length: int = 1000        # 0: no limit
    groups: bool = False
    msg_groups: bool = False
    drop_percentage: float = 0.0
    ignore_group: str = ""
    shared_node_reports: float = -1.0   # min real seconds between NODE_REPORT_UNC per vehicle; < 0: off
    stealth: dict[str, float] = field(default_factory=dict)
    earange: dict[str, float] = field(default_factory=dict)
    drop_seed: int | None = None

    @classmethod
    def from_config(cls, cfg) -> "NodeCommsParams":
        v = NODE_COMMS_PARAMS.read(cfg)
        comms, shared, seed = v["comms_range"], v["shared_node_reports"].lower(), v["drop_seed"]
        if shared not in ("true", "false"):
            shared_value = config_float(cfg, "shared_node_reports", 0.1, lo=0.0)
        else:
            shared_value = 0.1 if shared == "true" else -1.0
        if seed and not seed.isdigit():
            raise ConfigValueError("drop_seed", f"expected a whole number >= 0, got {seed!r}")
        return cls(
            comms_range=-1.0 if comms.lower() == "nolimit" else config_float(cfg, "comms_range", 100.0),
            critical_range=v["critical_range"], stale_time=v["stale_time"], min_msg_interval=v["min_msg_interval"],
            min_rpt_interval=v["min_rpt_interval"], max_msg_length=int(v["max_msg_length"]), groups=v["groups"],
            msg_groups=v["msg_groups"], drop_percentage=v["drop_percentage"], ignore_group=v["ignore_group"].upper(),
            shared_node_reports=shared_value,
            stealth=dict(parse_vname_factor(t, "stealth", MIN_STEALTH, 1.0) for t in v["stealth"]),
            earange=dict(parse_vname_factor(t, "earange", 1.0, MAX_EARANGE) for t in v["earange"]),
            drop_seed=int(seed) if seed else None,
        )


@dataclass
class CommsStats:
    """Totals for the status line and the tests."""

    reports_rcvd: int = 0
    reports_sent: int = 0
    reports_dropped: int = 0
    messages_rcvd: int = 0
    messages_sent: int = 0
    blk_invalid: int = 0
    blk_stale: int = 0
    blk_quick: int = 0
    blk_long: int = 0
    blk_far: int = 0
    blk_noinfo: int = 0
    blk_dropped: int = 0
    stale_forgotten: int = 0


class NodeCommsRelay:
    """Who hears whom, free of I/O: `on_node_report`/`on_node_message` in, `iterate(now)` posts out."""

    def __init__(self, params: NodeCommsParams, rng: np.random.Generator | None = None, grid=None,
                 time_warp: float = 1.0):
        self.params = params
        self.rng = rng if rng is not None else np.random.default_rng(params.drop_seed)
        self.grid = grid
        self.time_warp = time_warp
        self.records: dict[str, NodeRecord] = {}          # upper-case vehicle name -> latest report
        self.heard: dict[str, float] = {}                 # ... -> MOOS time of that report
        self.new_reports: set[str] = set()
        self.messages: dict[str, list[NodeMessage]] = {}  # upper-case source -> messages this round
        self.last_msg_time: dict[str, float] = {}
        self.last_rpt_time: dict[tuple[str, str], float] = {}
        self.last_share: dict[str, float] = {}
        self.stats = CommsStats()
        self.warnings: list[str] = []

    # ---- input ---------------------------------------------------------------------------
    def on_node_report(self, text: str, now: float) -> None:
        record = NodeRecord.parse(text, self.grid)
        if self.params.ignore_group and record.group.upper() == self.params.ignore_group:
            return
        name = record.name.upper()
        self.records[name], self.heard[name] = record, now
        self.new_reports.add(name)
        self.stats.reports_rcvd += 1

    def on_node_message(self, text: str) -> None:
        message = NodeMessage.parse(text)
        self.messages.setdefault(message.src_node.upper(), []).append(message)
        self.stats.messages_rcvd += 1

    def on_mail(self, key: str, value, now: float, sender: str = "") -> None:
        """One piece of shoreside mail; what cannot be used becomes a warning naming the sender."""
        try:
            if key in ("NODE_REPORT", "NODE_REPORT_LOCAL") and isinstance(value, str):
                self.on_node_report(value, now)
            elif key == "NODE_MESSAGE" and isinstance(value, str):
                try:
                    self.on_node_message(value)
                except NodeRecordError:
                    self.stats.blk_invalid += 1
                    raise
            elif key in ("UNC_STEALTH", "UNC_EARANGE") and isinstance(value, str):
                which = key[4:].lower()
                lo, hi = (MIN_STEALTH, 1.0) if which == "stealth" else (1.0, MAX_EARANGE)
                vname, factor = parse_vname_factor(value, which, lo, hi)
                getattr(self.params, which)[vname] = factor
            elif key == "UNC_COMMS_RANGE" and isinstance(value, float):
                self.params.comms_range = value
            elif key == "UNC_DROP_PCT" and isinstance(value, float) and 0.0 <= value <= 100.0:
                self.params.drop_percentage = value
            else:
                self.warnings.append(f"{key} from {sender or '?'} ignored: unexpected value {value!r}")
        except (NodeRecordError, ValueError) as exc:
            self.warnings.append(f"{key} from {sender or '?'} ignored: {exc}")

    # ---- criteria ------------------------------------------------------------------------
    def distance(self, a: str, b: str) -> float:
        ra, rb = self.records[a], self.records[b]
        return math.hypot(ra.x - rb.x, ra.y - rb.y)

    def in_range(self, src: str, dest: str) -> bool:
        """Within comms_range, scaled down by the sender's stealth and up by the receiver's earange."""
        if self.params.comms_range < 0:
            return True
        if self.params.comms_range == 0:
            return False
        limit = self.params.comms_range * self.params.stealth.get(src, 1.0) * self.params.earange.get(dest, 1.0)
        return self.distance(src, dest) <= limit

    def fresh(self, name: str, now: float) -> bool:
        return self.params.stale_time < 0 or now - self.heard[name] <= self.params.stale_time

    def dropped(self) -> bool:
        return self.params.drop_percentage > 0 and self.rng.uniform(0.0, 100.0) < self.params.drop_percentage

    # ---- work ----------------------------------------------------------------------------
    def relay_report(self, src: str, now: float) -> list[Post]:
        posts: list[Post] = []
        src_group = self.records[src].group.upper()
        for dest in sorted(self.records):
            if dest == src:
                continue
            send = (self.fresh(dest, now) and self.in_range(src, dest)
                    and (not self.params.groups or src_group == self.records[dest].group.upper()))
            if send and self.dropped():
                send = False
                self.stats.reports_dropped += 1
            if send and self.params.min_rpt_interval > 0:
                send = now - self.last_rpt_time.get((src, dest), -math.inf) >= self.params.min_rpt_interval
            if not send and self.distance(src, dest) <= self.params.critical_range:
                send = True   # close enough to matter for safety: always heard
            if send:
                posts.append((f"NODE_REPORT_{dest}", self.records[src].text))
                self.last_rpt_time[(src, dest)] = now
                self.stats.reports_sent += 1
        return posts

    def shared_report(self, name: str, now: float) -> list[Post]:
        """NODE_REPORT_UNC for the shoreside viewer, at most every shared_node_reports real seconds."""
        interval = self.params.shared_node_reports
        if interval < 0 or (now - self.last_share.get(name, -math.inf)) / self.time_warp < interval:
            return []
        self.last_share[name] = now
        return [("NODE_REPORT_UNC", self.records[name].text)]

    def message_destinations(self, src: str, message: NodeMessage) -> list[str]:
        dests = {d.strip().upper() for d in message.dest_node.split(":") if d.strip() and d.strip().upper() != "ALL"}
        group = message.dest_group.upper()
        if group or message.dest_node.upper() == "ALL":
            dests |= {name for name, rec in self.records.items()
                      if name != src and (not group or rec.group.upper() == group)}
        return sorted(dests)

    def relay_message(self, src: str, message: NodeMessage, now: float) -> list[Post]:
        if self.params.max_msg_length > 0 and message.length() > self.params.max_msg_length:
            self.stats.blk_long += 1
            return []
        posts: list[Post] = []
        for dest in self.message_destinations(src, message):
            if dest == src:
                continue
            if src not in self.records or dest not in self.records:
                self.stats.blk_noinfo += 1
            elif self.params.msg_groups and (not self.records[src].group
                                             or self.records[src].group.upper() != self.records[dest].group.upper()):
                continue
            elif not self.fresh(dest, now):
                self.stats.blk_stale += 1
            elif not self.in_range(src, dest):
                self.stats.blk_far += 1
            elif self.dropped():
                self.stats.blk_dropped += 1
            else:
                posts.append((f"NODE_MESSAGE_{dest}", message.text))
                self.stats.messages_sent += 1
        return posts

    def forget_stale(self, now: float) -> None:
        if self.params.stale_time < 0:
            return
        for name in [n for n, t in self.heard.items() if now - t > STALE_FORGET_FACTOR * self.params.stale_time]:
            for table in (self.records, self.heard, self.last_share, self.last_msg_time):
                table.pop(name, None)
            self.stats.stale_forgotten += 1

    def iterate(self, now: float) -> list[Post]:
        posts: list[Post] = []
        for name in sorted(self.new_reports):
            if name in self.records:
                posts += self.relay_report(name, now) + self.shared_report(name, now)
        for src, messages in sorted(self.messages.items()):
            for message in messages:
                if now - self.last_msg_time.get(src, -math.inf) < self.params.min_msg_interval:
                    self.stats.blk_quick += 1
                    continue
                self.last_msg_time[src] = now
                posts += self.relay_message(src, message, now)
        self.new_reports.clear()
        self.messages.clear()
        self.forget_stale(now)
        return posts


INPUTS = ("NODE_REPORT", "NODE_REPORT_LOCAL", "NODE_MESSAGE", "UNC_STEALTH", "UNC_EARANGE", "UNC_COMMS_RANGE",
          "UNC_DROP_PCT")


class NodeComms(MachineApp):
    """uFldNodeComms: relays each vehicle's NODE_REPORT and NODE_MESSAGE to the vehicles that can hear it.

    Runs on the shoreside. A report from vehicle A goes to vehicle B as NODE_REPORT_B when B has
    reported within stale_time, is within comms_range of A (times A's stealth and B's earange),
    is in A's group (groups = true), and the drop_percentage dice let it through; within
    critical_range it always goes. A NODE_MESSAGE goes to its dest_node (a name, a colon list,
    or all) or dest_group as NODE_MESSAGE_<NAME>, by the same range and freshness tests, at most one
    per min_msg_interval per sender and no longer than max_msg_length characters.
    """

    default_name = "uFldNodeComms"
    parameters = NODE_COMMS_PARAMS
    inputs = INPUTS
    example_config = """\
ProcessConfig = uFldNodeComms
{
  AppTick   = 4
  CommsTick = 4

  comms_range      = 100     // m (nolimit or < 0: no limit; 0: nothing passes)
  critical_range   = 30      // m: reports always pass within this range
  stale_time       = 5       // s: receivers silent longer hear nothing (< 0: never stale)

  max_msg_length   = 1000    // characters of a message's string_val (0: no limit)
  min_msg_interval = 30      // s between messages from one sender
  min_rpt_interval = -1      // s between reports from one vehicle to another (< 0: every one)

  groups     = false         // reports pass only within a group (GROUP= of the reports)
  msg_groups = false         // messages likewise
  ignore_group = buoys       // reports of this group are not relayed

  stealth = vname=alpha, stealth=0.8     // alpha is heard only within 0.8 x comms_range (>= 0.1)
  earange = vname=alpha, earange=4.5     // alpha hears from 4.5 x comms_range (<= 10)

  drop_percentage = 0        // % of otherwise passing reports and messages dropped at random
  drop_seed       = 7        // seed for the drops (project addition; default: unseeded)

  shared_node_reports = false  // true (or real s): also post NODE_REPORT_UNC for a shoreside viewer
}
"""
    interface = """\
SUBSCRIPTIONS:
  NODE_REPORT, NODE_REPORT_LOCAL = NAME=alpha,X=51.71,Y=-35.50,SPD=2.0,HDG=118.8,GROUP=blue,...
  NODE_MESSAGE    = src_node=alpha,dest_node=bravo,var_name=FOO,string_val=bar
                    (dest_node may be a:b lists or all; dest_group=<group>; double_val=<number>)
  UNC_STEALTH     = vname=alpha,stealth=0.4
  UNC_EARANGE     = vname=alpha,earange=2.0
  UNC_COMMS_RANGE = 250
  UNC_DROP_PCT    = 20
PUBLICATIONS:
  NODE_REPORT_<VNAME>  = the sender's report, as received (VNAME in upper case)
  NODE_MESSAGE_<VNAME> = the message, as received
  NODE_REPORT_UNC      = every vehicle's report, rate-limited (shared_node_reports)
"""

    def on_startup(self) -> None:
        params = read_params(self.config, NodeCommsParams.from_config)
        self.machine = NodeCommsRelay(params, grid=mission_grid(self.mission), time_warp=self.time_warp)

    def status_fields(self) -> dict:
        s = self.machine.stats
        return {"vehicles": len(self.machine.records), "reports_rcvd": s.reports_rcvd, "reports_sent": s.reports_sent,
                "messages_rcvd": s.messages_rcvd, "messages_sent": s.messages_sent,
                "reports_dropped": s.reports_dropped}


main = NodeComms.main
