"""pPathAssign: the shoreside coordinator between the spill forecaster and the fleet.

Three layers, so that everything except the sockets can be tested without a
MOOSDB: `parse_boundary_line` (one TCP line -> Boundary), `Coordinator` (the
phase machine; mail in, posts out, MOOS time passed in), and the `PathAssign`
MOOSApp shell that owns the TCP server and the MOOS client.
"""
from __future__ import annotations

import asyncio
import math
import re
from dataclasses import dataclass, field

from shapely.geometry import Polygon

from moosdb_py.app import MOOSApp
from moosdb_py.config import Param, Params
from moosdb_py.formats import format_number
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.messages import (
    Boundary,
    BoundaryError,
    format_forecast,
    operating_area,
    parse_boundary_line,
    parse_report,
    points_update,
    polygon_string,
)
from oilspill_moos.response.planner import (
    PLANNERS,
    Plan,
    PlanError,
    choose_forecast,
    containment_region,
    reshare,
    transit_route,
)

IDLE = "IDLE"
STATION_KEEPING = "STATION-KEEPING"
STARTING_POSITION = "STARTING-POSITION"
OIL_PATH = "OIL-PATH"


@dataclass
class Vehicle:
    """What the coordinator knows of one vehicle from its reports."""

    name: str
    x: float | None = None
    y: float | None = None
    last_seen: float = -math.inf
    dropped: bool = False


@dataclass
class Settings:
    """pPathAssign's parameters (see `PathAssign.example_config` for their meaning)."""

    standoff: float = 50.0
    patrol: str = "arcs"          # "arcs": each vessel its own arc, back and forth; "loop": all the whole loop
    coordinate_timeout: float = 30.0
    arrival_timeout: float = 600.0
    node_timeout: float = 20.0
    capture_radius: float = 10.0
    transit_speed: float = 2.0
    loop_speed: float = 0.0
    min_replan_interval: float = 10.0
    forecast_window: float = 5.0
    forecast_horizons: tuple[float, ...] = (3.0, 7.0, 11.0, 15.0)
    replan_distance: float = 25.0
    heartbeat_interval: float = 5.0
    status_interval: float = 2.0
    fleet: tuple[str, ...] = ()
    operating_area: Polygon | None = None


