"""BHV_Waypoint: traverse a list of points with capture/slip radius, capture line, lead and repeats.

Spec: ivp-helm.md §5 (advance rules §5.2, completion §5.3, wptflags §5.4, lead §5.5, function §5.6).
"""
from __future__ import annotations

import numpy as np

from .behavior import IvPBehavior, apply_visual_hints, hint_fields, parse_bool, parse_number
from .flags import FlagError
from .geometry import GeometryError, bearing, distance, fmt_num, format_seglist, parse_point, parse_polygon, parse_seglist
from .ivp_function import IvPFunction, couple
from .logic import ConditionError, parse_behavior_condition
from .zaic import PeakComponent, zaic_peak


class BHV_Waypoint(IvPBehavior):
    type_name = "BHV_Waypoint"
    default_name = "bhv_waypoint"
    info_vars = ("NAV_X", "NAV_Y", "NAV_SPEED", "NAV_HEADING")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.points = np.zeros((0, 2))
        self.ix = 0
        self.cpa: float | None = None
        self.prev: tuple[float, float] | None = None
        self.cycles = self.repeats_sofar = self.capture_hits = self.slip_hits = 0
        self.repeat, self.endless, self.reversed, self.complete = 0, False, False, False
        self.speed, self.speed_alt, self.use_alt_speed = 0.0, -1.0, False
        self.capture_radius, self.slip_radius, self.capture_line = 3.0, 15.0, False
        self.lead, self.lead_damper, self.lead_to_start = 0.0, 0.0, False
        self.lead_conditions: list = []
        self.lead_start: tuple[float, float] | None = None
        self.ratio, self.ipf_type = 50.0, "zaic"
        self.end_spd: tuple[float, float] | None = None
        self.status_var, self.index_var, self.cycle_var = "WPT_STAT", "WPT_INDEX", "CYCLE_INDEX"
        self.suffix = ""
        self.dist_prev_var = self.dist_next_var = ""
        self.wptflag_on_start = self.wptflags_posted = self.reset_on_idle = False
        self.point_start = self.empty_ok = False
        self.odo_leg = 0.0
        self.odo_last: tuple[float, float] | None = None   # None: pick up from here (fresh run)
        self.efficiency = False
        self.greedy_pending = False
        self.hints = dict(vertex_size="3", edge_size="1", vertex_color="dodger_blue", edge_color="white",
                          label_color="white", nextpt_color="yellow", nextpt_lcolor="aqua", nextpt_vertex_size="5")
        self.eff_mark: tuple[float, float, float] | None = None   # x, y, time where the measured leg began
        self.eff_totals = np.zeros(4)    # linear dist, odometer dist, linear time, actual time
        self.flags.update(cycleflag=[], wptflag=[])

    def is_flag_kind(self, key: str) -> bool:
        return key in ("cycleflag", "wptflag")

    # ---- parameters --------------------------------------------------------------------
    def _ownship(self) -> tuple[float, float]:
        x, y = self.info.number("NAV_X"), self.info.number("NAV_Y")
        return (x or 0.0, y or 0.0)

    def _parse_points(self, value: str) -> np.ndarray:
        try:
            return parse_seglist(value)
        except GeometryError:
            pts = parse_polygon(value)
        start = int(np.argmin(distance(*self._ownship(), pts[:, 0], pts[:, 1])))
        return np.roll(pts, -start, axis=0)

    def set_points(self, pts: np.ndarray) -> None:
        self.points = pts[::-1].copy() if self.reversed else pts
        self.ix, self.cycles, self.repeats_sofar, self.cpa, self.prev = 0, 0, 0, None, None
        self.complete, self.wptflags_posted = False, False

    def set_param(self, key: str, value: str) -> bool:
        low = value.lower()
        try:
            if key in ("points", "polygon"):
                self.set_points(self._parse_points(value))
            elif key == "xpoints":
                pts = self._parse_points(value)
                if len(pts) != len(self.points):
                    raise ValueError(f"xpoints must have {len(self.points)} points")
                self.points = pts
            elif key == "point":
                self.point_start = low == "start"
                self.empty_ok = low == "empty"
                if low in ("start", "empty"):
                    self.set_points(np.zeros((0, 2)))
                else:
                    self.set_points(np.array([parse_point(value)]))
            elif key == "newpt":
                if not self.reversed:
                    self.points = np.vstack([self.points, parse_point(value)])
            elif key == "speed":
                speed = min(parse_number(value, key, 0), self.domain.var("speed").high if "speed" in self.domain else np.inf)
                if speed != self.speed:
                    self.eff_mark = None    # a leg flown at two speeds says nothing about efficiency
                self.speed = speed
            elif key == "speed_alt":
                speed_alt = parse_number(value, key)
                if speed_alt != self.speed_alt:
                    self.eff_mark = None
                self.speed_alt = speed_alt
            elif key == "use_alt_speed":
                use_alt = parse_bool(value, key)
                if use_alt != self.use_alt_speed:
                    self.eff_mark = None
                self.use_alt_speed = use_alt
            elif key in ("capture_radius", "radius"):
                self.capture_radius = parse_number(value, key, 0)
                if self.capture_radius <= 0:
                    raise ValueError(f"{key} must be > 0, got '{value}'")
            elif key in ("slip_radius", "nm_radius"):
                self.slip_radius = parse_number(value, key, 0)
            elif key == "capture_line":
                if low == "absolute":
                    self.capture_line, self.capture_radius, self.slip_radius = True, 0.0, 0.0
                else:
                    self.capture_line = parse_bool(value, key)
            elif key == "lead":
                self.lead = max(parse_number(value, key), 0.0)
            elif key == "lead_damper":
                self.lead_damper = parse_number(value, key, 0)
                if self.lead_damper <= 0:
                    raise ValueError(f"lead_damper must be > 0, got '{value}'")
            elif key == "lead_to_start":
                self.lead_to_start = parse_bool(value, key)
            elif key == "lead_condition":
                self.lead_conditions.append(parse_behavior_condition(value))
            elif key == "order":
                if low not in ("normal", "reverse", "reversed", "toggle"):
                    raise ValueError("order must be normal, reverse or toggle")
                want = (not self.reversed) if low == "toggle" else low != "normal"
                if want != self.reversed:
                    self.reversed = want
                    self.points, self.ix, self.cpa = self.points[::-1].copy(), 0, None
            elif key == "repeat":
                if low == "forever":
                    self.endless = self.perpetual = True
                else:
                    self.repeat = int(parse_number(value, key, 0))
                    self.endless = False
                    self.perpetual = self.perpetual or self.repeat > 0
            elif key == "currix":
                ix = int(parse_number(value, key, 0))
                if ix < len(self.points):
                    self.ix, self.cpa = ix, None
            elif key in ("wpt_status", "wpt_status_var"):
                self.status_var = value
            elif key in ("wpt_index", "wpt_index_var"):
                self.index_var = value
            elif key == "cycle_index_var":
                self.cycle_var = value
            elif key == "wpt_dist_to_prev":
                self.dist_prev_var = value
            elif key == "wpt_dist_to_next":
                self.dist_next_var = value
            elif key == "post_suffix":
                if any(c.isspace() for c in value):
                    raise ValueError("post_suffix must not contain blanks")
                self.suffix = value if not value or value.startswith("_") else "_" + value
            elif key == "wptflag_on_start":
                self.wptflag_on_start = parse_bool(value, key)
            elif key in ("ipf_type", "ipf-type"):
                if low in ("roc", "rate_of_closure"):
                    raise ValueError(f"ipf_type '{value}' (rate of closure) is not supported by this helm: "
                                     "ivp-helm.md gives no formula for it; use zaic or zaic_spd")
                if low not in ("zaic", "zaic_spd"):
                    raise ValueError(f"ipf_type must be zaic or zaic_spd, got '{value}'")
                self.ipf_type = low
            elif key in ("crs_spd_zaic_ratio", "patience"):
                self.ratio = parse_number(value, key, 1)
                if self.ratio > 99:
                    raise ValueError(f"{key} must be in 1..99, got '{value}'")
            elif key == "end_spd":
                props = dict(p.split("=", 1) for p in "".join(value.split()).split(",") if "=" in p)
                slow, stop = parse_number(props.get("slow_dist", ""), "slow_dist", 0), parse_number(
                    props.get("stop_dist", ""), "stop_dist", 0)
                if stop > slow:
                    raise ValueError("end_spd needs stop_dist <= slow_dist")
                self.end_spd = (slow, stop)
            elif key == "reset_on_idle":
                self.reset_on_idle = parse_bool(value, key)
            elif key == "efficiency_measure":
                if low not in ("all", "off"):
                    raise ValueError("efficiency_measure must be all or off")
                self.efficiency = low == "all"
            elif key in ("greedy_tour", "shortest_tour"):
                self.greedy_pending = parse_bool(value, key)
                self._greedy_tour_when_nav_known()
            elif key in ("draw_path_loop", "eager_prev_index_flag"):
                parse_bool(value, key)  # drawing and PI-macro timing details; accepted
            elif key == "visual_hints":
                apply_visual_hints(self.hints, value)
            else:
                return False
        except (GeometryError, ConditionError, FlagError) as exc:
            raise ValueError(str(exc)) from None
        return True

    def _greedy_tour_when_nav_known(self) -> None:
        """The tour starts from ownship, so at startup it waits for the first NAV_X/NAV_Y."""
        if self.greedy_pending and self.info.number("NAV_X") is not None and self.info.number("NAV_Y") is not None:
            self.greedy_pending = False
            if len(self.points) > 1:
                self.set_points(self.greedy_tour(*self._ownship()))

    def greedy_tour(self, x: float, y: float) -> np.ndarray:
        """The points reordered nearest-first, starting from (x, y)."""
        left, order, here = list(range(len(self.points))), [], np.array((x, y))
        while left:
            dists = np.hypot(*(self.points[left] - here).T)
            nxt = left.pop(int(np.argmin(dists)))
            order.append(nxt)
            here = self.points[nxt]
        return self.points[order]

    # ---- macros --------------------------------------------------------------------------
    def macro(self, name: str):
        n = name.upper()
        npts = len(self.points)
        prev = self.prev or (None, None)
        values = {
            "NI": float(self.ix), "IX": float(self.ix), "PI": float(max(self.ix - 1, 0)),
            "NX": self.points[self.ix][0] if npts else None, "NY": self.points[self.ix][1] if npts else None,
            "PX": prev[0], "PY": prev[1], "X": prev[0], "Y": prev[1],
            "CYCLES": float(self.cycles), "CYCREM": float(max(self.repeat - self.repeats_sofar, 0)),
            "WPTS_HIT": float(self.capture_hits + self.slip_hits), "WPTS_REM": float(npts - self.ix),
            "WPTS": float(npts), "POINTS": format_seglist(self.points), "SPEED": self.speed,
            "SPEED_ALT": self.speed_alt, "USE_SPEED_ALT": str(self.use_alt_speed).lower(),
            "IPF_TYPE": self.ipf_type, "WPT_FLAG_ON_START": str(self.wptflag_on_start).lower(),
            "LEAD_TO_START": str(self.lead_to_start).lower(), "LEAD_DAMPER": self.lead_damper,
            "ORDER": "reverse" if self.reversed else "normal",
        }
        if n in values:
            return values[n]
        if n in ("CYC_DIST_TOGO", "ALL_DIST_TOGO") and npts:
            return round(self.cycle_distance(*self._ownship()) if n == "CYC_DIST_TOGO"
                         else self.remaining_distance(*self._ownship()), 3)
        return super().macro(name)

    # ---- traversal -----------------------------------------------------------------------
    def advance(self, osx: float, osy: float) -> str:
        """One iteration of the advance rules; returns advanced/cycled/completed/in-transit."""
        if self.complete:
            return "completed"
        tx, ty = self.points[self.ix]
        dist = float(distance(osx, osy, tx, ty))
        if self.cpa is None or dist < self.cpa:
            self.cpa = dist
        hit = False
        if dist < self.capture_radius:
            hit, self.capture_hits = True, self.capture_hits + 1
        elif self.slip_radius > self.capture_radius and dist > self.cpa and self.cpa <= self.slip_radius:
            hit, self.slip_hits = True, self.slip_hits + 1
        if not hit and self.capture_line and self.prev is not None:
            to_prev = np.subtract(self.prev, (tx, ty))
            to_os = np.subtract((osx, osy), (tx, ty))
            hit = bool(np.hypot(*to_prev) > 1e-9 and np.dot(to_prev, to_os) <= 0)
        if not hit:
            return "in-transit"
        self.ix += 1
        if self.ix < len(self.points):
            nx, ny = self.points[self.ix]
            self.cpa = float(distance(osx, osy, nx, ny))
            return "advanced"
        self.cycles, self.ix, self.cpa = self.cycles + 1, 0, None
        if self.perpetual or self.endless:
            self.repeats_sofar += 1
            if self.endless or self.repeats_sofar <= self.repeat:
                return "cycled"
        self.complete = True
        return "completed"

    def cycle_distance(self, osx: float, osy: float) -> float:
        """Distance to go to the end of this pass over the list."""
        pts = self.points[self.ix:]
        legs = np.hypot(*np.diff(pts, axis=0).T).sum() if len(pts) > 1 else 0.0
        return float(distance(osx, osy, *pts[0])) + float(legs)

    def remaining_distance(self, osx: float, osy: float) -> float:
        """Distance to go over the rest of the list and the repeats left; -1 when endless."""
        if self.endless:
            return -1.0
        d = self.cycle_distance(osx, osy)
        loop = np.hypot(*np.diff(np.vstack([self.points, self.points[:1]]), axis=0).T).sum()
        return d + max(self.repeat - self.repeats_sofar, 0) * loop if self.perpetual else d

    def steering_point(self, osx: float, osy: float) -> tuple[float, float]:
        nxt = tuple(self.points[self.ix])
        if self.lead <= 0 or not all(c.evaluate(self.info.get) for c in self.lead_conditions):
            return nxt
        if self.ix > 0:
            anchor = tuple(self.points[self.ix - 1])
        elif self.cycles > 0:
            anchor = tuple(self.points[-1])
        elif self.lead_to_start and self.lead_start is not None:
            anchor = self.lead_start
        else:
            return nxt
        a, n, o = np.array(anchor), np.array(nxt), np.array((osx, osy))
        leg = n - a
        length = float(np.hypot(*leg))
        if length < 1e-9:
            return nxt
        t = float(np.clip(np.dot(o - a, leg) / length**2, 0.0, 1.0))
        foot = a + t * leg
        e = float(np.hypot(*(o - foot)))
        factor = 1.0 + 2.0 * (1.0 - e / self.lead_damper) if e < self.lead_damper else 1.0
        step = min(self.lead * factor, float(np.hypot(*(n - foot))))
        x, y = foot + step * leg / length
        return float(x), float(y)

    def cruise_speed(self, osx: float, osy: float) -> float:
        cruise = self.speed_alt if self.use_alt_speed and self.speed_alt >= 0 else self.speed
        if self.end_spd is not None:
            slow, stop = self.end_spd
            d = self.remaining_distance(osx, osy)
            if d <= stop:
                cruise = 0.0
            elif d < slow:
                cruise *= (d - stop) / (slow - stop)
        return cruise

    def objective(self, osx: float, osy: float, heading: float) -> IvPFunction:
        sx, sy = self.steering_point(osx, osy)
        nx, ny = self.points[self.ix]
        self.post_point("trackpt", sx, sy, active=bool(distance(sx, sy, nx, ny) > 5))
        cruise = self.cruise_speed(osx, osy)
        spd_var, crs_var = self.domain.var("speed"), self.domain.var("course")
        if self.ipf_type == "zaic_spd":
            xs = np.array([spd_var.low, 0.1, cruise, cruise + 0.4, spd_var.high])
            us = np.array([0.0, 70.0, 100.0, 20.0, 0.0])
            order = np.argsort(xs, kind="stable")
            spd = np.interp(spd_var.values, xs[order], us[order])
        else:
            spd = zaic_peak(spd_var, [PeakComponent(cruise, cruise / 2, 1.6, 20, 0, 100)])
        crs = zaic_peak(crs_var, [PeakComponent(float(bearing(osx, osy, sx, sy)), 0, 180, 50, 0, 100),
                                  PeakComponent(heading, 30, 180, 5, 0, 20)], value_wrap=True, max_mode=False)
        return couple(IvPFunction(("course",), crs), IvPFunction(("speed",), spd),
                      self.ratio, 100 - self.ratio, self.pwt)

    # ---- life cycle ---------------------------------------------------------------------
    def post_report(self, var: str, value, **kw) -> None:
        """A status/index/cycle post: `silent` suppresses it, post_suffix is appended."""
        if var.lower() != "silent":
            self.post(var + self.suffix, value, **kw)

    def post_point(self, label: str, x: float, y: float, active: bool) -> None:
        """Next point and track point in the nextpt hint colours (the track point drawn smaller)."""
        text = f"x={fmt_num(x)},y={fmt_num(y)},label={self.ownship}'s {label},active={str(active).lower()}"
        if active:
            size = self.hints["nextpt_vertex_size"] if label == "nextpt" else "4"
            lcolor = self.hints["nextpt_lcolor"] if label == "nextpt" else self.hints["nextpt_color"]
            text += f",vertex_color={self.hints['nextpt_color']},label_color={lcolor},vertex_size={size}"
        self.post("VIEW_POINT", text, key=label)

    def measure_leg(self, osx: float, osy: float) -> None:
        """WPT_EFF_*: straight-line versus flown distance and time from the last mark to here.

        The first leg after a start, an idle spell or a speed change only sets the mark."""
        if self.eff_mark is not None:
            mx, my, mt = self.eff_mark
            linear = float(distance(osx, osy, mx, my))
            cruise = self.speed
            leg = np.array([linear, self.odo_leg, linear / cruise if cruise > 0 else 0.0, self.now - mt])
            self.eff_totals += leg
            for scope, (lin, odo, lin_t, odo_t) in (("LEG", leg), ("ALL", self.eff_totals)):
                eff_d, eff_t = (lin / odo if odo > 0 else 0.0), (lin_t / odo_t if odo_t > 0 else 0.0)
                self.post_report(f"WPT_EFF_SUMM_{scope}", ", ".join((
                    f"vname={self.ownship}", f"bhv_name={self.name}", f"linear_dist={fmt_num(lin, 1)}",
                    f"odo_dist={fmt_num(odo, 1)}", f"efficiency_dist={fmt_num(eff_d)}",
                    f"linear_time={fmt_num(lin_t, 1)}", f"odo_time={fmt_num(odo_t, 1)}",
                    f"efficiency_time={fmt_num(eff_t)}")))
                self.post_report(f"WPT_EFF_DIST_{scope}", eff_d)
                self.post_report(f"WPT_EFF_TIME_{scope}", eff_t)
        self.eff_mark = (osx, osy, self.now)

    def on_run_to_idle(self) -> None:
        self.cpa = None
        self.odo_last = None
        self.eff_mark = None
        for var in (self.dist_prev_var, self.dist_next_var):
            if var:
                self.post(var, -1.0)
        if len(self.points):
            for label in ("nextpt", "trackpt"):
                self.post_point(label, *self.points[self.ix], active=False)
        self.post("VIEW_SEGLIST", f"{format_seglist(self.points)},label={self.ownship}_{self.name},active=false")
        if self.reset_on_idle:
            self.set_points(self.points)

    def on_run_state(self) -> IvPFunction | None:
        nav = self.nav()
        if nav is None:
            return None
        osx, osy, heading, speed = nav
        if heading is None:
            self.post("BHV_ERROR", f"{self.name}: No ownship NAV_HEADING in info_buffer", repeatable=True)
            return None
        self._greedy_tour_when_nav_known()
        if self.point_start:
            self.point_start = False
            self.set_points(np.round(np.array([[osx, osy]]), 3))
        if len(self.points) == 0:
            if not self.empty_ok:
                self.post("BHV_WARNING", f"{self.name}: No waypts given. Set val to empty if intentional")
            return None
        if len(self.points) == 1 and (self.repeat > 0 or self.endless):
            self.post("BHV_WARNING", f"{self.name}: cycles/repeats not supported with single waypt")
        if self.prev is None:
            self.prev = (osx, osy)
        if self.lead_start is None:
            self.lead_start = (osx, osy)
        target_before = tuple(self.points[self.ix])
        if self.odo_last is not None:
            self.odo_leg += float(distance(*self.odo_last, osx, osy))
        self.odo_last = (osx, osy)
        result = self.advance(osx, osy)
        if result != "in-transit":
            if self.efficiency:
                self.measure_leg(osx, osy)
            self.odo_leg = 0.0       # a new leg starts at the waypoint just reached
        self.post_report("WPT_ODO", round(self.odo_leg, 2))
        if result in ("cycled", "completed"):
            self.post_report(self.status_var, f"behavior-name={self.name},{result}", key="end", repeatable=True)
            self.post_flags("cycleflag")
        target_changed = tuple(self.points[self.ix]) != target_before
        if result != "in-transit" or target_changed or (self.wptflag_on_start and not self.wptflags_posted):
            if result != "in-transit":
                self.prev = target_before
            self.wptflags_posted = True
            self.post_flags("wptflag")
        self.post_report(self.index_var, float(self.ix))
        self.post_report(self.cycle_var, float(self.cycles))
        if result == "completed":
            self.set_complete()
            if self.perpetual:
                self.complete, self.ix, self.repeats_sofar = False, 0, 0
            return None
        nx, ny = self.points[self.ix]
        dist = float(distance(osx, osy, nx, ny))
        eta = dist / speed if speed and speed > 0 else 0.0
        hits = self.capture_hits + self.slip_hits
        self.post_report(self.status_var, f"vname={self.ownship},behavior-name={self.name},index={self.ix},"
                  f"hits={self.capture_hits}/{hits},cycles={self.cycles},dist={dist:.0f},eta={eta:.0f}")
        if self.dist_next_var:
            self.post(self.dist_next_var, round(dist, 2))
        if self.dist_prev_var:
            self.post(self.dist_prev_var, round(float(distance(osx, osy, *self.prev)), 2))
        self.post("VIEW_SEGLIST", f"{format_seglist(self.points)},label={self.ownship}_{self.name}" + hint_fields(
            self.hints, "vertex_color", "edge_color", "label_color", "edge_size", "vertex_size"))
        self.post_point("nextpt", nx, ny, active=True)
        return self.objective(osx, osy, heading)

    def on_update_applied(self) -> None:
        self.post("BHV_SETTINGS", f"type={self.type_name},name={self.name},points={format_seglist(self.points)},"
                  f"speed={fmt_num(self.speed)}")
