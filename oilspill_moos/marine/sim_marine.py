"""uSimMarine: the 3-DOF kinematic boat model of uSimMarineV22 and its MOOS app, and the
deprecated uSimMarine as a variant of it (`SimMarineDeprecated`).

The model (`MarineModel`) is pure: rudder/thrust in, state out, time step given.
It reproduces the reference simulator's arithmetic (docs/spec/field-apps.md section 1),
including its quirks, so a mission flies the same laps in our stack as in C++.
"""
from __future__ import annotations

import logging
import math
from bisect import bisect_right
from dataclasses import dataclass, field, replace


from moosdb_py.app import MOOSApp
from moosdb_py.formats import format_number
from moosdb_py.config import ConfigLike, ConfigValueError, Param, Params, parse_bool, parse_float, read_params
from moosdb_py.geodesy import mission_grid

log = logging.getLogger("oilspill_moos.marine.sim_marine")

# The speed at which the turn rate reaches its configured value (the reference
# simulator's internal "full speed" of its turn-rate map).
TURN_RATE_FULL_SPEED = 5.0


@dataclass
class NavState:
    x: float = 0.0
    y: float = 0.0
    heading: float = 0.0
    speed: float = 0.0
    depth: float = 0.0

    @classmethod
    def parse(cls, text: str, what: str = "start_pos") -> "NavState":
        """`x=0, y=-20, heading=180, speed=0[, depth=0]`, positional `x,y,heading,speed[,depth]`, or a mix:
        a bare number is the field of its position, as MOOS-IvP reads `start_pos = x=0,y=0,heading=0, 0`
        (m2_berta's `$(START_POS), 0`: speed 0)."""
        parts = [p.strip() for p in str(text).split(",") if p.strip()]
        names = ("x", "y", "heading", "speed", "depth")
        if not parts or len(parts) > len(names):
            raise ConfigValueError(what, f"expected 'x=.., y=.., heading=.., speed=..' or 'x,y,heading,speed', got {text!r}")
        values: dict[str, float] = {}
        for index, part in enumerate(parts):
            key, eq, value = part.partition("=")
            key, value = (key.strip().lower(), value.strip()) if eq else (names[index], part)
            if key not in names:
                raise ConfigValueError(what, f"unknown field {key!r} (expected {', '.join(names)})")
            values[key] = parse_float(value, f"{what} {key}")
        state = cls(**values)
        state.heading = angle360(state.heading)
        return state


class ThrustMap:
    """Thrust (-100..100) to speed: piecewise linear over `thrust:speed` pairs, (0,0) implied."""

    def __init__(self, pairs: list[tuple[float, float]] | None = None, thrust_factor: float = 20.0,
                 reflect: bool = False):
        self.thrust_factor = thrust_factor
        self.reflect = reflect
        table = dict(pairs or [])
        if table:
            table.setdefault(0.0, 0.0)
        self.thrusts = tuple(sorted(table))     # tuples: one scalar a step, where numpy costs more than it does
        self.speeds = tuple(table[k] for k in self.thrusts)

    @classmethod
    def parse(cls, text: str, thrust_factor: float = 20.0, reflect: bool = False) -> "ThrustMap":
        pairs = []
        for item in str(text).split(","):
            if not item.strip():
                continue
            thrust, sep, speed = item.partition(":")
            if not sep:
                raise ConfigValueError("thrust_map", f"{item.strip()!r} is not a thrust:speed pair")
            pairs.append((parse_float(thrust, "thrust_map thrust", -100.0, 100.0),
                          parse_float(speed, "thrust_map speed")))
        thrusts = [t for t, _ in pairs]
        if len(set(thrusts)) != len(thrusts):
            raise ConfigValueError("thrust_map", "a thrust value appears twice")
        ordered = sorted(pairs)
        if any(b[1] < a[1] for a, b in zip(ordered, ordered[1:])):
            raise ConfigValueError("thrust_map", "speed must not fall as thrust rises")
        return cls(pairs, thrust_factor, reflect)

    @property
    def empty(self) -> bool:
        return not self.thrusts

    def speed(self, thrust: float) -> float:
        if self.empty:
            return thrust / self.thrust_factor if self.thrust_factor else 0.0
        if thrust < 0.0 and self.reflect:
            return -self.speed(-thrust)
        thrusts, speeds = self.thrusts, self.speeds
        if thrust < 0.0 and thrusts[0] >= 0.0:
            return 0.0
        if thrust <= thrusts[0]:
            return speeds[0]
        if thrust >= thrusts[-1]:
            return speeds[-1]
        j = bisect_right(thrusts, thrust) - 1      # np.interp's segment and arithmetic, to the bit
        if thrust == thrusts[j]:                   # as np.interp: a knot's own speed, never inf x 0
            return speeds[j]
        slope = (speeds[j + 1] - speeds[j]) / (thrusts[j + 1] - thrusts[j])
        speed = slope * (thrust - thrusts[j]) + speeds[j]
        if math.isnan(speed):                      # a subnormal gap: np.interp tries the other end
            speed = slope * (thrust - thrusts[j + 1]) + speeds[j + 1]
        return speed