@dataclass
class Coordinator:
    """The phase machine: STATION-KEEPING -> STARTING-POSITION -> OIL-PATH, restarted by each boundary.

    Sans-I/O: the shell feeds it mail and MOOS time, and drains `outbox`
    (MOOS variable, value) pairs; per-vehicle variables carry the vehicle's
    upper-case name as suffix so uFldShoreBroker's qbridge routes them.
    """

    settings: Settings = field(default_factory=Settings)
    phase: str = IDLE
    seq: int = 0
    cycles: int = 0     # forecast cycles accepted; the horizons of one forecast share one
    vehicles: dict[str, Vehicle] = field(default_factory=dict)
    forecasts: dict[float, Boundary] = field(default_factory=dict)
    forecast_seq: dict[float, int] = field(default_factory=dict)  # the line (seq) each horizon came in
    forecast_time: float | None = None  # issue time of the forecast in force
    boundary_received: float | None = None
    window_closes: float = math.inf   # when the horizon is chosen even if not every expected one is in
    decision: tuple[dict[str, tuple[float, float]], float] | None = None  # positions and age the choice used
    horizon: float | None = None      # the horizon in force (OILSPILL_BOUNDARY)
    plan: Plan | None = None
    reported: dict[str, tuple[float, float]] = field(default_factory=dict)
    arrived: set[str] = field(default_factory=set)
    patrolling: set[str] = field(default_factory=set)  # sent their OIL_PATH_UPDATES for the plan in force
    phase_started: float = 0.0
    coordinate_deadline: float = math.inf
    outbox: list[tuple[str, str | float]] = field(default_factory=list)
    _last_heartbeat: float = -math.inf
    _last_status: float = -math.inf
    _last_cycle: float = -math.inf
    _boundary_seq: int = 0

    def __post_init__(self):
        for name in self.settings.fleet:
            self.vehicles.setdefault(name, Vehicle(name))

    # ---- input ---------------------------------------------------------------------------

    def offer_boundary(self, boundary: Boundary, now: float) -> int:
        """Accept a boundary line or raise BoundaryError; the boundary in force stays on error.

        A forecast cycle (the lines sharing an issue time, one per horizon) is one decision: its
        first line halts the fleet, the horizon is chosen once every `forecast_horizons` is in or
        `forecast_window` has passed (and the positions are in); a line of the cycle arriving after
        that re-runs the choice on the same inputs and restarts the phases only if the stand-off
        loop it leads to lies more than `replan_distance` from the loop in force.
        """
        self._checked_region(boundary)
        issued = boundary.issued
        same_forecast = issued is not None and self.forecast_time is not None \
            and abs(issued - self.forecast_time) < 1.0
        if not same_forecast:
            if self.forecast_time is not None and issued is not None and issued < self.forecast_time:
                raise BoundaryError(f"forecast issued at {issued:.0f} is older than the one in force "
                                    f"({self.forecast_time:.0f})")
            wait = self._last_cycle + self.settings.min_replan_interval - now
            if wait > 0:
                raise BoundaryError(f"boundary flood: the last one is {now - self._last_cycle:.1f} s old, "
                                    f"next accepted in {wait:.1f} s")
            self.forecasts, self.forecast_seq, self.decision = {}, {}, None
            self.cycles += 1
            self._last_cycle = now
        self.forecast_time = issued
        self.seq += 1
        self.forecasts[boundary.horizon_h] = boundary
        self.forecast_seq[boundary.horizon_h] = self.seq
        self._post("OILSPILL_FORECAST", format_forecast(boundary, self.cycles))
        if not same_forecast:
            self.boundary_received = now
            self.window_closes = now if self._collected() else now + self.settings.forecast_window
            if self._collected():  # a lone line that nothing can join: it is the boundary in force already
                self._post_boundary(boundary.horizon_h)
            self._begin_station_keeping(now)
        elif self.decision is None:  # another horizon joins the cycle still collecting
            if self._collected():
                self.window_closes = now
            if self.phase == STATION_KEEPING:
                self._maybe_plan(now)
        else:
            self._reconsider(now)
        return self.seq

    def _collected(self) -> bool:
        """Nothing more to wait for: a line without a time stands alone, or every expected horizon is in."""
        return self.forecast_time is None or (
            bool(self.settings.forecast_horizons) and set(self.settings.forecast_horizons) <= set(self.forecasts))

    def _reconsider(self, now: float) -> None:
        """A late line of the cycle in force: the choice again on the inputs it was made with."""
        positions, age_h = self.decision
        horizon, plan = self._choose(positions, age_h)
        shift = plan.region.exterior.hausdorff_distance(self.plan.region.exterior)
        if shift <= self.settings.replan_distance:
            return
        self._post("OILSPILL_WARNING", f"late line of forecast cycle {self.cycles} moves the loop by {shift:.0f} m "
                                       f"(> replan_distance {self.settings.replan_distance:g}): re-planning")
        self.decision = None
        self.window_closes = now
        self._begin_station_keeping(now)

    def on_coordinates(self, text: str, now: float, community: str = "") -> None:
        """VEHICLE_COORDINATES="vname=abe,x=..,y=..,utc=..": counts once the current cycle has begun."""
        name, x, y = self._position_of(text, community)
        self._seen(name, x, y, now)
        if self.phase == STATION_KEEPING:
            self.reported[name] = (x, y)
            self._maybe_plan(now)

    def on_node_report(self, text: str, now: float, community: str = "") -> None:
        """NODE_REPORT keeps positions fresh, spots drop-outs coming back, and backs up arrival flags."""
        name, x, y = self._position_of(text, community)
        self._seen(name, x, y, now)
        if self.phase == STARTING_POSITION and self.plan and name in self.plan.starts:
            sx, sy = self.plan.starts[name]
            if math.hypot(x - sx, y - sy) <= self.settings.capture_radius:
                self.on_reached(name, now)

    def on_reached(self, name: str, now: float) -> None:
        """REACHED_STARTING_POSITION from `name`: a vessel with an arc of its own starts patrolling it
        at once; the last arrival starts the phase OIL-PATH (and, in loop mode, everyone's loops)."""
        if self.phase != STARTING_POSITION or not self.plan or name not in self.plan.starts:
            return
        self.arrived.add(name)
        if self.plan.arcs:
            self._send_patrol(name)
        if set(self.plan.starts) <= self.arrived:
            self._begin_oil_path(now)

    def tick(self, now: float) -> None:
        """Time-outs: vehicles that went silent, the coordinate wait, heartbeat and status."""
        for vehicle in self.vehicles.values():
            if not vehicle.dropped and now - vehicle.last_seen > self.settings.node_timeout \
                    and vehicle.last_seen > -math.inf:
                self._drop(vehicle, now)
        if self.phase == STATION_KEEPING:
            self._maybe_plan(now)
        elif self.phase == STARTING_POSITION and now - self.phase_started > self.settings.arrival_timeout:
            late = sorted(set(self.plan.starts) - self.arrived)
            self._post("OILSPILL_WARNING", f"arrival time-out: {':'.join(late)} not at the start; "
                                           f"looping anyway (they join the loop at their start)")
            self._begin_oil_path(now)
        if now - self._last_heartbeat >= self.settings.heartbeat_interval:
            self._last_heartbeat = now
            self._post("SHORE_HEARTBEAT_ALL", "true")
        if now - self._last_status >= self.settings.status_interval:
            self._last_status = now
            self._post("OILSPILL_STATUS", ",".join(f"{k}={v}" for k, v in self.status(now).items()))

    def status(self, now: float) -> dict[str, str | int | float]:
        active = sorted(v.name for v in self.vehicles.values() if not v.dropped)
        return {
            "phase": self.phase,
            "vehicles": ":".join(active),
            "reported": len(self.reported),
            "planned": len(self.plan.starts) if self.plan else 0,
            "arrived": len(self.arrived),
            "dropped": sum(v.dropped for v in self.vehicles.values()),
            "boundaries": self.seq,
            "cycle": self.cycles,
            "horizon": -1 if self.horizon is None else format_number(self.horizon, 3),
            "boundary_age": -1 if self.boundary_received is None else round(now - self.boundary_received, 1),
        }

    # ---- phases --------------------------------------------------------------------------

    def _begin_station_keeping(self, now: float) -> None:
        self._set_phase(STATION_KEEPING, now)
        self.reported = {}
        self.arrived = set()
        self.coordinate_deadline = now + self.settings.coordinate_timeout
        self._post("STATION_KEEP_ALL", "true")
        self._post("OILSPILL_PHASE_ALL", STATION_KEEPING)
        self._post("REPORT_COORDINATES_ALL", str(self.seq))

    def _maybe_plan(self, now: float) -> None:
        expected = {v.name for v in self.vehicles.values() if not v.dropped}
        if not self.reported:
            if now >= self.coordinate_deadline:  # nobody answered: ask again rather than plan for no one
                self.coordinate_deadline = now + self.settings.coordinate_timeout
                self._post("REPORT_COORDINATES_ALL", str(self.seq))
            return
        if now < self.window_closes:  # more horizons of this forecast may still come
            return
        if expected <= set(self.reported) or now >= self.coordinate_deadline:
            positions = dict(self.reported)
            self.decision = (positions, (now - self.boundary_received) / 3600.0)  # the wait already used up
            horizon, plan = self._choose(*self.decision)
            self._post_boundary(horizon)
            self._assign_starts(plan, now)

    def _choose(self, positions: dict[str, tuple[float, float]], age_h: float) -> tuple[float, Plan]:
        """With several horizons of one forecast on offer, aim at the one matching the fleet's arrival."""
        planner = PLANNERS[self.settings.patrol]
        if len(self.forecasts) == 1:
            ((horizon, boundary),) = self.forecasts.items()
            return horizon, planner(containment_region(boundary.polygon, self.settings.standoff), positions)
        choice = choose_forecast({h: b.polygon for h, b in self.forecasts.items()}, positions,
                                 {name: self.settings.transit_speed for name in positions},
                                 self.settings.standoff, age_h, planner)
        return choice.horizon_h, choice.plan

    def _post_boundary(self, horizon: float) -> None:
        """OILSPILL_BOUNDARY: the outline the fleet is sent around, posted when it changes."""
        if self.horizon == horizon and self._boundary_seq == self.forecast_seq[horizon]:
            return
        self.horizon, self._boundary_seq = horizon, self.forecast_seq[horizon]
        self._post("OILSPILL_BOUNDARY", polygon_string(self.forecasts[horizon].polygon, f"oilspill_{self._boundary_seq}"))

    def _assign_starts(self, plan: Plan, now: float) -> None:
        self.plan = plan
        self.arrived, self.patrolling = set(), set()
        self._set_phase(STARTING_POSITION, now)
        self._post("VIEW_POLYGON", polygon_string(plan.region, "standoff", edge_color="orange"))
        for name, start in plan.starts.items():
            suffix = name.upper()
            vehicle = self.vehicles[name]
            route = [start] if vehicle.x is None else transit_route(plan.region, (vehicle.x, vehicle.y), start)
            self._post(f"STARTING_POSITION_UPDATES_{suffix}", points_update(route))
            self._post(f"STATION_KEEP_{suffix}", "false")
            self._post(f"OILSPILL_PHASE_{suffix}", STARTING_POSITION)
        for name in plan.starts:  # someone may already be sitting on their point
            vehicle = self.vehicles[name]
            if vehicle.x is not None and math.hypot(vehicle.x - plan.starts[name][0],
                                                    vehicle.y - plan.starts[name][1]) <= self.settings.capture_radius:
                self.on_reached(name, now)

    def _begin_oil_path(self, now: float) -> None:
        self._set_phase(OIL_PATH, now)
        for name in self.plan.starts:
            self._send_patrol(name)

    def _send_patrol(self, name: str) -> None:
        """The waypoints `name` repeats for ever: its arc back and forth, or the whole loop."""
        if name in self.patrolling:
            return
        self.patrolling.add(name)
        speed = {"speed": self.settings.loop_speed} if self.settings.loop_speed > 0 else {}
        suffix = name.upper()
        self._post(f"OIL_PATH_UPDATES_{suffix}", points_update(self.plan.loop(name), repeat="forever", **speed))
        self._post(f"STATION_KEEP_{suffix}", "false")
        self._post(f"OILSPILL_PHASE_{suffix}", OIL_PATH)

    def _reshare(self, now: float) -> None:
        """Spread the loop over whoever is reporting now; they go to new starts, then loop again."""
        positions = {v.name: (v.x, v.y) for v in self.vehicles.values() if not v.dropped and v.x is not None}
        if not positions:
            self._post("OILSPILL_WARNING", "no vehicle left to re-share the loop with")
            return
        self._assign_starts(reshare(self.plan, positions), now)

    def _drop(self, vehicle: Vehicle, now: float) -> None:
        vehicle.dropped = True
        self.reported.pop(vehicle.name, None)
        self._post("OILSPILL_DROPPED", vehicle.name)
        if self.phase in (STARTING_POSITION, OIL_PATH) and self.plan and vehicle.name in self.plan.starts:
            self._reshare(now)

    def _seen(self, name: str, x: float, y: float, now: float) -> None:
        vehicle = self.vehicles.setdefault(name, Vehicle(name))
        first_heard = vehicle.x is None
        vehicle.x, vehicle.y, vehicle.last_seen = x, y, now
        rejoined = vehicle.dropped
        if rejoined:
            vehicle.dropped = False
            self._post("OILSPILL_REJOINED", name)
            self._post(f"COMMS_LOST_{name.upper()}", "false")
            self._post(f"DEPLOY_{name.upper()}", "true")  # its watchdog may have parked it at base
        if self.phase in (STARTING_POSITION, OIL_PATH) and self.plan:
            # A first report can be the only one able to take over starts whose vehicles were dropped
            # while it was still silent (the re-share then found nobody).
            orphaned = any(self.vehicles[v].dropped for v in self.plan.starts)
            if rejoined or (first_heard and orphaned):
                self._reshare(now)
        elif rejoined and self.phase == STATION_KEEPING:
            self._post(f"REPORT_COORDINATES_{name.upper()}", str(self.seq))

    # ---- helpers -------------------------------------------------------------------------

    def _checked_region(self, boundary: Boundary) -> Polygon:
        try:
            region = containment_region(boundary.polygon, self.settings.standoff)
        except PlanError as exc:
            raise BoundaryError(str(exc)) from None
        area = self.settings.operating_area
        if area is not None and not region.intersects(area):
            centre = region.centroid
            raise BoundaryError(f"polygon (centre {centre.x:.0f},{centre.y:.0f}) lies outside the operating area")
        return region

    def _position_of(self, text: str, community: str) -> tuple[str, float, float]:
        fields = parse_report(text)
        name = fields.get("vname") or fields.get("name") or community
        if not name:
            raise ValueError(f"report without a vehicle name: {text!r}")
        try:
            return name.lower(), float(fields["x"]), float(fields["y"])
        except (KeyError, ValueError):
            raise ValueError(f"report from {name} without numeric x,y: {text!r}") from None

    def _set_phase(self, phase: str, now: float) -> None:
        self.phase = phase
        self.phase_started = now
        self._post("OILSPILL_PHASE", phase)

    def _post(self, key: str, value: str | float) -> None:
        self.outbox.append((key, value))

    def drain(self) -> list[tuple[str, str | float]]:
        posts, self.outbox = self.outbox, []
        return posts


