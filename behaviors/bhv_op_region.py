"""BHV_OpRegion: the safety net. Ownship must stay inside the operation polygon(s), above
`min_altitude`, above `max_depth` and within `max_time` of the behaviour's first run; a breach is
a behaviour error, so the helm all-stops (IVPHELM_ALLSTOP = BehaviorError) with the reason posted
as BHV_ERROR, and stays stopped: the error is latched, as MOOS-IvP's `postEMessage` leaves the
behaviour's state not-ok for good.

It never produces an objective function. Each running iteration it posts the distance and time to
the perimeter along the present heading (OPREG_TRAJECTORY_PERIM_*) and by the shortest way at the
domain's top speed (OPREG_ABSOLUTE_PERIM_*), and OPREG_TIME_REMAINING when `max_time` is set.
Names, defaults and messages follow MOOS-IvP's BHV_OpRegion.
"""
from __future__ import annotations

import math

import numpy as np
import shapely

from .behavior import IvPBehavior, apply_visual_hints, hint_fields
from .geometry import format_seglist, parse_polygon
from .ivp_function import IvPFunction
from .parameters import NON_NEGATIVE, Parser, attr, param

RAY_LENGTH = 1e7   # metres: far beyond any operation area, so a ray to it crosses every edge ahead


def perimeter_distance_along(polygon: shapely.Polygon, x: float, y: float, heading: float) -> float:
    """Distance from (x, y) along `heading` (degrees, 0 = north) to the polygon's edge; -1 if the
    ray never meets it."""
    a = math.radians(heading)
    ray = shapely.LineString([(x, y), (x + RAY_LENGTH * math.sin(a), y + RAY_LENGTH * math.cos(a))])
    points = shapely.get_coordinates(ray.intersection(polygon.exterior))
    if not len(points):
        return -1.0
    return float(np.hypot(points[:, 0] - x, points[:, 1] - y).min())