@dataclass
class SimParams:
    """The uSimMarineV22 ProcessConfig parameters the model and app use."""

    start: NavState = field(default_factory=NavState)
    prefix: str = "USM"
    turn_rate: float = 70.0
    thrust_map: ThrustMap = field(default_factory=ThrustMap)
    max_acceleration: float = 0.0
    max_deceleration: float = 0.5
    turn_spd_loss: float = 0.85
    max_speed: float = 5.0
    max_rudder_degs_per_sec: float = 0.0
    drift_x: float = 0.0
    drift_y: float = 0.0
    rotate_speed: float = 0.0
    buoyancy_rate: float = 0.025
    max_depth_rate: float = 0.5
    max_depth_rate_speed: float = 2.0
    water_depth: float = 0.0
    sim_pause: bool = False
    turn_speed_map: bool = True   # V22: the turn rate grows with speed, full at TURN_RATE_FULL_SPEED
    nav_interval: int = 2         # iterations between NAV_* posts (V22: every second one)

    @classmethod
    def from_config(cls, cfg: ConfigLike) -> "SimParams":
        v = SIM_PARAMS.read(cfg)
        start = NavState.parse(v["start_pos"]) if v["start_pos"] else NavState()
        for name in ("x", "y", "heading", "speed", "depth"):
            if v[f"start_{name}"] is not None:
                setattr(start, name, v[f"start_{name}"])
        start.heading = angle360(start.heading)
        factor, reflect = v["thrust_factor"], v["thrust_reflect"]
        thrust_map = ThrustMap.parse(v["thrust_map"], factor, reflect) if v["thrust_map"] else ThrustMap(None, factor, reflect)
        drift_x, drift_y = v["drift_x"], v["drift_y"]
        if v["drift_vector"]:
            dx, dy = parse_drift_vector(v["drift_vector"], "drift_vector")
            drift_x, drift_y = drift_x + dx, drift_y + dy
        same = ("prefix", "turn_rate", "max_acceleration", "max_deceleration", "turn_spd_loss", "max_speed",
                "max_rudder_degs_per_sec", "rotate_speed", "buoyancy_rate", "max_depth_rate", "max_depth_rate_speed",
                "sim_pause")
        return cls(start=start, thrust_map=thrust_map, drift_x=drift_x, drift_y=drift_y,
                   water_depth=v["default_water_depth"], **{name: v[name] for name in same})


def parse_drift_vector(text: str, what: str) -> tuple[float, float]:
    """`ang,mag` (direction the water flows to, degrees; metres/second) -> (drift_x, drift_y)."""
    parts = str(text).split(",")
    if len(parts) != 2:
        raise ConfigValueError(what, f"expected 'angle,magnitude', got {text!r}")
    ang = parse_float(parts[0], f"{what} angle")
    mag = parse_float(parts[1], f"{what} magnitude")
    rad = math.radians(ang)
    return mag * math.sin(rad), mag * math.cos(rad)


def angle360(deg: float) -> float:
    """Degrees in [0, 360); a tiny negative angle would otherwise round to 360.0."""
    deg %= 360.0
    return 0.0 if deg >= 360.0 else deg


@dataclass
class StepResult:
    speed_over_ground: float
    heading_over_ground: float