MAX_LINE = 1 << 20  # a forecast outline of ~20000 vertices; longer lines are refused, not buffered


PATH_ASSIGN_PARAMS = Params(
    Param("boundary_host", str, "127.0.0.1", "TCP boundary server address (loopback unless you mean it)"),
    Param("boundary_port", int, 9100, "its port", 0, 65535),
    Param("fleet", str, "", "expected vehicles, abe:ben:cal; empty: whoever reports"),
    Param("standoff", float, 50.0, "metres the loop stays outside the predicted boundary", lo=0),
    Param("patrol", str, "arcs", "arcs: each vessel its own arc, back and forth; loop: all the whole loop"),
    Param("coordinate_timeout", float, 30.0, "s to wait for every VEHICLE_COORDINATES before planning", lo=0),
    Param("arrival_timeout", float, 600.0, "s after which the loops start even if someone is not at its point", lo=0),
    Param("node_timeout", float, 20.0, "s without NODE_REPORT before a vehicle is dropped", lo=0),
    Param("capture_radius", float, 10.0, "m from its start that counts as arrived (backs up the flag)", lo=0),
    Param("transit_speed", float, 2.0, "m/s used to estimate arrival when choosing a forecast horizon", lo=1e-3),
    Param("loop_speed", float, 0.0, "m/s sent with the loops; 0 keeps the vehicles' own setting", lo=0),
    Param("min_replan_interval", float, 10.0, "s between accepted boundaries of different forecasts", lo=0),
    Param("forecast_window", float, 5.0, "s to collect the lines (horizons) of one forecast before choosing", lo=0),
    Param("forecast_horizons", str, "3:7:11:15", "h a forecast brings; once all are in the choice need not wait"),
    Param("replan_distance", float, 25.0, "m a late line of the forecast in force must move the loop to re-plan", lo=0),
    Param("heartbeat_interval", float, 5.0, "s between SHORE_HEARTBEAT_ALL posts (vehicle watchdogs)", lo=0.1),
    Param("status_interval", float, 2.0, "s between OILSPILL_STATUS posts", lo=0.1),
    Param("operating_area", str, "", "pts={x,y:...}: boundaries must touch it; empty: use the radius"),
    Param("operating_radius", float, 0.0, "m about the origin boundaries must touch; 0: anywhere", lo=0),
)


