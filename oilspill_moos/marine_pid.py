"""pMarinePID: heading/speed (and optional depth) PID from DESIRED_* to DESIRED_RUDDER/THRUST.

`ScalarPID` and `PIDEngine` are pure and follow pMarinePIDV22's arithmetic
(field-apps.md section 2); `MarinePID` is the MOOS app around them.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

from oilspill_moos.app_config import ConfigLike, config_bool, config_float

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
    def from_config(cls, cfg: ConfigLike, prefix: str) -> "PIDGains":
        limit_key = f"{prefix}_integral_limit"
        if cfg.get(limit_key, None) is None:
            limit_key = f"{prefix}_ki_limit"  # the older alias
        return cls(
            kp=config_float(cfg, f"{prefix}_kp", 0.0),
            kd=config_float(cfg, f"{prefix}_kd", 0.0),
            ki=config_float(cfg, f"{prefix}_ki", 0.0),
            integral_limit=config_float(cfg, limit_key, 0.0, lo=0.0),
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
        return cls(
            yaw=PIDGains.from_config(cfg, "yaw_pid"),
            speed=PIDGains.from_config(cfg, "speed_pid"),
            z_to_pitch=PIDGains.from_config(cfg, "z_to_pitch_pid"),
            pitch=PIDGains.from_config(cfg, "pitch_pid"),
            max_rudder=config_float(cfg, "maxrudder", 100.0, lo=0.0),
            max_thrust=config_float(cfg, "maxthrust", 100.0, lo=0.0),
            max_pitch=config_float(cfg, "maxpitch", 15.0, lo=0.0),
            max_elevator=config_float(cfg, "maxelevator", 13.0, lo=0.0),
            speed_factor=config_float(cfg, "speed_factor", 0.0),
            depth_control=config_bool(cfg, "depth_control", True),
            tardy_helm_threshold=config_float(cfg, "tardy_helm_threshold", 2.0, lo=0.0),
            tardy_nav_threshold=config_float(cfg, "tardy_nav_threshold", 2.0, lo=0.0),
            simulation=config_bool(cfg, "simulation", False),
            ignore_nav_yaw=config_bool(cfg, "ignore_nav_yaw", False),
        )


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