class MarineModel:
    """The kinematic state and its update, one call of `step(dt)` per simulator Iterate."""

    def __init__(self, params: SimParams):
        self.params = params
        self.state = replace(params.start)
        self.rudder = 0.0
        self.thrust = 0.0
        self.elevator = 0.0
        self.drift_x = params.drift_x
        self.drift_y = params.drift_y
        self.rotate_speed = params.rotate_speed
        self.buoyancy_rate = params.buoyancy_rate
        self.turn_rate = params.turn_rate
        self.paused = params.sim_pause
        self._last_rudder_time: float | None = None

    def reset(self, state: NavState | None = None) -> None:
        self.state = replace(state or self.params.start)
        self.rudder = self.thrust = self.elevator = 0.0

    def set_rudder(self, desired: float, time: float) -> None:
        """Apply a DESIRED_RUDDER message; each message moves the rudder by a bounded amount."""
        desired = max(-100.0, min(100.0, desired))
        rate = self.params.max_rudder_degs_per_sec
        if rate > 0.0 and self._last_rudder_time is not None:
            limit = rate * max(0.0, time - self._last_rudder_time)
        else:
            limit = 100.0
        change = max(-limit, min(limit, desired - self.rudder))
        self.rudder += change
        self._last_rudder_time = time

    def set_thrust(self, desired: float) -> None:
        self.thrust = max(-100.0, min(100.0, desired))

    def set_elevator(self, desired: float) -> None:
        self.elevator = max(-100.0, min(100.0, desired))

    @property
    def drift_angle(self) -> float:
        return angle360(math.degrees(math.atan2(self.drift_x, self.drift_y)))

    @property
    def drift_magnitude(self) -> float:
        return math.hypot(self.drift_x, self.drift_y)

    def step(self, dt: float) -> StepResult:
        """Propagate by dt seconds of MOOS time (speed, heading, depth, then position)."""
        st, p = self.state, self.params
        if self.paused or dt <= 0.0:
            return StepResult(0.0, st.heading)
        v0, psi0 = st.speed, st.heading
        rudder = max(-100.0, min(100.0, self.rudder))

        # 1. speed
        v1 = p.thrust_map.speed(self.thrust)
        v1 *= 1.0 - (abs(rudder) / 100.0) * p.turn_spd_loss
        if v1 > v0 and p.max_acceleration > 0.0:
            v1 = min(v1, v0 + p.max_acceleration * dt)
        elif v1 < v0 and p.max_deceleration > 0.0:
            v1 = max(v1, v0 - p.max_deceleration * dt)

        # 2. heading: the turn rate grows with speed (V22) and scales with thrust/50
        if v1 > 0.0:
            scale = min(v1 / TURN_RATE_FULL_SPEED, 1.0) if p.turn_speed_map else 1.0
            rate = min(100.0, max(0.0, self.turn_rate * scale))
            turn = rudder * (rate / 100.0) * dt * (1.0 + (self.thrust - 50.0) / 50.0)
        else:
            turn = 0.0
        psi1 = angle360(psi0 + turn + self.rotate_speed * dt)

        # 3. depth: the elevator dives in proportion to speed; buoyancy lifts; never above 0
        speed_ratio = min(abs(v1) / p.max_depth_rate_speed, 1.0) if p.max_depth_rate_speed > 0 else 1.0
        dive_rate = (self.elevator / 100.0) * p.max_depth_rate * speed_ratio
        st.depth = max(0.0, st.depth + (dive_rate - self.buoyancy_rate) * dt)

        # 4. position with the mean heading and mean speed of the step
        r0, r1 = math.radians(psi0), math.radians(psi1)
        mean_heading = math.atan2(math.sin(r0) + math.sin(r1), math.cos(r0) + math.cos(r1))
        mean_speed = (v0 + v1) / 2.0
        vx = math.sin(mean_heading) * mean_speed + self.drift_x
        vy = math.cos(mean_heading) * mean_speed + self.drift_y
        st.x += vx * dt
        st.y += vy * dt
        st.heading = psi1
        st.speed = mean_speed  # the reference keeps the mean, so speed converges geometrically
        hog = angle360(math.degrees(math.atan2(vx, vy))) if (vx or vy) else psi1
        return StepResult(math.hypot(vx, vy), hog)


