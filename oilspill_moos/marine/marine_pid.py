"""pMarinePID: heading/speed (and optional depth) PID from DESIRED_* to DESIRED_RUDDER/THRUST.

`ScalarPID` and `PIDEngine` are pure and follow pMarinePIDV22's arithmetic
(docs/spec/field-apps.md section 2); `MarinePID` is the MOOS app around them.
"""
from __future__ import annotations

import logging
import math
from collections import deque
from dataclasses import dataclass, field

from moosdb_py.app import MOOSApp
from moosdb_py.config import ConfigLike, Param, Params, read_params
from moosdb_py.formats import FormatError, parse_bool

log = logging.getLogger("oilspill_moos.marine.marine_pid")

# The reference averages the derivative over this many recent finite differences.
DERIVATIVE_HISTORY = 9


def angle180(deg: float) -> float:
    """Wrap degrees into (-180, 180]."""
    deg = deg % 360.0
    return deg - 360.0 if deg > 180.0 else deg


@dataclass
class PIDGains:
    kp: float = 0.0
    kd: float = 0.0
    ki: float = 0.0
    integral_limit: float = 0.0

    @classmethod
    def from_values(cls, v: dict, prefix: str) -> "PIDGains":
        limit = v[f"{prefix}_integral_limit"]
        return cls(kp=v[f"{prefix}_kp"], kd=v[f"{prefix}_kd"], ki=v[f"{prefix}_ki"],
                   integral_limit=v[f"{prefix}_ki_limit"] if limit is None else limit)


def _gain_params(loop: str, what: str) -> tuple[Param, ...]:
    return (Param(f"{loop}_kp", float, 0.0, f"{what}: proportional gain"),
            Param(f"{loop}_kd", float, 0.0, f"{what}: derivative gain"),
            Param(f"{loop}_ki", float, 0.0, f"{what}: integral gain"),
            Param(f"{loop}_integral_limit", float, None, f"{what}: integral clip (default 0)", lo=0.0),
            Param(f"{loop}_ki_limit", float, 0.0, f"{what}: older name of {loop}_integral_limit", lo=0.0))


PID_PARAMS = Params(
    Param("depth_control", bool, True, "false for surface craft, else it waits for depth inputs"),
    Param("speed_factor", float, 0.0, "non-zero: thrust = DESIRED_SPEED * speed_factor, speed PID bypassed"),
    *_gain_params("yaw_pid", "heading loop (missing gains are 0: it never steers)"),
    *_gain_params("speed_pid", "speed loop (incremental: thrust += PID)"),
    *_gain_params("z_to_pitch_pid", "depth loop: depth error -> desired pitch"),
    *_gain_params("pitch_pid", "pitch error -> elevator"),
    Param("maxrudder", float, 100.0, "rudder clip", lo=0.0),
    Param("maxthrust", float, 100.0, "thrust clip", lo=0.0),
    Param("maxpitch", float, 15.0, "desired pitch clip", lo=0.0),
    Param("maxelevator", float, 13.0, "elevator clip", lo=0.0),
    Param("tardy_helm_threshold", float, 2.0, "s: older desired values make the PID stale", lo=0.0),
    Param("tardy_nav_threshold", float, 2.0, "s: older nav values make the PID stale", lo=0.0),
    Param("simulation", bool, False, "skip the staleness check (then it never gains control, as in MOOS)"),
    Param("ignore_nav_yaw", bool, False, "do not take the heading from NAV_YAW"),
    Param("pid_verbose", str, "", "accepted for compatibility"),
    Param("active_start", str, "", "accepted, no effect: MOOS_MANUAL_OVERRIDE=false starts it"),
)


class ScalarPID:
    """out = kp*e + kd*mean(recent de/dt) + I, clipped to +-output_limit."""

    def __init__(self, gains: PIDGains, output_limit: float):
        self.gains = gains
        self.output_limit = output_limit
        self.reset()

    def reset(self) -> None:
        self.integral = 0.0
        self.output = 0.0
        self._old_error = 0.0
        self._old_time: float | None = None
        self._diffs: deque[float] = deque(maxlen=DERIVATIVE_HISTORY)

    def run(self, error: float, time: float) -> float:
        g = self.gains
        if self._old_time is None:
            dt = 0.0
            derivative = 0.0
        else:
            dt = time - self._old_time
            if dt <= 0.0:
                return self.output
            self._diffs.append((error - self._old_error) / dt)
            derivative = sum(self._diffs) / len(self._diffs)
        if g.ki > 0.0:
            self.integral += g.ki * error * dt
            self.integral = max(-g.integral_limit, min(g.integral_limit, self.integral))
        else:
            self.integral = 0.0
        out = g.kp * error + g.kd * derivative + self.integral
        self.output = max(-self.output_limit, min(self.output_limit, out))
        self._old_error = error
        self._old_time = time
        return self.output


