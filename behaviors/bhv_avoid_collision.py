"""BHV_AvoidCollision: keep clear of one contact, judged by the closest point of approach (CPA).

Spawned per contact: a `templating = spawn` block with `updates = CONTACT_INFO` asks the contact
manager at helm start-up for alerts (BCM_ALERT_REQUEST); each alert posts
`CONTACT_INFO = name=<vname> # contact=<vname>`, which makes a copy named `<template><vname>`.

Each iteration (MOOS-IvP's BHV_AvoidCollision and IvPContactBehavior, facts and defaults):
- the contact's last NODE_REPORT (`<CONTACT>_NAV_*` in the info buffer) is extrapolated to now
  along its heading, slowing linearly to a stop between the two `decay` times;
- relevance = 0 beyond `pwt_outer_dist`, 1 within `pwt_inner_dist`, graded (linear, quadratic or
  quasi = power 1.5) between; the function's weight is relevance x pwt, none at relevance 0;
- for every (course, speed) of the domain, the CPA distance over `time_on_leg` seconds of ownship
  on that leg against the contact on its straight track gives the utility: 0 below
  `min_util_cpa_dist` (half the present range when the range is already inside it), 100 above
  `max_util_cpa_dist`, 25..100 linearly between; then normalised to 0..100;
- beyond 1.1 x `completed_dist` (running or idle) it completes: endflags, then the helm drops it.
"""
from __future__ import annotations

import math

import numpy as np

from .behavior import IvPBehavior
from .contacts import closing_speed, extrapolate, leg_cpa, velocity
from .flags import FlagSpec, expand_macros, parse_flag
from .geometry import fmt_num, format_seglist
from .ivp_function import IvPFunction
from .parameters import BOOLEAN, NON_NEGATIVE, Parser, accepted, attr, one_of, pair_bound, param, parse_number

GRADES = {"linear": 1.0, "quasi": 1.5, "quadratic": 2.0}
GRID_VELOCITIES: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}   # per domain grid: ownship (vx, vy)


def _decay(value: str, key: str) -> tuple[float, float]:
    start, sep, end = value.partition(",")
    first, last = parse_number(start, f"{key} start", 0), parse_number(end, f"{key} end", 0) if sep else None
    if last is None or last < first:
        raise ValueError(f"{key} must be start,end seconds with 0 <= start <= end, got '{value}'")
    return first, last


def _bearing_lines(value: str, key: str) -> tuple[str, list[tuple[str, float]]]:
    """`white:0, green:0.65, yellow:0.8, red:1.0[, info:range]`: the colour of the first threshold at or
    above the relevance (or range) draws the ownship-contact line."""
    info, steps = "relevance", []
    for item in value.split(","):
        left, _, right = (p.strip() for p in item.partition(":"))
        if left.lower() == "info" and right.lower() in ("range", "relevance"):
            info = right.lower()
        else:
            steps.append((left, parse_number(right, f"{key} {left}")))
    return info, steps


def _contact_flag(value: str, key: str) -> FlagSpec:
    flag = parse_flag(value)
    if flag is None or not (flag.tag == "@cpa" or (flag.tag[:2] in ("@<", "@>") and
                                                     parse_number(flag.tag[2:], key) >= 0)):
        raise ValueError(f"{key} must be '@<N VAR=value', '@>N VAR=value' or '@cpa VAR=value', got '{value}'")
    return flag