SIM_PARAMS = Params(
    Param("start_pos", str, "", "start state `x=0, y=0, heading=0, speed=0[, depth=0]` or `x,y,heading,speed[,depth]`"),
    *(Param(f"start_{name}", float, None, f"start {name}; wins over the same field of start_pos")
      for name in ("x", "y", "heading", "speed", "depth")),
    Param("prefix", str, "USM", "output prefix; missions use NAV"),
    Param("turn_rate", float, 70.0, "deg/s at full rudder, speed >= 5 m/s, thrust 50", 0.0, 100.0),
    Param("thrust_map", str, "", "thrust:speed pairs, e.g. `0:0, 20:1, 40:2, 60:3, 80:4, 100:5`"),
    Param("thrust_factor", float, 20.0, "speed = thrust / thrust_factor when there is no thrust_map", lo=0.0),
    Param("thrust_reflect", bool, False, "negative thrust mirrors the positive map"),
    Param("max_acceleration", float, 0.0, "m/s^2, 0 = unlimited", lo=0.0),
    Param("max_deceleration", float, 0.5, "m/s^2, 0 = unlimited", lo=0.0),
    Param("turn_spd_loss", float, 0.85, "fraction of speed lost at full rudder", 0.0, 1.0),
    Param("max_speed", float, 5.0, "NAV_SPEED is clipped to this", lo=0.0),
    Param("max_rudder_degs_per_sec", float, 0.0, "rudder rate limit, 0 = a message moves it by at most 100", lo=0.0),
    Param("drift_x", float, 0.0, "current, m/s east"),
    Param("drift_y", float, 0.0, "current, m/s north"),
    Param("drift_vector", str, "", "current as `angle,magnitude` (deg towards, m/s); added to drift_x/y"),
    Param("rotate_speed", float, 0.0, "deg/s of external rotation"),
    Param("buoyancy_rate", float, 0.025, "m/s, positive rises"),
    Param("max_depth_rate", float, 0.5, "m/s at full elevator", lo=0.0),
    Param("max_depth_rate_speed", float, 2.0, "speed at which the full depth rate is reached", lo=0.0),
    Param("default_water_depth", float, 0.0, "> 0 enables <prefix>_ALTITUDE", lo=0.0),
    Param("sim_pause", bool, False, "start paused (USM_SIM_PAUSED = false resumes)"),
)