class PathAssign(MOOSApp):
    """pPathAssign: receives predicted spill boundaries over TCP (one JSON or pts={} line each,
    answered `OK <seq>` or `ERR <reason>`) and leads the fleet through STATION-KEEPING ->
    STARTING-POSITION -> OIL-PATH around the stand-off perimeter (each vessel patrolling its own
    arc, or all running the whole loop), re-sharing it when a vehicle drops out or comes back."""

    default_name = "pPathAssign"
    parameters = PATH_ASSIGN_PARAMS
    example_config = """\
ProcessConfig = pPathAssign
{
  AppTick   = 4
  CommsTick = 4

  boundary_host       = 127.0.0.1   // TCP boundary server address (loopback unless you mean it)
  boundary_port       = 9100        // its port
  fleet               =             // expected vehicles, abe:ben:cal; empty: whoever reports
  standoff            = 50          // metres the loop stays outside the predicted boundary
  patrol              = arcs        // arcs: each vessel its own arc, back and forth; loop: all the whole loop
  coordinate_timeout  = 30          // s to wait for every VEHICLE_COORDINATES before planning
  arrival_timeout     = 600         // s after which the loops start even if someone is not at its point
  node_timeout        = 20          // s without NODE_REPORT before a vehicle is dropped
  capture_radius      = 10          // m from its start that counts as arrived (backs up the flag)
  transit_speed       = 2.0         // m/s used to estimate arrival when choosing a forecast horizon
  loop_speed          = 0           // m/s sent with the loops; 0 keeps the vehicles' own setting
  min_replan_interval = 10          // s between accepted boundaries of different forecasts
  forecast_window     = 5           // s to collect the lines (horizons) of one forecast before choosing
  forecast_horizons   = 3:7:11:15   // h a forecast brings; once all are in the choice need not wait
  replan_distance     = 25          // m a late line of the forecast in force must move the loop to re-plan
  heartbeat_interval  = 5           // s between SHORE_HEARTBEAT_ALL posts (vehicle watchdogs)
  status_interval     = 2           // s between OILSPILL_STATUS posts
  operating_area      =             // pts={x,y:...}: boundaries must touch it; empty: use the radius
  operating_radius    = 0           // m about the origin boundaries must touch; 0: anywhere
}
"""
    interface = """\
SUBSCRIPTIONS:
  VEHICLE_COORDINATES          "vname=abe,x=..,y=..,utc=.." (pCoordinates, bridged)
  NODE_REPORT                  positions and liveness of every vehicle (bridged)
  REACHED_STARTING_POSITION*   arrival flags; the vehicle is the _<NAME> suffix, the
                               value (if not "true") or the message's community

PUBLICATIONS:
  OILSPILL_BOUNDARY            pts={...},label=oilspill_<seq>: the boundary in force (the horizon
                               chosen for the fleet; <seq> is the line it came in), posted when it changes
  OILSPILL_FORECAST            every accepted line, for viewers: cycle=<n>,horizon=<h>,
                               [valid=<utc s>,]uncertainty=<m>,source=<name>,pts={x,y:...}
                               (local metres; the horizons of one forecast share the cycle)
  VIEW_POLYGON                 the stand-off loop in force (label=standoff), for viewers
  OILSPILL_PHASE               STATION-KEEPING | STARTING-POSITION | OIL-PATH
  STATION_KEEP_ALL, STATION_KEEP_<V>       true on a new boundary, false when moving on
  OILSPILL_PHASE_ALL, OILSPILL_PHASE_<V>   the phase each vehicle should be in
  REPORT_COORDINATES_ALL, REPORT_COORDINATES_<V>   asks pCoordinates to report
  STARTING_POSITION_UPDATES_<V>  "points=x,y[:...]": the route to its start (the last point),
                               around the stand-off loop when the straight line would cross it
  OIL_PATH_UPDATES_<V>         "points=x,y:...#repeat=forever[#speed=..]"
  SHORE_HEARTBEAT_ALL          true every heartbeat_interval (vehicle comms watchdog)
  COMMS_LOST_<V>, DEPLOY_<V>   false / true when a dropped vehicle is heard again
  OILSPILL_DROPPED, OILSPILL_REJOINED   vehicle names
  OILSPILL_STATUS              phase=..,vehicles=a:b,reported=..,planned=..,arrived=..,
                               dropped=..,boundaries=..,cycle=..,horizon=..,boundary_age=..
  OILSPILL_WARNING             a refused boundary line, a report that made no sense, an arrival
                               time-out, a late line of the forecast in force that re-plans
"""

    def on_startup(self) -> None:
        v = self.settings = self.read_settings()
        fleet = tuple(n.lower() for n in re.split(r"[\s:,]+", v["fleet"]) if n)
        same = ("standoff", "coordinate_timeout", "arrival_timeout", "node_timeout", "capture_radius", "transit_speed",
                "loop_speed", "min_replan_interval", "forecast_window", "replan_distance", "heartbeat_interval",
                "status_interval")
        self.coordinator = Coordinator(Settings(forecast_horizons=self._horizons(v["forecast_horizons"]), fleet=fleet,
                                                operating_area=self._operating_area(), patrol=self._patrol(v["patrol"]),
                                                **{k: v[k] for k in same}))
        lat = self.mission.lat_origin if self.mission is not None else None
        lon = self.mission.long_origin if self.mission is not None else None
        self.grid = LocalGrid(lat, lon) if lat is not None and lon is not None else None

    @staticmethod
    def _patrol(text: str) -> str:
        patrol = text.strip().lower()
        if patrol not in PLANNERS:
            raise ValueError(f"patrol: {text!r} must be one of {', '.join(PLANNERS)}")
        return patrol

    @staticmethod
    def _horizons(text: str) -> tuple[float, ...]:
        try:
            horizons = tuple(float(h) for h in re.split(r"[\s:,]+", text) if h)
        except ValueError:
            raise ValueError(f"forecast_horizons: {text!r} is not a list of hours like 3:7:11:15") from None
        if not all(math.isfinite(h) and h >= 0 for h in horizons):
            raise ValueError(f"forecast_horizons: {text!r} holds a negative or non-finite hour")
        return horizons

    def _operating_area(self) -> Polygon | None:
        try:
            return operating_area(self.settings["operating_area"], self.settings["operating_radius"])
        except BoundaryError as exc:
            raise ValueError(f"operating_area: {exc}") from None

    def on_connect(self) -> None:
        self.register("VEHICLE_COORDINATES")
        self.register("NODE_REPORT")
        self.register_wildcard("REACHED_STARTING_POSITION*")

    async def run_async(self):
        """The boundary server shares the app's event loop; a port in use stops the app with its error."""
        settings = self.read_settings()
        self.boundary_host, self.boundary_port = settings["boundary_host"], settings["boundary_port"]
        self.lines_ok = self.lines_refused = 0
        server = await asyncio.start_server(self._serve, self.boundary_host, self.boundary_port, limit=MAX_LINE)
        self.boundary_port = server.sockets[0].getsockname()[1]
        async with server:
            await super().run_async()

    # ---- TCP boundary server -------------------------------------------------------------

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        peer = writer.get_extra_info("peername")
        client = f"{peer[0]}:{peer[1]}" if peer else "tcp client"
        try:
            while (raw := await _read_line(reader)) != b"":
                if raw is None:
                    reply = self._refuse(client, f"line longer than {MAX_LINE} bytes")
                else:
                    reply = self.accept_line(raw, client)
                writer.write(reply.encode() + b"\n")
                await writer.drain()
        except ConnectionError:
            pass
        finally:
            writer.close()

    def accept_line(self, raw: bytes, client: str = "tcp client") -> str:
        """One boundary line -> the reply; a refusal leaves the boundary in force alone."""
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            return self._refuse(client, "line is not UTF-8")
        try:
            seq = self.coordinator.offer_boundary(parse_boundary_line(text, self.grid), self.moos_time())
        except BoundaryError as exc:
            return self._refuse(client, str(exc))
        self.lines_ok += 1
        self._flush()
        return f"OK {seq}"

    def _refuse(self, client: str, reason: str) -> str:
        self.lines_refused += 1
        self.notify("OILSPILL_WARNING", f"{client}: {reason}")
        return f"ERR {reason}"

    # ---- MOOS side -----------------------------------------------------------------------

    def on_new_mail(self, mail) -> None:
        now = self.moos_time()
        for msg in mail:
            try:
                if msg.key == "VEHICLE_COORDINATES":
                    self.coordinator.on_coordinates(str(msg.value), now, msg.community)
                elif msg.key == "NODE_REPORT":
                    self.coordinator.on_node_report(str(msg.value), now, msg.community)
                elif msg.key.startswith("REACHED_STARTING_POSITION"):
                    self.coordinator.on_reached(_arrival_name(msg), now)
            except ValueError as exc:
                self.notify("OILSPILL_WARNING", f"{msg.key} from {msg.sender}: {exc}")
        self._flush()

    def iterate(self) -> None:
        self.coordinator.tick(self.moos_time())
        self._flush()

    def _flush(self) -> None:
        for key, value in self.coordinator.drain():
            self.notify(key, value)

    def status_fields(self) -> dict:
        return {**self.coordinator.status(self.moos_time()), "port": self.boundary_port,
                "lines_ok": self.lines_ok, "lines_refused": self.lines_refused}


def _arrival_name(msg) -> str:
    """REACHED_STARTING_POSITION_ABE names the vehicle; a plain flag names it by value or community."""
    suffix = msg.key[len("REACHED_STARTING_POSITION"):].lstrip("_")
    value = str(msg.value).strip()
    name = suffix or (value if value.lower() not in ("true", "") else msg.community)
    if not name:
        raise ValueError("arrival flag without a vehicle name")
    return name.lower()


async def _read_line(reader: asyncio.StreamReader) -> bytes | None:
    """The next line (b"" at the end), or None for a line over MAX_LINE, which is read and thrown away."""
    try:
        return await reader.readuntil(b"\n")
    except asyncio.IncompleteReadError as exc:
        return exc.partial
    except asyncio.LimitOverrunError as exc:
        await reader.readexactly(exc.consumed)
    while True:
        try:
            await reader.readuntil(b"\n")
            return None
        except asyncio.IncompleteReadError:
            return None
        except asyncio.LimitOverrunError as exc:
            await reader.readexactly(exc.consumed)


main = PathAssign.main