@dataclass
class PIDParams:
    yaw: PIDGains = field(default_factory=PIDGains)
    speed: PIDGains = field(default_factory=PIDGains)
    z_to_pitch: PIDGains = field(default_factory=PIDGains)
    pitch: PIDGains = field(default_factory=PIDGains)
    max_rudder: float = 100.0
    max_thrust: float = 100.0
    max_pitch: float = 15.0
    max_elevator: float = 13.0
    speed_factor: float = 0.0
    depth_control: bool = True
    tardy_helm_threshold: float = 2.0
    tardy_nav_threshold: float = 2.0
    simulation: bool = False
    ignore_nav_yaw: bool = False

    @classmethod
    def from_config(cls, cfg: ConfigLike) -> "PIDParams":
        v = PID_PARAMS.read(cfg)
        same = ("speed_factor", "depth_control", "tardy_helm_threshold", "tardy_nav_threshold", "simulation",
                "ignore_nav_yaw")
        return cls(yaw=PIDGains.from_values(v, "yaw_pid"), speed=PIDGains.from_values(v, "speed_pid"),
                   z_to_pitch=PIDGains.from_values(v, "z_to_pitch_pid"), pitch=PIDGains.from_values(v, "pitch_pid"),
                   max_rudder=v["maxrudder"], max_thrust=v["maxthrust"], max_pitch=v["maxpitch"],
                   max_elevator=v["maxelevator"], **{name: v[name] for name in same})


class PIDEngine:
    """The three loops of pMarinePID, with the reference's thrust and rudder rules."""

    def __init__(self, params: PIDParams):
        self.params = params
        self.speed_factor = params.speed_factor
        self.yaw_pid = ScalarPID(params.yaw, params.max_rudder)
        self.speed_pid = ScalarPID(params.speed, params.max_thrust)
        self.z_pid = ScalarPID(params.z_to_pitch, params.max_pitch)
        self.pitch_pid = ScalarPID(params.pitch, params.max_elevator)
        self.thrust = 0.0

    def reset(self) -> None:
        for pid in (self.yaw_pid, self.speed_pid, self.z_pid, self.pitch_pid):
            pid.reset()
        self.thrust = 0.0

    def desired_thrust(self, desired_speed: float, current_speed: float, time: float) -> float:
        if self.speed_factor != 0.0:
            thrust = desired_speed * self.speed_factor
        else:
            thrust = self.thrust + self.speed_pid.run(desired_speed - current_speed, time)
        if thrust < 0.01:
            thrust = 0.0
        self.thrust = min(thrust, self.params.max_thrust)
        return self.thrust

    def desired_rudder(self, desired_heading: float, current_heading: float, time: float) -> float:
        error = angle180(current_heading - angle180(desired_heading))
        rudder = -self.yaw_pid.run(error, time)
        limit = self.params.max_rudder
        return max(-limit, min(limit, rudder))

    def desired_elevator(self, desired_depth: float, current_depth: float, current_pitch: float,
                         time: float) -> float:
        """Too deep -> nose up (positive pitch) -> negative elevator, which the sim reads as rising."""
        desired_pitch = self.z_pid.run(current_depth - desired_depth, time)
        elevator = self.pitch_pid.run(current_pitch - desired_pitch, time)
        limit = self.params.max_elevator
        return max(-limit, min(limit, elevator))

    def control(self, desired_heading: float, desired_speed: float, heading: float, speed: float,
                time: float) -> tuple[float, float]:
        """(rudder, thrust) for one iteration; no rudder without thrust."""
        thrust = self.desired_thrust(desired_speed, speed, time)
        rudder = self.desired_rudder(desired_heading, heading, time) if thrust > 0.0 else 0.0
        return rudder, thrust


