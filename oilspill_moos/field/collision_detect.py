"""uFldCollisionDetect: the shoreside judge of how close vehicles came to each other.

`CollisionMonitor` is pure. For every pair of vehicles it follows the range between their latest
NODE_REPORTs; when the range turns from closing to opening (by more than a 1 m swing, so jitter
does not count) the smallest range seen is the pair's CPA, and a CPA within `encounter_range` is
an encounter, within `near_miss_range` a near miss, within `collision_range` a collision. Pairs
farther apart than 1.5 x encounter_range are forgotten until they close in again.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

from behaviors.flags import FlagError, FlagSpec, parse_flag
from behaviors.logic import Condition, ConditionError, condition_variables, parse_condition
from moosdb_py.formats import format_number
from moosdb_py.config import ConfigValueError, Param, Params, read_params
from moosdb_py.geodesy import mission_grid
from oilspill_moos.machine_app import MachineApp
from behaviors.contacts import NodeRecord, NodeRecordError

log = logging.getLogger(__name__)

Post = tuple[str, str | float]
SWING_RANGE = 1.0            # m the range must turn by before closing/opening is believed
IGNORE_FACTOR = 1.5          # pairs beyond this x encounter_range are not followed
RANKS = ("collision", "near_miss", "encounter")


@dataclass(frozen=True)
class CPAEvent:
    """Two vehicles passed each other at `cpa` metres; (x, y) is their midpoint then."""

    vname1: str
    vname2: str
    cpa: float
    x: float
    y: float
    rank: str


@dataclass
class PairTrack:
    """The range history of one pair, as much as the closing/opening test needs."""

    dist: float
    closing: bool = False
    valid: bool = False
    min_closing: float = math.inf   # smallest range while closing
    max_opening: float = 0.0        # largest range while opening
    mid: tuple[float, float] = (0.0, 0.0)


@dataclass
class CollisionParams:
    encounter_range: float = 20.0
    near_miss_range: float = 6.0
    collision_range: float = 3.0
    flags: dict[str, list[FlagSpec]] = field(default_factory=lambda: {rank: [] for rank in RANKS})
    conditions: list[Condition] = field(default_factory=list)
    ignore_groups: set[str] = field(default_factory=set)
    reject_groups: set[str] = field(default_factory=set)
    post_closest_range: bool = False
    report_all_encounters: bool = False
    pulse_render: bool = True
    pulse_range: float = 20.0
    pulse_duration: float = 10.0
    warnings: list[str] = field(default_factory=list)

    @classmethod
    def from_config(cls, cfg) -> "CollisionParams":
        v = COLLISION_PARAMS.read(cfg)
        same = ("encounter_range", "near_miss_range", "collision_range", "post_closest_range", "report_all_encounters",
                "pulse_render", "pulse_range", "pulse_duration")
        params = cls(**{name: v[name] for name in same})
        for rank in RANKS:
            for text in v[f"{rank}_flag"]:
                try:
                    flag = parse_flag(text)
                except FlagError as exc:
                    raise ConfigValueError(f"{rank}_flag", str(exc)) from None
                if flag is not None:
                    params.flags[rank].append(flag)
        for text in v["condition"]:
            try:
                params.conditions.append(parse_condition(text))
            except ConditionError as exc:
                raise ConfigValueError("condition", str(exc)) from None
        for key, groups in (("ignore_group", params.ignore_groups), ("reject_group", params.reject_groups)):
            groups.update(g.strip().lower() for text in v[key] for g in text.split(",") if g.strip())
        if params.near_miss_range < params.collision_range:
            params.near_miss_range = params.collision_range
            params.warnings.append("near_miss_range raised to collision_range")
        if params.encounter_range < params.near_miss_range:
            params.encounter_range = params.near_miss_range
            params.warnings.append("encounter_range raised to near_miss_range")
        return params


def pair_tag(a: str, b: str) -> tuple[str, str]:
    return (a, b) if a < b else (b, a)


class CollisionMonitor:
    """Encounters, near misses and collisions between vehicles, free of I/O."""

    def __init__(self, params: CollisionParams, grid=None):
        self.params = params
        self.grid = grid
        self.records: dict[str, NodeRecord] = {}
        self.groups: dict[str, str] = {}
        self.updated: set[str] = set()
        self.pairs: dict[tuple[str, str], PairTrack] = {}
        self.values: dict[str, str | float] = {}     # variables the conditions read
        self.totals = {rank: 0 for rank in RANKS}
        self.per_vehicle: dict[str, dict[str, int]] = {}
        self.closest_range = math.inf                # over the latest round
        self.closest_ever = math.inf
        self.warnings: list[str] = []

    def on_node_report(self, text: str) -> None:
        record = NodeRecord.parse(text, self.grid)
        group = record.group.lower()
        if group in self.params.reject_groups:
            return
        self.records[record.name], self.groups[record.name] = record, group
        self.updated.add(record.name)

    def on_mail(self, key: str, value, now: float = 0.0, sender: str = "") -> None:
        if key == "NODE_REPORT":
            try:
                self.on_node_report(value if isinstance(value, str) else "")
            except NodeRecordError as exc:
                self.warnings.append(f"NODE_REPORT from {sender or '?'} ignored: {exc}")
        else:
            self.values[key] = value

    def conditions_hold(self) -> bool:
        return all(c.evaluate(self.values.get) for c in self.params.conditions)

    def track(self, a: str, b: str) -> CPAEvent | None:
        """Update one pair's range; an event when it has just turned from closing to opening."""
        ra, rb = self.records[a], self.records[b]
        dist = math.hypot(ra.x - rb.x, ra.y - rb.y)
        self.closest_range = min(self.closest_range, dist)
        self.closest_ever = min(self.closest_ever, dist)
        tag = pair_tag(a, b)
        if dist > IGNORE_FACTOR * self.params.encounter_range:
            self.pairs.pop(tag, None)
            return None
        pair = self.pairs.get(tag)
        if pair is None:
            self.pairs[tag] = PairTrack(dist, max_opening=dist)   # first sight counts as the farthest yet
            return None
        was_closing, was_valid = pair.closing, pair.valid
        if dist == pair.dist:
            return None
        if dist < pair.dist:
            if not pair.closing and pair.max_opening - dist > SWING_RANGE:
                pair.closing = True
            pair.min_closing = dist
        else:
            if pair.closing and dist - pair.min_closing > SWING_RANGE:
                pair.closing = False
            pair.max_opening = dist
        pair.dist, pair.valid = dist, True
        pair.mid = ((ra.x + rb.x) / 2.0, (ra.y + rb.y) / 2.0)
        if not (was_valid and was_closing and not pair.closing) or pair.min_closing > self.params.encounter_range:
            return None
        cpa = pair.min_closing
        rank = ("collision" if cpa <= self.params.collision_range else
                "near_miss" if cpa <= self.params.near_miss_range else "encounter")
        return CPAEvent(tag[0], tag[1], cpa, pair.mid[0], pair.mid[1], rank)

    def examine(self) -> list[CPAEvent]:
        """Every pair with at least one vehicle heard from since the last round, once each."""
        self.closest_range = math.inf
        events, seen = [], set()
        for a in sorted(self.updated):
            for b in sorted(self.records):
                tag = pair_tag(a, b)
                if a == b or tag in seen:
                    continue
                seen.add(tag)
                if self.params.ignore_groups and {self.groups[a], self.groups[b]} <= self.params.ignore_groups:
                    continue
                event = self.track(a, b)
                if event is not None:
                    events.append(event)
        self.updated.clear()
        return events

    def flag_posts(self, event: CPAEvent) -> list[Post]:
        posts: list[Post] = []
        names = {"$UP_V1": event.vname1.upper(), "$UP_V2": event.vname2.upper(), "$V1": event.vname1,
                 "$V2": event.vname2}
        flags = self.params.flags["encounter"] + (self.params.flags[event.rank] if event.rank != "encounter" else [])
        for flag in flags:
            var, value = flag.var, flag.value
            for macro, name in names.items():
                var = var.replace(macro, name)
            if isinstance(value, str) and value == "$CPA":
                value = event.cpa
            elif isinstance(value, str):
                for macro, name in names.items():
                    value = value.replace(macro, name)
                value = value.replace("$CPA", format_number(event.cpa, 4))
            posts.append((var, value))
        return posts

    def iterate(self, now: float) -> list[Post]:
        events = self.examine()
        posts: list[Post] = []
        if self.params.post_closest_range and math.isfinite(self.closest_range) and self.closest_range > 0:
            posts.append(("UCD_CLOSEST_RANGE", self.closest_range))
        if not self.conditions_hold():
            return posts
        for event in events:
            for name in (event.vname1, event.vname2):   # every event is an encounter; a collision is not a near miss
                counts = self.per_vehicle.setdefault(name, {r: 0 for r in RANKS})
                counts["encounter"] += 1
                if event.rank != "encounter":
                    counts[event.rank] += 1
            self.totals["encounter"] += 1
            posts.append(("ENCOUNTER_TOTAL", float(self.totals["encounter"])))
            if event.rank != "encounter":
                self.totals[event.rank] += 1
                posts.append((f"{event.rank.upper()}_TOTAL", float(self.totals[event.rank])))
            if event.rank != "encounter" or self.params.report_all_encounters:
                posts.append(("UCD_REPORT", f"vname1={event.vname1},vname2={event.vname2},"
                                            f"cpa={format_number(event.cpa, 3)},rank={event.rank}"))
            posts += self.flag_posts(event)
            if self.params.pulse_render and event.rank != "encounter":
                color = "red" if event.rank == "collision" else "yellow"
                posts.append(("VIEW_RANGE_PULSE", f"x={format_number(event.x, 2)},y={format_number(event.y, 2)},"
                              f"radius={format_number(self.params.pulse_range, 3)},"
                              f"duration={format_number(self.params.pulse_duration, 3)},fill=0.25,fill_color={color},"
                              f"edge_color={color},time={format_number(now, 2)},edge_size=1"))
        return posts

    def params_summary(self) -> str:
        p = self.params
        return ",".join(f"{key}={format_number(value, 3)}" for key, value in (
            ("collision_range", p.collision_range), ("near_miss_range", p.near_miss_range),
            ("encounter_range", p.encounter_range)))


