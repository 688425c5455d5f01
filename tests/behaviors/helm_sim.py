"""A fake clock and a simple kinematic boat for driving the helm engine in tests and benchmarks (no
MOOS), and the head-on encounter the avoidance test and benchmarks/helm_bench.py fly."""
from __future__ import annotations

import math


class Boat:
    """Turns toward DESIRED_HEADING at a fixed rate and takes DESIRED_SPEED at once."""

    def __init__(self, x=0.0, y=0.0, heading=0.0, current=(0.0, 0.0)):
        self.x, self.y, self.heading, self.speed, self.current = x, y, heading, 0.0, current

    def step(self, desired: dict, dt: float):
        want = desired.get("DESIRED_HEADING", self.heading)
        turn = (want - self.heading + 180) % 360 - 180
        self.heading = (self.heading + max(-40 * dt, min(40 * dt, turn))) % 360
        self.speed = desired.get("DESIRED_SPEED", 0.0)
        rad = math.radians(self.heading)
        self.x += (self.speed * math.sin(rad) + self.current[0]) * dt
        self.y += (self.speed * math.cos(rad) + self.current[1]) * dt

    def nav(self):
        return dict(NAV_X=self.x, NAV_Y=self.y, NAV_HEADING=self.heading, NAV_SPEED=self.speed)


def run(helm: "Helm", boat: Boat, seconds: float, dt=0.25, start=0.0, pokes=None, log=None):
    t = start
    while t < start + seconds:
        for var, value in boat.nav().items():
            helm.on_mail(var, value, t)
        for var, value in (pokes or {}).pop(round(t, 2), {}).items():
            helm.on_mail(var, value, t)
        posts = helm.iterate(t)
        if log is not None:
            log.extend((t, v, val) for v, val, _ in posts)
        boat.step({v: val for v, val, _ in posts if v.startswith("DESIRED_")}, dt)
        if log is not None:
            log.append((t, "POS", (boat.x, boat.y)))
        t += dt
    return t


# A transit north with an avoidance template, as the head-on test and benchmarks/helm_bench.py fly it.
AVOID_MISSION = """Behavior = BHV_AvoidCollision
{
  name       = avd_
  pwt        = 300
  updates    = CONTACT_INFO
  templating = spawn
  endflag    = CONTACT_RESOLVED = $[CONTACT]
  contact    = to-be-set
  pwt_outer_dist = 100
  pwt_inner_dist = 30
  completed_dist = 150
  min_util_cpa_dist = 10
  max_util_cpa_dist = 30
  pwt_grade  = linear
}
Behavior = BHV_Waypoint
{
  name   = transit
  speed  = 2
  point  = 0,400
}
"""


def node_report(name: str, x: float, y: float, hdg: float, spd: float, t: float) -> str:
    """A NODE_REPORT as pNodeReporter writes it (the fields the helm's contact ledger reads)."""
    return f"NAME={name},X={x:.2f},Y={y:.2f},SPD={spd},HDG={hdg},DEP=0,TIME={t:.2f}"


def head_on(helm: Helm, until_y: float = 390.0, limit: float = 600.0) -> tuple[float, float, list]:
    """Ownship (helm) transits north from 0,0 at 2 m/s; henry comes south from 0,300 at 2 m/s on the
    same line and does not give way. The alert comes as a contact manager sends it: once, when the
    range falls inside 100 m. Returns (closest approach, time ownship reached until_y, log)."""
    boat, t, closest, alerted, log = Boat(0, 0, 0), 0.0, math.inf, False, []
    while boat.y < until_y and t < limit:
        cn_y = 300 - 2 * t
        helm.on_mail("NODE_REPORT", node_report("henry", 0, cn_y, 180, 2, t), t)
        if not alerted and math.hypot(boat.x, boat.y - cn_y) < 100:
            helm.on_mail("CONTACT_INFO", "name=henry # contact=henry", t)
            alerted = True
        run(helm, boat, 0.25, start=t, log=log)
        closest = min(closest, math.hypot(boat.x, boat.y - cn_y))
        t += 0.25
    return closest, t, log