# (key, label in PID_STALE, threshold attribute) for the inputs whose age is checked.
STALENESS_CHECKS = (
    ("DESIRED_HEADING", "DesHdg", "tardy_helm_threshold"),
    ("DESIRED_SPEED", "DesSpd", "tardy_helm_threshold"),
    ("DESIRED_DEPTH", "DesDepth", "tardy_helm_threshold"),
    ("NAV_HEADING", "NavHdg", "tardy_nav_threshold"),
    ("NAV_SPEED", "NavSpd", "tardy_nav_threshold"),
    ("NAV_DEPTH", "NavDepth", "tardy_nav_threshold"),
)
NUMERIC_INPUTS = ("DESIRED_HEADING", "DESIRED_SPEED", "DESIRED_DEPTH", "NAV_HEADING", "NAV_SPEED", "NAV_DEPTH",
                  "NAV_PITCH", "NAV_YAW")
DEPTH_INPUTS = ("DESIRED_DEPTH", "NAV_DEPTH")
# Mail stamped further than this from our clock is from a confused process and is dropped.
MAX_MAIL_SKEW = 360.0


class MarinePID(MOOSApp):
    """pMarinePID (pMarinePIDV22): turns the helm's DESIRED_HEADING/SPEED into DESIRED_RUDDER/THRUST.

    Starts overridden: it drives only after MOOS_MANUAL_OVERRIDE = false (and stops, posting
    zeros once, on MOOS_MANUAL_OVERRIDE = true). While it has control it posts every
    iteration; outputs are zero until desired and nav values have all arrived, and while any
    of them is older than its tardy threshold (then PID_STALE says which). With speed_factor
    the thrust is DESIRED_SPEED * speed_factor; otherwise an incremental speed PID. Surface
    craft need depth_control = false.
    """

    default_name = "pMarinePID"
    parameters = PID_PARAMS
    example_config = """\
ProcessConfig = pMarinePIDV22
{
  AppTick   = 20
  CommsTick = 20

  depth_control = true       // false for surface craft, else it waits for depth inputs
  speed_factor  = 0          // non-zero: thrust = DESIRED_SPEED * speed_factor, speed PID bypassed

  yaw_pid_kp             = 0     // heading loop (missing gains are 0: it never steers)
  yaw_pid_kd             = 0
  yaw_pid_ki             = 0
  yaw_pid_integral_limit = 0     // alias yaw_pid_ki_limit
  speed_pid_kp             = 0   // speed loop (incremental: thrust += PID)
  speed_pid_kd             = 0
  speed_pid_ki             = 0
  speed_pid_integral_limit = 0
  z_to_pitch_pid_kp = 0          // depth loop: depth error -> desired pitch
  z_to_pitch_pid_kd = 0
  z_to_pitch_pid_ki = 0
  z_to_pitch_pid_integral_limit = 0
  pitch_pid_kp = 0               // pitch error -> elevator
  pitch_pid_kd = 0
  pitch_pid_ki = 0
  pitch_pid_integral_limit = 0

  maxrudder   = 100
  maxthrust   = 100
  maxpitch    = 15
  maxelevator = 13

  tardy_helm_threshold = 2.0     // s: older desired values make the PID stale
  tardy_nav_threshold  = 2.0     // s: older nav values make the PID stale
  simulation      = false        // skip the staleness check (then it never gains control, as in MOOS)
  ignore_nav_yaw  = false        // do not take the heading from NAV_YAW
  verbose         = false        // accepted for compatibility
  active_start    = false        // accepted, no effect: MOOS_MANUAL_OVERRIDE=false starts it
}
"""
    interface = """\
SUBSCRIPTIONS:
  DESIRED_HEADING, DESIRED_SPEED, DESIRED_DEPTH (from the helm)
  NAV_HEADING, NAV_SPEED, NAV_DEPTH, NAV_PITCH, NAV_YAW (from the simulator / navigation)
  MOOS_MANUAL_OVERRIDE (and the MOOS spelling MOOS_MANUAL_OVERIDE) = true|false
  SPEED_FACTOR (double: replaces the configured speed_factor)
PUBLICATIONS:
  DESIRED_RUDDER, DESIRED_THRUST (every iteration while it has control),
  DESIRED_ELEVATOR (with depth_control)
  PID_HAS_CONTROL = true|false, PID_STALE = "Stale DesHdg:2.61 ..." when inputs become old
"""

    def on_startup(self) -> None:
        self.params = read_params(self.config, PIDParams.from_config)
        self.engine = PIDEngine(self.params)
        self.overridden = True
        self.values: dict[str, float] = {}
        self.times: dict[str, float] = {}
        self.stale_report = ""
        self._required_inputs = frozenset(self._required())
        self._staleness_checks = [(key, label, getattr(self.params, limit)) for key, label, limit in STALENESS_CHECKS
                                  if key in self._required_inputs]

    def on_connect(self) -> None:
        for key in (*NUMERIC_INPUTS, "MOOS_MANUAL_OVERRIDE", "MOOS_MANUAL_OVERIDE", "SPEED_FACTOR"):
            self.register(key)

    def on_new_mail(self, mail) -> None:
        now = self.moos_time()
        for msg in mail:
            if msg.time > 0 and abs(now - msg.time) > MAX_MAIL_SKEW:
                continue
            key = msg.key
            if key in ("MOOS_MANUAL_OVERRIDE", "MOOS_MANUAL_OVERIDE"):
                self._set_override(str(msg.value).strip().lower())
            elif key == "SPEED_FACTOR" and msg.is_double():
                self.engine.speed_factor = msg.double
            elif key not in NUMERIC_INPUTS:
                continue  # e.g. <NAME>_CMD
            elif not msg.is_double():
                log.warning("%s: %s from %s is not a number (%r): ignored", self.name, key, msg.source or "?",
                            msg.value)
            else:
                value = msg.double
                if key == "NAV_YAW":
                    if self.params.ignore_nav_yaw:
                        continue
                    key, value = "NAV_HEADING", (-math.degrees(value)) % 360.0
                self.values[key] = value
                self.times[key] = msg.time if msg.time > 0 else now

    def _set_override(self, word: str) -> None:
        try:
            overridden = parse_bool(word)
        except FormatError:
            return   # neither true nor false: no change, as pMarinePID
        if not overridden:
            if self.overridden:
                self.values.clear()
                self.times.clear()
                self.engine.reset()
            self.overridden = False
            self.notify("PID_HAS_CONTROL", "true")
        elif not self.overridden:
            self.overridden = True
            self.notify("PID_HAS_CONTROL", "false")
            self._post(0.0, 0.0, 0.0)

    def _required(self) -> tuple[str, ...]:
        base = ("DESIRED_HEADING", "DESIRED_SPEED", "NAV_HEADING", "NAV_SPEED")
        return base + DEPTH_INPUTS if self.params.depth_control else base

    def _stale(self, now: float) -> list[tuple[str, float]]:
        """(label, age) of each input older than its tardy threshold."""
        if self.params.simulation:
            return []
        times = self.times
        for key, _, limit in self._staleness_checks:   # nearly always fresh: no list made for that
            if now - times[key] > limit:
                return [(label, now - times[key]) for key, label, limit in self._staleness_checks
                        if now - times[key] > limit]
        return []

    def iterate(self) -> None:
        if self.overridden:
            return
        now = self.moos_time()
        v = self.values
        if not v.keys() >= self._required_inputs:
            self._post(0.0, 0.0, 0.0)
            return
        stale = self._stale(now)
        if stale:
            labels = " ".join(label for label, _ in stale)
            if labels != self.stale_report:  # once per change, not every iteration
                self.notify("PID_STALE", "Stale " + " ".join(f"{label}:{age:.2f}" for label, age in stale))
            self.stale_report = labels
            self._post(0.0, 0.0, 0.0)
            return
        self.stale_report = ""
        rudder, thrust = self.engine.control(v["DESIRED_HEADING"], v["DESIRED_SPEED"], v["NAV_HEADING"],
                                             v["NAV_SPEED"], now)
        elevator = 0.0
        if self.params.depth_control:
            elevator = self.engine.desired_elevator(v["DESIRED_DEPTH"], v["NAV_DEPTH"], v.get("NAV_PITCH", 0.0), now)
        self._post(rudder, thrust, elevator)

    def _post(self, rudder: float, thrust: float, elevator: float) -> None:
        self.notify("DESIRED_RUDDER", rudder)
        self.notify("DESIRED_THRUST", thrust)
        if self.params.depth_control:
            self.notify("DESIRED_ELEVATOR", elevator)

    def status_fields(self) -> dict:
        return {"has_control": not self.overridden, "stale": self.stale_report or "no"}


main = MarinePID.main
