"""BHV_Waypoint: traverse a list of points with capture/slip radius, capture line, lead and repeats.

Spec: docs/spec/ivp-helm.md §5 (advance rules §5.2, completion §5.3, wptflags §5.4, lead §5.5, function §5.6).
"""
from __future__ import annotations

import math

import numpy as np

from moosdb_py.formats import FormatError, parse_pairs

from .behavior import IvPBehavior, apply_visual_hints, flag_param, hint_fields
from .geometry import GeometryError, bearing, distance, fmt_num, format_seglist, parse_point, parse_polygon, parse_seglist
from .ivp_function import IvPFunction, couple
from .logic import parse_behavior_condition
from .parameters import (BOOLEAN, NON_NEGATIVE, NUMBER, POSITIVE, TEXT, Parser, accepted, attr, one_of, param,
                         parse_number)
from .zaic import PeakComponent, zaic_peak


def _ratio(value: str, key: str) -> float:
    ratio = parse_number(value, key, 1)
    if ratio > 99:
        raise ValueError(f"{key} must be in 1..99, got '{value}'")
    return ratio


def _ipf_type(value: str, key: str) -> str:
    low = value.strip().lower()
    if low in ("roc", "rate_of_closure"):
        raise ValueError(f"ipf_type '{value}' (rate of closure) is not supported by this helm: "
                         "docs/spec/ivp-helm.md gives no formula for it; use zaic or zaic_spd")
    if low not in ("zaic", "zaic_spd"):
        raise ValueError(f"ipf_type must be zaic or zaic_spd, got '{value}'")
    return low


def _end_spd(value: str, key: str) -> tuple[float, float]:
    try:
        props = parse_pairs(value)
    except FormatError as exc:
        raise ValueError(f"end_spd: {exc}") from None
    slow = parse_number(props.get("slow_dist", ""), "slow_dist", 0)
    stop = parse_number(props.get("stop_dist", ""), "stop_dist", 0)
    if stop > slow:
        raise ValueError("end_spd needs stop_dist <= slow_dist")
    return slow, stop


def _post_suffix(value: str, key: str) -> str:
    if any(c.isspace() for c in value):
        raise ValueError("post_suffix must not contain blanks")
    return value if not value or value.startswith("_") else "_" + value


