"""A fake clock and a simple kinematic boat for driving the helm engine in tests (no MOOS)."""
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


def run(helm: Helm, boat: Boat, seconds: float, dt=0.25, start=0.0, pokes=None, log=None):
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