class BHV_AvoidCollision(IvPBehavior):
    type_name = "BHV_AvoidCollision"
    default_name = "avoid_collision"
    info_vars = ("NAV_X", "NAV_Y", "NAV_SPEED", "NAV_HEADING")
    uses_contacts = True
    params = (
        attr("extrapolate", "extrapolate", BOOLEAN, "true", "extrapolate the contact's last report to now"),
        attr("decay", "decay", Parser("start,end seconds", _decay), "15,30",
             "extrapolation at full speed until start, slowing to a stop at end"),
        attr("on_no_contact_ok", "on_no_contact_ok", BOOLEAN, "true",
             "no report of the contact yet is a warning (false: a behaviour error)"),
        attr("time_on_leg", "time_on_leg", NON_NEGATIVE, "120", "seconds of each candidate leg judged for CPA"),
        attr("completed_dist", "completed_dist", NON_NEGATIVE, "500",
             "beyond 1.1 x this range the behaviour completes (and a spawned one dies)"),
        attr("pwt_grade", "pwt_grade", one_of("linear", "quadratic", "quasi"), "quasi",
             "growth of the weight from pwt_outer_dist in to pwt_inner_dist"),
        attr("bearing_line_config", "bearing_lines", Parser("color:threshold,...[,info:range]", _bearing_lines),
             doc="draw the ownship-contact line (VIEW_SEGLIST) coloured by relevance (or range)"),
        attr("no_alert_request", "no_alert_request", BOOLEAN, "false",
             "a spawning template does not post BCM_ALERT_REQUEST at helm start"),
        attr(("match_contact_group", "match_group"), "match_group", doc="only a contact of this group (else complete)"),
        attr(("ignore_contact_group", "ignore_group"), "ignore_group", doc="never a contact of this group (complete)"),
        pair_bound("pwt_inner_dist", "pwt_inner_dist", "pwt_outer_dist", True, "50",
                   "within this range the weight is full; raises pwt_outer_dist to it if needed"),
        pair_bound("pwt_outer_dist", "pwt_inner_dist", "pwt_outer_dist", False, "200",
                   "beyond this range the weight is 0 (no function); lowers pwt_inner_dist to it if needed"),
        pair_bound("min_util_cpa_dist", "min_util_cpa_dist", "max_util_cpa_dist", True, "10",
                   "a leg whose CPA is closer has utility 0; raises max_util_cpa_dist to it if needed"),
        pair_bound("max_util_cpa_dist", "min_util_cpa_dist", "max_util_cpa_dist", False, "75",
                   "a leg whose CPA is farther has utility 100; lowers min_util_cpa_dist to it if needed"),
        accepted(("use_refinery", "check_plateaus", "check_validity", "verbose"),
                 "accepted: the CPA refinery speeds up the C++ piecewise build; this helm evaluates every grid "
                 "point exactly", BOOLEAN),
        accepted(("pcheck_thresh", "roc_max_heighten", "roc_max_dampen"),
                 "accepted, no effect (the C++ behaviour does not use them either)", NON_NEGATIVE),
    )

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.contact = ""
        self.pwt_inner_dist, self.pwt_outer_dist = 50.0, 200.0
        self.min_util_cpa_dist, self.max_util_cpa_dist = 10.0, 75.0
        self.contact_flags: list[FlagSpec] = []
        self.range: float | None = None
        self.closing = 0.0
        self.relevance = 0.0
        self.line_drawn = False
        self.filtered_out = False

    # ---- parameters -------------------------------------------------------------------
    @param("contact", "them", parse=Parser("vehicle name", lambda value, key: value.strip()),
           doc="the vehicle to avoid (its NODE_REPORTs); a template has it set by its spawning update")
    def _set_contact(self, name: str) -> None:
        self.contact = name

    @param("cnflag", parse=Parser("@<N \\| @>N \\| @cpa VAR=value", _contact_flag),
           doc="posted when the range drops below N, rises above N, or at the closest approach; macros "
               "`$[RANGE]`, `$[ROC]` (closing speed), `$[CONTACT]`")
    def _add_contact_flag(self, flag: FlagSpec) -> None:
        self.contact_flags.append(flag)

    # ---- helm start, macros ----------------------------------------------------------
    def on_helm_start(self) -> None:
        """A spawning template asks the contact manager to alert it (MOOS-IvP's onHelmStart)."""
        if self.templating != "spawn" or not self.updates_var or self.no_alert_request:
            return
        request = (f"id={self.name}, on_flag={self.updates_var}=name=$[VNAME] # contact=$[VNAME],"
                   f"alert_range={fmt_num(self.pwt_outer_dist, 1)}, cpa_range={fmt_num(self.completed_dist, 1)}")
        for key, group in (("match_group", self.match_group), ("ignore_group", self.ignore_group)):
            if group:
                request += f",{key}={group}"
        self.post("BCM_ALERT_REQUEST", request)

    def macro(self, name: str):
        n = name.upper()
        if n == "CONTACT":
            return self.contact
        if n == "RANGE":
            return round(self.range, 1) if self.range is not None else None
        if n == "ROC":
            return round(self.closing, 2)
        return super().macro(name)

    # ---- the contact -----------------------------------------------------------------
    def contact_state(self) -> tuple[float, float, float, float, float, float, float, float] | None:
        """Ownship x, y, heading, speed and the contact's (extrapolated) x, y, heading, speed, or None."""
        if not self.contact:
            self.post("BHV_ERROR", f"{self.name}: contact ID not set.", repeatable=True)
            return None
        own = [self.info.number(v) for v in ("NAV_X", "NAV_Y", "NAV_HEADING", "NAV_SPEED")]
        if any(v is None for v in own):
            self.post("BHV_ERROR", f"{self.name}: ownship x,y,heading, or speed info not found.", repeatable=True)
            return None
        cn = self.contact.upper()
        cnx, cny, cnh, cnv, utc = (self.info.number(f"{cn}_NAV_{v}") for v in ("X", "Y", "HEADING", "SPEED", "UTC"))
        if any(v is None for v in (cnx, cny, cnh, cnv, utc)):
            message = f"{self.name}: {cn} x/y/heading/speed info not found"
            self.post("BHV_WARNING" if self.on_no_contact_ok else "BHV_ERROR", message, repeatable=True)
            return None
        group = str(self.info.get(f"{cn}_NAV_GROUP") or "").lower()
        self.filtered_out = bool((self.match_group and self.match_group.lower() != group) or
                                 (self.ignore_group and self.ignore_group.lower() == group))
        if self.extrapolate:
            age = self.now - utc
            if age < -0.1:
                self.post("BHV_WARNING", f"{self.name}: Incomplete Linear Extrapolation: negative delta time, "
                          f"possible clock skew, delta_time={age:.5f}", repeatable=True)
            else:
                cnx, cny = extrapolate(cnx, cny, cnv, cnh, age, *self.decay)
        osx, osy, osh, osv = own
        return osx, osy, osh % 360, osv, cnx, cny, cnh % 360, cnv

    def update_range(self, state) -> None:
        osx, osy, osh, osv, cnx, cny, cnh, cnv = state
        before, closing_before = self.range, self.closing
        self.range = math.hypot(osx - cnx, osy - cny)
        self.closing = closing_speed(*state)
        cn = self.contact.upper()
        self.post(f"CLSG_SPD_AVD_{cn}", round(self.closing, 1))
        self.post(f"RANGE_AVD_{cn}", self.range if self.range <= 10 else float(round(self.range)))
        for flag in self.contact_flags:
            if self.contact_flag_due(flag, before, closing_before) and flag.holds(self.info.get):
                self.post(flag.var, expand_macros(flag.value, self.macro), key="cnflag" + flag.var, repeatable=True)

    def contact_flag_due(self, flag: FlagSpec, before: float | None, closing_before: float) -> bool:
        if flag.tag == "@cpa":
            return before is not None and closing_before > 0 >= self.closing
        limit = float(flag.tag[2:])
        if flag.tag.startswith("@<"):
            return self.range < limit and (before is None or before >= limit)
        return self.range > limit and before is not None and before <= limit

    def relevance_now(self) -> float:
        if self.range >= self.pwt_outer_dist:
            return 0.0
        span = self.pwt_outer_dist - self.pwt_inner_dist
        fraction = min((self.pwt_outer_dist - self.range) / span, 1.0) if span > 0 else 1.0
        return fraction ** GRADES[self.pwt_grade]

    def objective(self, state) -> IvPFunction:
        """Utility of each (course, speed) from its CPA with the contact, normalised to 0..100."""
        osx, osy, _, _, cnx, cny, cnh, cnv = state
        ovx, ovy = self.grid_velocities()
        cpa = leg_cpa(osx - cnx, osy - cny, ovx, ovy, *velocity(cnh, cnv), self.time_on_leg)
        low = self.range / 2 if self.range <= self.min_util_cpa_dist else self.min_util_cpa_dist
        high = self.max_util_cpa_dist
        if high > low:       # 25..100 between, then 0 below low and 100 above high
            utility = np.clip(cpa, low, high)
            utility -= low
            utility *= 75.0 / (high - low)
            utility += 25.0
        else:
            utility = np.full(cpa.shape, 100.0)
        utility[cpa < low] = 0.0
        lo, hi = float(utility.min()), float(utility.max())
        if hi > lo:
            utility = (utility - lo) * (100.0 / (hi - lo))
        return IvPFunction(("course", "speed"), utility, self.relevance * self.pwt)

    def grid_velocities(self) -> tuple[np.ndarray, np.ndarray]:
        """Ownship's (vx, vy) at every (course, speed) of the domain, computed once per domain grid;
        single precision halves the per-iteration work, and a centimetre is all the CPA needs."""
        course, speed = self.domain.var("course"), self.domain.var("speed")
        key = (course.low, course.high, course.npts, speed.low, speed.high, speed.npts)
        if key not in GRID_VELOCITIES:
            vx, vy = velocity(course.values[:, None], speed.values[None, :])
            GRID_VELOCITIES[key] = (vx.astype(np.float32), vy.astype(np.float32))
        return GRID_VELOCITIES[key]

    def draw_bearing_line(self, state, active: bool) -> None:
        if not self.bearing_lines or not self.bearing_lines[1] or (not active and not self.line_drawn):
            return
        info, steps = self.bearing_lines
        osx, osy, _, _, cnx, cny, _, _ = state
        index = self.range if info == "range" else self.relevance
        color = next((c for c, limit in steps if index <= limit), "blank")
        line = f"{format_seglist(np.array([[osx, osy], [cnx, cny]]))},label={self.ownship}_{self.name}"
        self.post("VIEW_SEGLIST", f"{line},label_color=white,edge_color={color}" if active else f"{line},active=false")
        self.line_drawn = active

    # ---- life cycle ------------------------------------------------------------------
    def completes(self) -> bool:
        """Out of range (1.1 x completed_dist, so a contact manager alerting at that range does not
        re-spawn it at once) or filtered out by the group rules."""
        return self.filtered_out or self.range >= 1.1 * self.completed_dist

    def on_idle_state(self) -> None:
        state = self.contact_state()
        if state is None:
            return
        self.update_range(state)
        if self.completes():
            self.set_complete()

    def on_run_state(self) -> IvPFunction | None:
        state = self.contact_state()
        if state is None:
            return None
        self.update_range(state)
        if self.completes():
            self.draw_bearing_line(state, active=False)
            self.set_complete()
            return None
        self.relevance = self.relevance_now()
        if self.relevance <= 0:
            self.draw_bearing_line(state, active=False)
            return None
        self.draw_bearing_line(state, active=True)
        return self.objective(state)