class BHV_Waypoint(IvPBehavior):
    type_name = "BHV_Waypoint"
    default_name = "bhv_waypoint"
    info_vars = ("NAV_X", "NAV_Y", "NAV_SPEED", "NAV_HEADING")
    params = (
        attr(("capture_radius", "radius"), "capture_radius", POSITIVE, "3", "strict `dist < radius` captures"),
        attr(("slip_radius", "nm_radius"), "slip_radius", NON_NEGATIVE, "15",
             "slip hit when moving away after coming within it"),
        attr("lead_to_start", "lead_to_start", BOOLEAN, "false",
             "with `lead`: the first leg's track line starts at the start position"),
        attr(("wpt_status", "wpt_status_var"), "status_var", TEXT, "WPT_STAT", "status variable; `silent` suppresses"),
        attr(("wpt_index", "wpt_index_var"), "index_var", TEXT, "WPT_INDEX", "index variable; `silent` suppresses"),
        attr("cycle_index_var", "cycle_var", TEXT, "CYCLE_INDEX", "cycle count variable; `silent` suppresses"),
        attr("wpt_dist_to_prev", "dist_prev_var", TEXT, "",
             "variable for the distance to the previous point, posted each running iteration, -1 on going idle"),
        attr("wpt_dist_to_next", "dist_next_var", TEXT, "", "the same for the next point"),
        attr("post_suffix", "suffix", Parser("word", _post_suffix), "",
             "`_S` appended to WPT_STAT, WPT_INDEX, CYCLE_INDEX, WPT_ODO, WPT_EFF_*"),
        attr("wptflag_on_start", "wptflag_on_start", BOOLEAN, "false", "post the wptflags when starting"),
        attr(("ipf_type", "ipf-type"), "ipf_type", Parser("zaic \\| zaic_spd", _ipf_type), "zaic",
             "objective function shape; `roc`/`rate_of_closure` is an error saying it is not supported "
             "(the spec gives no formula)"),
        attr(("crs_spd_zaic_ratio", "patience"), "ratio", Parser("number 1..99", _ratio), "50",
             "course weight; speed weight 100 - it"),
        attr("end_spd", "end_spd", Parser("slow_dist=..,stop_dist=..", _end_spd),
             doc="speed ramp down to 0 over the remaining distance"),
        attr("reset_on_idle", "reset_on_idle", BOOLEAN, "false", "traversal restarts on going idle"),
        accepted(("draw_path_loop", "eager_prev_index_flag"), "checked, no effect (drawing detail, PI-macro timing)",
                 BOOLEAN),
        flag_param("cycleflag"),
        flag_param("wptflag"),
    )

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.points = np.zeros((0, 2))
        self._seglist: tuple[bytes, str] = (b"", "")   # the points' bytes and their pts={...} text, built once
        self._drawn: dict[str, tuple] = {}   # VIEW_* drawing posted every iteration -> (what it shows, its text)
        self.reversed = False
        self.ix = 0
        self.cpa: float | None = None
        self.prev: tuple[float, float] | None = None
        self.cycles = self.repeats_sofar = self.capture_hits = self.slip_hits = 0
        self.repeat, self.endless, self.complete = 0, False, False
        self.speed, self.speed_alt, self.use_alt_speed = 0.0, -1.0, False
        self.capture_line = False
        self.lead, self.lead_damper = 0.0, 0.0
        self.lead_conditions: list = []
        self.lead_start: tuple[float, float] | None = None
        self.wptflags_posted = False
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

    @param("points", "polygon", parse=Parser("seglist \\| polygon", lambda value, key: value),
           doc="seglist first (`x,y:x,y`, `pts={..}`, `format=lawnmower`), else a polygon (radial forms) "
               "entered at the vertex nearest ownship; resets index, cycles and previous point")
    def _set_points_param(self, value: str) -> None:
        self.set_points(self._parse_points(value))

    @param("xpoints", parse=Parser("seglist", lambda value, key: value),
           doc="replaces the points, keeps the index; a different point count is an error")
    def _set_xpoints(self, value: str) -> None:
        pts = self._parse_points(value)
        if len(pts) != len(self.points):
            raise ValueError(f"xpoints must have {len(self.points)} points")
        self.points = pts

    @param("point", parse=Parser("x,y \\| start \\| empty", lambda value, key: value),
           doc="one point; `start` = ownship's position (3 decimals) on the first run; `empty`")
    def _set_point(self, value: str) -> None:
        low = value.lower()
        self.point_start, self.empty_ok = low == "start", low == "empty"
        self.set_points(np.zeros((0, 2)) if low in ("start", "empty") else np.array([parse_point(value)]))

    @param("newpt", parse=Parser("x,y", lambda value, key: parse_point(value)), doc="appended (ignored while reversed)")
    def _new_point(self, point: tuple[float, float]) -> None:
        if not self.reversed:
            self.points = np.vstack([self.points, point])

    @param("speed", parse=NON_NEGATIVE, default="0", doc="cruise speed, clipped to the domain's top speed")
    def _set_speed(self, speed: float) -> None:
        speed = min(speed, self.domain.var("speed").high if "speed" in self.domain else np.inf)
        if speed != self.speed:
            self.eff_mark = None    # a leg flown at two speeds says nothing about efficiency
        self.speed = speed

    @param("speed_alt", parse=NUMBER, default="-1", doc="alternative cruise speed, used when `use_alt_speed = true` "
                                                       "and it is >= 0")
    def _set_speed_alt(self, speed_alt: float) -> None:
        if speed_alt != self.speed_alt:
            self.eff_mark = None
        self.speed_alt = speed_alt

    @param("use_alt_speed", parse=BOOLEAN, default="false", doc="cruise at `speed_alt`")
    def _set_use_alt_speed(self, use_alt: bool) -> None:
        if use_alt != self.use_alt_speed:
            self.eff_mark = None
        self.use_alt_speed = use_alt

    @param("capture_line", parse=Parser("boolean \\| absolute", lambda value, key: value.strip().lower()),
           default="false", doc="passing the line through the point square to the leg captures it; `absolute` "
                                "also zeroes both radii")
    def _set_capture_line(self, low: str) -> None:
        if low == "absolute":
            self.capture_line, self.capture_radius, self.slip_radius = True, 0.0, 0.0
        else:
            self.capture_line = BOOLEAN(low, "capture_line")

    @param("lead", parse=NUMBER, default="0", doc="track-line steering point this far ahead (docs/spec/ivp-helm.md §5.5); "
                                                  "negative means 0")
    def _set_lead(self, lead: float) -> None:
        self.lead = max(lead, 0.0)

    @param("lead_damper", parse=POSITIVE, doc="steering toward the track line grows within this distance of it")
    def _set_lead_damper(self, damper: float) -> None:
        self.lead_damper = damper

    @param("lead_condition", parse=Parser("condition", lambda value, key: parse_behavior_condition(value)),
           doc="lead only while these hold; repeatable")
    def _add_lead_condition(self, condition) -> None:
        self.lead_conditions.append(condition)

    @param("order", parse=one_of("normal", "reverse", "reversed", "toggle"), default="normal",
           doc="a change reverses the points and resets the index")
    def _set_order(self, low: str) -> None:
        want = (not self.reversed) if low == "toggle" else low != "normal"
        if want != self.reversed:
            self.reversed = want
            self.points, self.ix, self.cpa = self.points[::-1].copy(), 0, None

    @param("repeat", parse=Parser("N >= 0 \\| forever", lambda value, key: value.strip().lower()), default="0",
           doc="passes after the first (N > 0 makes it perpetual)")
    def _set_repeat(self, low: str) -> None:
        if low == "forever":
            self.endless = self.perpetual = True
        else:
            self.repeat = int(parse_number(low, "repeat", 0))
            self.endless = False
            self.perpetual = self.perpetual or self.repeat > 0

    @param("currix", parse=NON_NEGATIVE, doc="jump to this index (ignored when out of range)")
    def _set_currix(self, ix: float) -> None:
        if int(ix) < len(self.points):
            self.ix, self.cpa = int(ix), None

    @param("efficiency_measure", parse=one_of("all", "off"), default="off",
           doc="`all` posts `WPT_EFF_SUMM_LEG/ALL` (`vname=.., bhv_name=.., linear_dist=.., odo_dist=.., "
               "efficiency_dist=.., linear_time=.., odo_time=.., efficiency_time=..`) and `WPT_EFF_DIST/TIME_LEG/ALL` "
               "at each waypoint reached after the first; a start, an idle spell or a speed change only re-marks")
    def _set_efficiency(self, low: str) -> None:
        self.efficiency = low == "all"

    @param("greedy_tour", "shortest_tour", parse=BOOLEAN, default="false",
           doc="nearest-neighbour reorder from ownship, once ownship's position is known")
    def _set_greedy(self, greedy: bool) -> None:
        self.greedy_pending = greedy
        self._greedy_tour_when_nav_known()

    @param("visual_hints", parse=Parser("key=value,...", lambda value, key: value),
           doc="`vertex_color`, `edge_color` (`off` hides the edges), `label_color`, `vertex_size`, `edge_size` on "
               "`VIEW_SEGLIST`; `nextpt_color`, `nextpt_lcolor`, `nextpt_vertex_size` on the next/track "
               "`VIEW_POINT`s; other keys ignored as MOOS-IvP does; lines accumulate")
    def _set_visual_hints(self, value: str) -> None:
        apply_visual_hints(self.hints, value)
        self._drawn.clear()

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
            px, py = self.prev      # plain floats: numpy on 2-vectors costs more than the sums
            hit = math.hypot(px - tx, py - ty) > 1e-9 and (px - tx) * (osx - tx) + (py - ty) * (osy - ty) <= 0
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
        nxt = tuple(self.points[self.ix].tolist())   # plain floats: the same IEEE sums as numpy's scalars, cheaper
        if self.lead <= 0 or not all(c.evaluate(self.info.get) for c in self.lead_conditions):
            return nxt
        if self.ix > 0:
            anchor = tuple(self.points[self.ix - 1].tolist())
        elif self.cycles > 0:
            anchor = tuple(self.points[-1].tolist())
        elif self.lead_to_start and self.lead_start is not None:
            anchor = self.lead_start
        else:
            return nxt
        (ax, ay), (nx, ny) = anchor, nxt      # plain floats: numpy on 2-vectors costs more than the sums
        lx, ly = nx - ax, ny - ay
        length = math.hypot(lx, ly)
        if length < 1e-9:
            return nxt
        t = min(max(((osx - ax) * lx + (osy - ay) * ly) / length**2, 0.0), 1.0)
        fx, fy = ax + t * lx, ay + t * ly
        e = math.hypot(osx - fx, osy - fy)
        factor = 1.0 + 2.0 * (1.0 - e / self.lead_damper) if e < self.lead_damper else 1.0
        step = min(self.lead * factor, math.hypot(nx - fx, ny - fy))
        return float(fx + step * lx / length), float(fy + step * ly / length)

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
                                  PeakComponent(heading, 30, 180, 5, 0, 20)], value_wrap=True, max_mode=False,
                       keep=False)
        return couple(IvPFunction(("course",), crs), IvPFunction(("speed",), spd),
                      self.ratio, 100 - self.ratio, self.pwt)

    # ---- life cycle ---------------------------------------------------------------------
    def post_report(self, var: str, value, **kw) -> None:
        """A status/index/cycle post: `silent` suppresses it, post_suffix is appended."""
        if var.lower() != "silent":
            self.post(var + self.suffix, value, **kw)

    def post_point(self, label: str, x: float, y: float, active: bool) -> None:
        """Next point and track point in the nextpt hint colours (the track point drawn smaller)."""
        shows = (x, y, active)
        kept = self._drawn.get(label)       # the next point is the same one every iteration of a leg
        if kept is not None and kept[0] == shows:
            text = kept[1]
        else:
            text = f"x={fmt_num(x)},y={fmt_num(y)},label={self.ownship}'s {label},active={str(active).lower()}"
            if active:
                size = self.hints["nextpt_vertex_size"] if label == "nextpt" else "4"
                lcolor = self.hints["nextpt_lcolor"] if label == "nextpt" else self.hints["nextpt_color"]
                text += f",vertex_color={self.hints['nextpt_color']},label_color={lcolor},vertex_size={size}"
            self._drawn[label] = (shows, text)
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
        self.post("VIEW_SEGLIST", f"{self._points_text()},label={self.ownship}_{self.name},active=false")
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
                  f"hits={self.capture_hits}/{hits},cycles={self.cycles}," + "dist=%.0f,eta=%.0f" % (dist, eta))
        if self.dist_next_var:
            self.post(self.dist_next_var, round(dist, 2))
        if self.dist_prev_var:
            self.post(self.dist_prev_var, round(float(distance(osx, osy, *self.prev)), 2))
        points = self._points_text()
        kept = self._drawn.get("seglist")       # the route drawn changes only with the points
        if kept is not None and kept[0] is points:
            text = kept[1]
        else:
            text = f"{points},label={self.ownship}_{self.name}" + hint_fields(
                self.hints, "vertex_color", "edge_color", "label_color", "edge_size", "vertex_size")
            self._drawn["seglist"] = (points, text)
        self.post("VIEW_SEGLIST", text)
        self.post_point("nextpt", nx, ny, active=True)
        return self.objective(osx, osy, heading)

    def _points_text(self) -> str:
        """format_seglist of the points, rebuilt only when they change (it is posted every iteration)."""
        key = self.points.tobytes()
        if self._seglist[0] != key or not self._seglist[1]:
            self._seglist = (key, format_seglist(self.points))
        return self._seglist[1]

    def on_update_applied(self) -> None:
        self.post("BHV_SETTINGS", f"type={self.type_name},name={self.name},points={format_seglist(self.points)},"
                  f"speed={fmt_num(self.speed)}")