class SimMarine(MOOSApp):
    """uSimMarine (uSimMarineV22): a simulated surface vehicle.

    Integrates the kinematic boat model every AppTick from the last DESIRED_RUDDER and
    DESIRED_THRUST, and posts the navigation solution (<prefix>_X, _Y, _HEADING, _SPEED,
    _DEPTH, _LAT, _LONG, ...) on every second iteration, as uSimMarineV22 does. Time is
    MOOS time, so MOOSTimeWarp speeds the simulation up. An external current can be set in
    the config (drift_x, drift_y, drift_vector) or at run time (DRIFT_X, DRIFT_VECTOR, ...).
    LatOrigin/LongOrigin in the mission enable <prefix>_LAT/_LONG.
    """

    default_name = "uSimMarine"
    parameters = SIM_PARAMS
    variant: dict = {}   # SimParams fields that set this app's model apart
    example_config = """\
ProcessConfig = uSimMarineV22
{
  AppTick   = 4
  CommsTick = 4

  start_pos   = x=0, y=0, heading=0, speed=0   // or x,y,heading,speed[,depth]
  // start_x = 0, start_y = 0, start_heading = 0, start_speed = 0, start_depth = 0
  prefix      = USM        // output prefix; missions use NAV
  turn_rate   = 70         // 0..100, deg/s at full rudder, speed >= 5 m/s, thrust 50
  thrust_map  =            // thrust:speed pairs, e.g. 0:0, 20:1, 40:2, 60:3, 80:4, 100:5
  thrust_factor  = 20      // speed = thrust / thrust_factor when there is no thrust_map
  thrust_reflect = false   // negative thrust mirrors the positive map
  max_acceleration = 0     // m/s^2, 0 = unlimited
  max_deceleration = 0.5   // m/s^2, 0 = unlimited
  turn_spd_loss    = 0.85  // 0..1, fraction of speed lost at full rudder
  max_speed        = 5     // NAV_SPEED is clipped to this
  max_rudder_degs_per_sec = 0   // rudder rate limit, 0 = a message moves it by at most 100
  drift_x      = 0         // current, m/s east
  drift_y      = 0         // current, m/s north
  drift_vector = 0,0       // current as angle(deg, towards),magnitude(m/s); added to drift_x/y
  rotate_speed = 0         // deg/s of external rotation
  buoyancy_rate        = 0.025  // m/s, positive rises
  max_depth_rate       = 0.5    // m/s at full elevator
  max_depth_rate_speed = 2.0    // speed at which the full depth rate is reached
  default_water_depth  = 0      // > 0 enables <prefix>_ALTITUDE
  sim_pause    = false     // start paused (USM_SIM_PAUSED = false resumes)
}
"""
    interface = """\
SUBSCRIPTIONS:
  DESIRED_RUDDER, DESIRED_THRUST, DESIRED_ELEVATOR   (double, -100..100)
  DRIFT_X, DRIFT_Y, CURRENT_X, CURRENT_Y             (double, m/s)
  DRIFT_VECTOR = ang,mag   DRIFT_VECTOR_ADD = ang,mag   DRIFT_VECTOR_MULT = factor
  ROTATE_SPEED (deg/s), BUOYANCY_RATE, WATER_DEPTH, USM_TURN_RATE
  USM_SIM_PAUSED = true|false
  USM_RESET = true | x=..,y=..,heading=..,speed=..   (back to the start or to that state)
PUBLICATIONS (every second iteration, with prefix NAV):
  NAV_X, NAV_Y, NAV_LAT, NAV_LONG, NAV_HEADING, NAV_SPEED, NAV_DEPTH,
  NAV_HEADING_OVER_GROUND, NAV_SPEED_OVER_GROUND, NAV_ALTITUDE (with a water depth)
  USM_RESET_COUNT, USM_DRIFT_SUMMARY (when they change)
"""

    def on_startup(self) -> None:
        self.params = replace(read_params(self.config, SimParams.from_config), **self.variant)
        self.model = MarineModel(self.params)
        self.water_depth = self.params.water_depth
        self.grid = mission_grid(self.mission)
        self.iteration = 0
        self.last_step_time: float | None = None
        self.last_result = StepResult(0.0, self.model.state.heading)
        self.reset_count = 0
        self._drift_summary_posted: str | None = None
        self._drift_posted: tuple[float, float] | None = None
        self._latlon: tuple[float, float, float, float] | None = None   # (x, y, lat, lon) last converted

    def on_connect(self) -> None:
        for key in SIM_INPUTS:
            self.register(key)

    def on_new_mail(self, mail) -> None:
        for msg in mail:
            try:
                self._handle(msg)
            except ValueError as err:
                log.warning("%s: %s from %s ignored: %s", self.name, msg.key, msg.source or "?", err)

    def _handle(self, msg) -> None:
        key, model = msg.key, self.model
        if key in ("DESIRED_RUDDER", "DESIRED_THRUST", "DESIRED_ELEVATOR", "DRIFT_X", "DRIFT_Y",
                   "CURRENT_X", "CURRENT_Y", "ROTATE_SPEED", "BUOYANCY_RATE", "WATER_DEPTH",
                   "USM_TURN_RATE", "DRIFT_VECTOR_MULT"):
            value = msg.double if msg.is_double() else parse_float(msg.string, key)
            if key == "DESIRED_RUDDER":
                model.set_rudder(value, msg.time)
            elif key == "DESIRED_THRUST":
                model.set_thrust(value)
            elif key == "DESIRED_ELEVATOR":
                model.set_elevator(value)
            elif key in ("DRIFT_X", "CURRENT_X"):
                model.drift_x = value
            elif key in ("DRIFT_Y", "CURRENT_Y"):
                model.drift_y = value
            elif key == "DRIFT_VECTOR_MULT":
                model.drift_x, model.drift_y = model.drift_x * value, model.drift_y * value
            elif key == "ROTATE_SPEED":
                model.rotate_speed = value
            elif key == "BUOYANCY_RATE":
                model.buoyancy_rate = value
            elif key == "WATER_DEPTH":
                self.water_depth = max(0.0, value)
            else:
                model.turn_rate = max(0.0, min(100.0, value))
        elif key in ("DRIFT_VECTOR", "DRIFT_VECTOR_ADD"):
            dx, dy = parse_drift_vector(msg.string, key)
            if key == "DRIFT_VECTOR_ADD":
                dx, dy = dx + model.drift_x, dy + model.drift_y
            model.drift_x, model.drift_y = dx, dy
        elif key == "USM_SIM_PAUSED":
            model.paused = parse_bool(msg.string if msg.is_string() else str(int(msg.double)), key)
        elif key == "USM_RESET":
            text = msg.string.strip() if msg.is_string() else ""
            model.reset(NavState.parse(text, key) if "=" in text or "," in text else None)
            self.reset_count += 1
            self.notify("USM_RESET_COUNT", float(self.reset_count))

    def iterate(self) -> None:
        now = self.moos_time()
        if self.last_step_time is not None:
            self.last_result = self.model.step(now - self.last_step_time)
        self.last_step_time = now
        self.iteration += 1
        if self.iteration % self.params.nav_interval == 0:
            self._post_nav(now)

    def _post_nav(self, now: float) -> None:
        s, prefix, notify = self.model.state, self.params.prefix, self.notify
        notify(prefix + "_X", s.x, now)
        notify(prefix + "_Y", s.y, now)
        if self.grid is not None:
            lat, lon = self._lat_lon(s.x, s.y)
            notify(prefix + "_LAT", lat, now)
            notify(prefix + "_LONG", lon, now)
        notify(prefix + "_HEADING", s.heading, now)
        notify(prefix + "_SPEED", min(round(s.speed, 2), self.params.max_speed), now)
        notify(prefix + "_DEPTH", s.depth, now)
        notify(prefix + "_HEADING_OVER_GROUND", self.last_result.heading_over_ground, now)
        notify(prefix + "_SPEED_OVER_GROUND", self.last_result.speed_over_ground, now)
        if self.water_depth > 0.0:
            notify(prefix + "_ALTITUDE", max(0.0, self.water_depth - s.depth), now)
        drift = (self.model.drift_x, self.model.drift_y)
        if drift != self._drift_posted:     # USM_DRIFT_SUMMARY when the current changes
            self._drift_posted = drift
            summary = (f"ang={format_number(self.model.drift_angle, 2)},mag={format_number(self.model.drift_magnitude, 2)},"
                       f"xmag={format_number(drift[0], 2)},ymag={format_number(drift[1], 2)}")
            if summary != self._drift_summary_posted:
                notify("USM_DRIFT_SUMMARY", summary, now)
                self._drift_summary_posted = summary

    def _lat_lon(self, x: float, y: float) -> tuple[float, float]:
        """The grid's lat/lon of (x, y), converted again only when the position moved (a vessel at rest, as
        most of a fleet is between tasks, posts the same position; a conversion is most of a NAV_* post)."""
        last = self._latlon
        if last is None or last[0] != x or last[1] != y:
            last = self._latlon = (x, y, *self.grid.to_latlon(x, y))
        return last[2], last[3]

    def status_fields(self) -> dict:
        s = self.model.state
        return {"x": round(s.x, 2), "y": round(s.y, 2), "hdg": round(s.heading, 1), "spd": round(s.speed, 2),
                "rudder": round(self.model.rudder, 1), "thrust": round(self.model.thrust, 1)}