class BHV_OpRegion(IvPBehavior):
    type_name = "BHV_OpRegion"
    default_name = "bhv_opregion"
    info_vars = ("NAV_X", "NAV_Y", "NAV_HEADING", "NAV_SPEED", "NAV_DEPTH", "NAV_ALTITUDE")
    domain_vars = ()
    params = (
        attr("max_depth", "max_depth", NON_NEGATIVE, "0", "deeper than this is a breach; 0: no limit"),
        attr("min_altitude", "min_altitude", NON_NEGATIVE, "0", "NAV_ALTITUDE below this is a breach; 0: no limit"),
        attr("max_time", "max_time", NON_NEGATIVE, "0", "seconds after the first run that are a breach; 0: no limit"),
        attr("trigger_exit_time", "trigger_exit_time", NON_NEGATIVE, "0.5",
             "seconds outside the polygon before it counts (one wild GPS fix is forgiven)"),
    )

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.polygons: list[np.ndarray] = []
        self.areas: list[shapely.Polygon] = []   # the same, as prepared shapely polygons: made once, asked every iteration
        self._view: tuple = ()                   # (points, (active, name, hints), text) of the last VIEW_POLYGON
        self.trigger_entry_time = 1.0
        self.trigger_on_entry = False      # set by a trigger_entry_time > 0: armed once inside long enough
        self.entry_made = False
        self.first_time: float | None = None
        self.last_time = 0.0
        self.secs_in = self.secs_out = 0.0
        self.was_in = False
        self.breach = ""                   # the latched reason, once breached
        self.hints = dict(vertex_color="", edge_color="", vertex_size="", edge_size="")

    @param("polygon", parse=Parser("convex polygon", lambda value, key: parse_polygon(value)),
           doc="the operation area; repeatable: ownship must be inside every one")
    def _add_polygon(self, pts: np.ndarray) -> None:
        if len(pts) < 3:
            raise ValueError("an operation polygon needs at least 3 vertices")
        self.polygons.append(pts)
        area = shapely.Polygon(pts)
        shapely.prepare(area)
        self.areas.append(area)

    @param("trigger_entry_time", parse=NON_NEGATIVE, default="1",
           doc="setting it (> 0) enforces the polygon only once ownship has been inside it this many "
               "seconds (a launch from outside the area)")
    def _set_trigger_entry_time(self, secs: float) -> None:
        self.trigger_entry_time = secs
        self.trigger_on_entry = self.trigger_on_entry or secs > 0

    @param("visual_hints", parse=Parser("key=value,...", lambda value, key: value),
           doc="`vertex_color`, `edge_color`, `vertex_size`, `edge_size` of the drawn polygon")
    def _set_visual_hints(self, value: str) -> None:
        apply_visual_hints(self.hints, value)

    # ---- life cycle ------------------------------------------------------------------
    def post_error(self, reason: str) -> None:
        """A breach: the first reason is latched and posted every iteration, so the helm stays all-stopped."""
        self.breach = self.breach or reason

    def post_breach(self) -> None:
        if self.breach:
            self.post("BHV_ERROR", f"{self.name}: {self.breach}", repeatable=True)

    def on_idle_state(self) -> None:
        self.post_breach()
        self.post_polygon(active=False)

    def on_run_state(self) -> IvPFunction | None:
        if self.first_time is None:
            self.first_time = self.last_time = self.now
        delta, self.last_time = self.now - self.last_time, self.now
        elapsed = self.now - self.first_time
        x, y = self.info.number("NAV_X"), self.info.number("NAV_Y")
        if x is None or y is None:
            self.post_error("No ownship info in info_buffer")
        else:
            self.verify_polygon(x, y, delta)
            self.post_perimeter(x, y, elapsed)
        self.verify_limits(elapsed)
        self.post_breach()
        self.post_polygon(active=True)
        return None

    def verify_polygon(self, x: float, y: float, delta: float) -> None:
        here = shapely.Point(x, y)
        inside = all(area.contains(here) for area in self.areas)
        if inside:
            self.secs_out = 0.0
            self.secs_in = self.secs_in + delta if self.was_in else 0.0
            if self.secs_in >= self.trigger_entry_time:
                self.entry_made = True
        else:
            self.secs_in = 0.0
            self.secs_out = self.secs_out + delta if not self.was_in else 0.0
        self.was_in = inside
        armed = self.entry_made or not self.trigger_on_entry
        if not inside and armed and self.secs_out >= self.trigger_exit_time:
            self.post_error(f"BHV_OpRegion Polygon containment failure:  x={x:.5f} y={y:.5f}")

    def verify_limits(self, elapsed: float) -> None:
        if self.max_depth > 0:
            depth = self.info.number("NAV_DEPTH")
            if depth is None:
                self.post_error("No ownship depth in info_buffer.")
            elif depth > self.max_depth:
                self.post_error(f"OpRegion Depth failure: max:{self.max_depth:.5f} detected:{depth:.5f}")
        if self.min_altitude > 0:
            altitude = self.info.number("NAV_ALTITUDE")
            if altitude is None:
                self.post_error("No ownship altitude in info_buffer.")
            elif altitude < self.min_altitude:
                self.post_error(f"OpRegion Altitude failure: Min-Altitude:{self.min_altitude:.5f}  "
                                f"Detected Altitude: {altitude:.5f}")
        if self.max_time > 0 and elapsed > self.max_time:
            self.post_error(f"OpRegion timeout failure: MaxTime:{self.max_time:.5f}  Elapsed Time: {elapsed:.5f}")

    def post_perimeter(self, x: float, y: float, elapsed: float) -> None:
        speed, heading = self.info.number("NAV_SPEED"), self.info.number("NAV_HEADING")
        if speed is None or heading is None or not self.polygons:
            return
        poly = self.areas[-1]
        along = perimeter_distance_along(poly, x, y, heading)
        self.post("OPREG_TRAJECTORY_PERIM_DIST", along if along <= 1 else float(round(along)))
        self.post("OPREG_TRAJECTORY_PERIM_ETA", float(round(along / speed)) if speed > 0 else 0.0)
        shortest = float(poly.exterior.distance(shapely.Point(x, y)))
        top = self.domain.var("speed").high if "speed" in self.domain else 0.0
        self.post("OPREG_ABSOLUTE_PERIM_DIST", shortest if shortest <= 1 else float(round(shortest)))
        self.post("OPREG_ABSOLUTE_PERIM_ETA", float(round(shortest / top)) if top > 0 else 0.0)
        if self.max_time > 0:
            self.post("OPREG_TIME_REMAINING", max(self.max_time - elapsed, 0.0))

    def post_polygon(self, active: bool) -> None:
        if not self.polygons:
            return
        points, key = self.polygons[-1], (active, self.name, tuple(self.hints.items()))
        if not self._view or self._view[0] is not points or self._view[1] != key:   # built once, posted every iteration
            spec = f"{format_seglist(points)},label={self.ownship}_{self.name}"
            if active:
                spec += "".join(hint_fields(self.hints, k) for k in self.hints if self.hints[k])
            else:
                spec += ",active=false"
            self._view = (points, key, spec)
        self.post("VIEW_POLYGON", self._view[2])