COLLISION_PARAMS = Params(
    Param("condition", list, [], "count only while this holds (repeatable)"),
    *(Param(f"{rank}_flag", list, [], f"`VAR = value` posted at each {rank.replace('_', ' ')} ($V1, $V2, $CPA; "
                                      "repeatable)") for rank in RANKS),
    Param("encounter_range", float, 20.0, "m", lo=0.0),
    Param("near_miss_range", float, 6.0, "m", lo=0.0),
    Param("collision_range", float, 3.0, "m", lo=0.0),
    Param("ignore_group", list, [], "pairs of two vehicles of these groups are not judged"),
    Param("reject_group", list, [], "reports of these groups are not read at all"),
    Param("post_closest_range", bool, False, "UCD_CLOSEST_RANGE every round"),
    Param("report_all_encounters", bool, False, "UCD_REPORT for plain encounters too"),
    Param("pulse_render", bool, True, "VIEW_RANGE_PULSE at each near miss and collision"),
    Param("pulse_range", float, 20.0, "m", lo=0.0),
    Param("pulse_duration", float, 10.0, "s", lo=0.0),
    Param("encounter_rings", str, "", "accepted, not drawn"),
)


class CollisionDetect(MachineApp):
    """uFldCollisionDetect: counts encounters, near misses and collisions between vehicles.

    Runs on the shoreside with every vehicle's NODE_REPORT. When two vehicles pass each other
    (their range turns from closing to opening), the closest range is their CPA: within
    encounter_range (20 m) it is an encounter, within near_miss_range (6 m) a near miss, within
    collision_range (3 m) a collision. Near misses and collisions post UCD_REPORT; every event
    updates ENCOUNTER_TOTAL, NEAR_MISS_TOTAL, COLLISION_TOTAL and posts the configured flags
    ($V1, $V2, $UP_V1, $UP_V2, $CPA). Events count only while every `condition` holds.
    """

    default_name = "uFldCollisionDetect"
    parameters = COLLISION_PARAMS
    inputs = ("NODE_REPORT",)
    example_config = """\
ProcessConfig = uFldCollisionDetect
{
  AppTick   = 4
  CommsTick = 4

  condition = DEPLOY_ALL = true     // count only while this holds (repeatable)

  encounter_flag = ENCOUNTER = $CPA
  collision_flag = COLLISION = $CPA
  near_miss_flag = NEAR_MISS = vname1=$V1,vname2=$V2,cpa=$CPA

  encounter_range = 20             // m (the default)
  near_miss_range = 6              // m (the default)
  collision_range = 3              // m (the default)

  ignore_group = alpha             // pairs of two vehicles of these groups are not judged
  reject_group = bravo             // reports of these groups are not read at all

  post_closest_range    = false    // UCD_CLOSEST_RANGE every round
  report_all_encounters = false    // UCD_REPORT for plain encounters too

  pulse_render   = true            // VIEW_RANGE_PULSE at each near miss and collision
  pulse_range    = 20              // m
  pulse_duration = 10              // s
}
"""
    interface = """\
SUBSCRIPTIONS:
  NODE_REPORT = NAME=alpha,X=51.71,Y=-35.50,SPD=2.0,HDG=118.8,GROUP=blue,...
  the variables the conditions name
PUBLICATIONS:
  UCD_REPORT       = vname1=abe,vname2=cal,cpa=2.4,rank=collision   (rank: collision | near_miss)
  ENCOUNTER_TOTAL  = 193
  NEAR_MISS_TOTAL  = 8
  COLLISION_TOTAL  = 0
  UCD_CLOSEST_RANGE = 14.2          (post_closest_range)
  COLLISION_DETECT_PARAMS = collision_range=3,near_miss_range=6,encounter_range=20   (at start)
  VIEW_RANGE_PULSE = x=78.78,y=-78.4,radius=20,duration=10,fill=0.25,fill_color=red,...
  the collision_flag, near_miss_flag and encounter_flag postings
"""

    def on_startup(self) -> None:
        params = read_params(self.config, CollisionParams.from_config)
        for warning in params.warnings:
            log.warning("%s: %s", self.name, warning)
        self.machine = CollisionMonitor(params, mission_grid(self.mission))
        self.params_posted = False

    def registrations(self) -> list[str]:
        return [*self.inputs, *condition_variables(self.machine.params.conditions)]

    def iterate(self) -> None:
        if not self.params_posted:
            self.notify("COLLISION_DETECT_PARAMS", self.machine.params_summary())
            self.params_posted = True
        super().iterate()

    def status_fields(self) -> dict:
        t = self.machine.totals
        closest = self.machine.closest_ever
        return {"encounters": t["encounter"], "near_misses": t["near_miss"], "collisions": t["collision"],
                "closest": f"{closest:.2f}" if math.isfinite(closest) else "none"}


main = CollisionDetect.main