SIM_INPUTS = ("DESIRED_RUDDER", "DESIRED_THRUST", "DESIRED_ELEVATOR", "DRIFT_X", "DRIFT_Y", "CURRENT_X",
              "CURRENT_Y", "DRIFT_VECTOR", "DRIFT_VECTOR_ADD", "DRIFT_VECTOR_MULT", "ROTATE_SPEED",
              "BUOYANCY_RATE", "WATER_DEPTH", "USM_TURN_RATE", "USM_SIM_PAUSED", "USM_RESET")


class SimMarineDeprecated(SimMarine):
    """uSimMarine, the simulator MOOS-IvP deprecated for uSimMarineV22: the same model, except that
    it turns at the full turn_rate at any speed (no turn-rate map), always loses 0.85 of its speed at
    full rudder (turn_spd_loss is V22's) and posts NAV_* on every iteration. Older missions that
    run `uSimMarine` fly as they did in C++.
    """

    variant = {"turn_speed_map": False, "turn_spd_loss": 0.85, "nav_interval": 1}
    example_config = SimMarine.example_config.replace("ProcessConfig = uSimMarineV22", "ProcessConfig = uSimMarine")
    interface = SimMarine.interface.replace("(every second iteration,", "(every iteration,")

    def on_startup(self) -> None:
        super().on_startup()
        if self.config.get("turn_spd_loss") is not None:
            log.warning("%s: turn_spd_loss is uSimMarineV22's; uSimMarine always loses 0.85 of its speed at "
                        "full rudder", self.name)


main = SimMarine.main
deprecated_main = SimMarineDeprecated.main
