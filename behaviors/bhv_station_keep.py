"""BHV_StationKeep: hold a station point with inner/outer radii, swing time and hibernation.

Spec: docs/spec/ivp-helm.md §6.
"""
from __future__ import annotations

from collections import deque

from .behavior import IvPBehavior, apply_visual_hints, hint_fields
from .geometry import bearing, distance, fmt_num, parse_point
from .ivp_function import IvPFunction, couple
from .parameters import BOOLEAN, NON_NEGATIVE, Parser, attr, param, parse_number
from .zaic import PeakComponent, zaic_peak

PROGRESS_WINDOW = 10.0  # seconds of (time, distance) samples judging "progress stopped"
PROGRESS_SPAN = 5.0


def _swing_time(value: str, key: str) -> float:
    return min(max(parse_number(value, key), 0.0), 60.0)


def _hibernation(value: str, key: str) -> float:
    return -1.0 if value.strip().lower() in ("off", "-1") else parse_number(value, key, 0)


class BHV_StationKeep(IvPBehavior):
    type_name = "BHV_StationKeep"
    default_name = "station_keep"
    info_vars = ("NAV_X", "NAV_Y", "NAV_HEADING")

    params = (
        attr("center_activate", "center_activate", BOOLEAN, "false",
             "station = ownship's position each time it becomes active (swing while `swing_time` runs)"),
        attr("swing_time", "swing_time", Parser("seconds, clipped to 0..60", _swing_time), "0",
             "after a center_activate, keep the heading this long before fixing the station"),
        attr("hibernation_radius", "hibernation_radius", Parser("off \\| -1 \\| number > 0", _hibernation), "off",
             "the PSKEEP_MODE machine of docs/spec/ivp-helm.md §6.4"),
    )

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.static_pt: tuple[float, float] | None = None
        self.station: tuple[float, float] | None = None
        self.station_pending = False
        self.center_pending = True
        self.swing_until = 0.0
        self.inner, self.outer = 4.0, 15.0
        self.outer_speed, self.transit_speed = 1.2, 2.5
        self.pskeep = "disabled"
        self.dist = -1.0
        self.samples: deque[tuple[float, float]] = deque()
        self.transit = "pending_progress_start"
        self.hints = dict(edge_size="1", vertex_size="1", edge_color="light_blue", label_color="white",
                          vertex_color="red")
        self._circles: tuple = (None, [])   # (what the ring texts show, [(tag, text)])

    @param("station_pt", "point", parse=Parser("x,y", lambda value, key: parse_point(value)),
           doc="static station, applied on the first run and after an update")
    def _set_station_pt(self, point: tuple[float, float]) -> None:
        self.static_pt, self.station_pending = point, True

    @param("inner_radius", parse=NON_NEGATIVE, default="4", doc="speed 0 inside; outer raised to it if smaller")
    def _set_inner(self, radius: float) -> None:
        self.inner = radius
        self.outer = max(self.outer, radius)

    @param("outer_radius", parse=NON_NEGATIVE, default="15", doc="`outer_speed` here, `transit_speed` beyond")
    def _set_outer(self, radius: float) -> None:
        self.outer = max(radius, self.inner)

    @param("outer_speed", parse=NON_NEGATIVE, default="1.2", doc="speed at the outer circle, rising from 0 at the "
                                                                 "inner one; transit raised to at least it")
    def _set_outer_speed(self, speed: float) -> None:
        self.outer_speed = speed
        self.transit_speed = max(self.transit_speed, speed)

    @param("transit_speed", "extra_speed", parse=NON_NEGATIVE, default="2.5", doc="speed beyond the outer circle")
    def _set_transit_speed(self, speed: float) -> None:
        self.transit_speed = max(speed, self.outer_speed)

    @param("visual_hints", parse=Parser("key=value,...", lambda value, key: value),
           doc="`vertex_color`, `edge_color`, `label_color`, `vertex_size`, `edge_size` on the circles")
    def _set_visual_hints(self, value: str) -> None:
        apply_visual_hints(self.hints, value)

    def _set_station(self, pt: tuple[float, float]) -> None:
        self.station = (float(pt[0]), float(pt[1]))
        self.pskeep = "hibernating"
        self.samples.clear()
        self.transit = "pending_progress_start"

    def desired_speed(self, d: float) -> float:
        if self.pskeep == "hibernating" or d <= self.inner:
            return 0.0
        if d < self.outer:
            return self.outer_speed * (d - self.inner) / (self.outer - self.inner)
        return self.transit_speed

    def _history_trend(self) -> float | None:
        """newest - oldest distance over the 10 s history, or None while it spans 5 s or less."""
        (t0, d0), (t1, d1) = self.samples[0], self.samples[-1]
        return d1 - d0 if t1 - t0 > PROGRESS_SPAN else None

    def _update_pskeep(self, d: float) -> None:
        """Hibernation: sleep inside the radius once the approach has stopped closing (spec §6.4)."""
        self.samples.append((self.now, d))
        while self.now - self.samples[0][0] > PROGRESS_WINDOW:
            self.samples.popleft()
        trend = self._history_trend()
        if self.transit == "pending_progress_start":
            if d <= self.hibernation_radius and trend is not None and trend <= 0:
                self.samples.clear()
                self.transit = "noted_progress_start"
        elif self.transit == "noted_progress_start" and trend is not None and trend >= 0:
            self.transit = "noted_progress_end"
        if self.pskeep == "hibernating":
            if d > self.hibernation_radius:
                self.pskeep, self.transit = "seeking_station", "pending_progress_start"
                self.samples.clear()
        elif d <= self.inner or (self.transit == "noted_progress_end" and d <= self.hibernation_radius):
            self.pskeep, self.transit = "hibernating", "hibernating"
            self.samples.clear()

    def circles(self, active: bool) -> None:
        """The station's rings as VIEW_POLYGONs; their texts are built again only when what they show
        changes (they are posted every running iteration)."""
        if self.station is None:
            return
        key = (self.station, active, self.name, tuple(self.hints.items()), self.inner, self.outer,
               self.hibernation_radius)
        if self._circles[0] != key:
            self._circles = (key, self._circle_texts(active))
        for tag, text in self._circles[1]:
            self.post("VIEW_POLYGON", text, key=tag)

    def _circle_texts(self, active: bool) -> list[tuple[str, str]]:
        x, y = self.station
        rings = [("out", self.outer)]
        if self.inner < self.outer:
            rings.append(("in", self.inner))
        if self.hibernation_radius > self.outer:
            rings.append(("hiber", self.hibernation_radius))
        texts = []
        for tag, radius in rings:
            text = (f"radial:: x={x:.1f},y={y:.1f},source={self.ownship}:{self.name},pts=32"
                    + hint_fields(self.hints, "edge_size", "vertex_size", "edge_color", "label_color", "vertex_color")
                    + f",label={self.ownship}:station-keep-{tag},radius={radius:.1f}")
            texts.append((tag, text if active else text + ",active=false"))
        return texts

    def on_run_to_idle(self) -> None:
        self.circles(False)
        if self.center_activate:
            self.center_pending = True

    def on_run_state(self) -> IvPFunction | None:
        nav = self.nav()
        if nav is None:
            return None
        osx, osy, heading, _ = nav
        swinging = False
        if self.center_activate:
            recenter = self.center_pending
            if recenter:
                self.center_pending = False
                self.swing_until = self.now + self.swing_time
            swinging = self.now < self.swing_until
            if recenter or swinging:
                self._set_station((osx, osy))
        elif self.station_pending and self.static_pt is not None:
            self.station_pending = False
            self._set_station(self.static_pt)
        if self.station is None:
            self.post("DIST_TO_STATION", -1.0)
            self.post("BHV_WARNING", f"{self.name}: STATION_POINT_NOT_SET")
            self.circles(False)
            return None
        d = float(distance(osx, osy, *self.station))
        if not swinging:
            self.dist = d
            self._update_pskeep(d)
        self.post("DIST_TO_STATION", round(self.dist, 2))
        self.post("PSKEEP_MODE", self.pskeep.upper() if self.hibernation_radius > 0 else "DISABLED")
        self.circles(True)
        speed = self.desired_speed(self.dist) if self.dist >= 0 else 0.0
        course = heading if swinging and heading is not None else float(bearing(osx, osy, *self.station))
        spd = zaic_peak(self.domain.var("speed"), [PeakComponent(speed, 0, 0.4, 0, 0, 25)])
        crs = zaic_peak(self.domain.var("course"), [PeakComponent(course, 0, 180, 0, 0, 100)], value_wrap=True,
                       keep=False)
        return couple(IvPFunction(("course",), crs), IvPFunction(("speed",), spd), 50, 50, self.pwt)

    def on_update_applied(self) -> None:
        x, y = self.station or self.static_pt or (0.0, 0.0)
        self.post("BHV_SETTINGS", f"type={self.type_name},name={self.name},x={fmt_num(x)},y={fmt_num(y)},"
                  f"inner_radius={fmt_num(self.inner)},outer_radius={fmt_num(self.outer)},"
                  f"hibernation_radius={fmt_num(self.hibernation_radius)},outer_speed={fmt_num(self.outer_speed)},"
                  f"center_activate={str(self.center_activate).lower()}")
