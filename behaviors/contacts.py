"""Contacts as contact behaviours and contact apps see them: NODE_REPORTs read into records, the
helm's ledger of them, the contact's extrapolated position, and the closest point of approach (CPA),
over a course x speed grid for the helm or for one course for pContactMgrV20 and uFldCollisionDetect.

The helm turns each `NODE_REPORT` into info-buffer values named after the vehicle, upper-cased
(`HENRY_NAV_X`, `_NAV_Y`, `_NAV_SPEED`, `_NAV_HEADING`, `_NAV_DEPTH`, `_NAV_UTC`, `_NAV_GROUP`,
`_NAV_TYPE`), as MOOS-IvP's helm does; a contact behaviour reads those.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from moosdb_py.formats import FormatError, parse_number, parse_pairs

from .geometry import are_floats
from .logic import as_number

# NODE_REPORT field -> info-buffer suffix; keys are matched without regard to case.
NUMERIC_FIELDS = {"x": "NAV_X", "y": "NAV_Y", "spd": "NAV_SPEED", "hdg": "NAV_HEADING", "dep": "NAV_DEPTH",
                  "depth": "NAV_DEPTH", "lat": "NAV_LAT", "lon": "NAV_LONG", "long": "NAV_LONG"}
TIME_FIELDS = ("time", "utc_time", "moos_time")
TEXT_FIELDS = {"group": "NAV_GROUP", "type": "NAV_TYPE"}
REQUIRED = ("NAV_X", "NAV_Y", "NAV_SPEED", "NAV_HEADING", "NAV_UTC")


class NodeRecordError(ValueError):
    """A node report (or node message) that cannot be used; the message quotes it."""


def _number(fields: dict[str, str], key: str, text: str, default: float | None = None) -> float | None:
    raw = fields.get(key)
    if raw is None or raw == "":
        return default
    try:
        return parse_number(raw)
    except FormatError as exc:
        raise NodeRecordError(f"{key.upper()}: {exc} in {text!r}") from None


@dataclass(frozen=True)
class NodeRecord:
    """One vehicle's NODE_REPORT (`NAME=..,X=..,Y=..,SPD=..,HDG=..`, keys in any case, LONG for LON,
    DEPTH for DEP): position (local x/y), motion, identity, and every field as received."""

    name: str
    x: float
    y: float
    speed: float = 0.0
    heading: float = 0.0
    depth: float = 0.0
    time: float | None = None
    group: str = ""
    type: str = ""
    length: float = 0.0
    fields: tuple[tuple[str, str], ...] = ()   # every key=value as received (keys lower-cased)
    text: str = ""

    @classmethod
    def parse(cls, text: str, grid=None) -> "NodeRecord":
        """Read a report; one with only LAT/LON is placed with `grid` (the mission's LocalGrid)."""
        try:
            fields = parse_pairs(text)
        except FormatError as exc:
            raise NodeRecordError(f"NODE_REPORT {text!r}: {exc}") from None
        name = fields.get("name", "")
        if not name:
            raise NodeRecordError(f"NODE_REPORT without NAME: {text!r}")
        if "lon" not in fields and "long" in fields:
            fields["lon"] = fields["long"]
        x, y = _number(fields, "x", text), _number(fields, "y", text)
        if x is None or y is None:
            lat, lon = _number(fields, "lat", text), _number(fields, "lon", text)
            if grid is None or lat is None or lon is None:
                raise NodeRecordError(f"NODE_REPORT without X/Y (or LAT/LON and a LatOrigin): {text!r}")
            x, y = grid.to_local(lat, lon)
        depth = _number(fields, "dep", text, None)
        stamps = (_number(fields, key, text, None) for key in TIME_FIELDS)
        return cls(name=name, x=float(x), y=float(y), speed=_number(fields, "spd", text, 0.0),
                   heading=_number(fields, "hdg", text, 0.0) % 360.0,
                   depth=depth if depth is not None else _number(fields, "depth", text, 0.0),
                   time=next((stamp for stamp in stamps if stamp is not None), None),
                   group=fields.get("group", ""), type=fields.get("type", ""),
                   length=_number(fields, "length", text, 0.0), fields=tuple(fields.items()), text=text)

    def field(self, key: str, default: str = "") -> str:
        """The value of a report key as it was written (`x`, `spd`, `lat`, ...)."""
        return dict(self.fields).get(key, default)

    def dead_reckoned(self, elapsed: float, decay_start: float, decay_end: float) -> tuple[float, float]:
        """Where the vehicle is `elapsed` s after the report, holding its course (see `extrapolate`)."""
        return extrapolate(self.x, self.y, self.speed, self.heading, elapsed, decay_start, decay_end)


def node_report_values(report: str, grid=None) -> dict[str, float | str] | None:
    """The info-buffer values of one NODE_REPORT, or None when it lacks a name, position, speed,
    heading or time (such a report tells a contact behaviour nothing it can use). A report with
    only LAT/LON (pNodeReporter's `coord_policy_global = true`, as in m2_berta) is placed with `grid`,
    the mission's LocalGrid, as the C++ helm places it about LatOrigin/LongOrigin."""
    try:
        fields = parse_pairs(report)
    except FormatError:
        return None
    name = fields.get("name", "").upper()
    values: dict[str, float | str] = {}
    for key, suffix in NUMERIC_FIELDS.items():
        number = as_number(fields.get(key, ""))
        if number is not None:
            values[suffix] = number
    if grid is not None and ("NAV_X" not in values or "NAV_Y" not in values):
        lat, lon = as_number(fields.get("lat", "")), as_number(fields.get("lon", fields.get("long", "")))
        if lat is not None and lon is not None:
            values["NAV_X"], values["NAV_Y"] = grid.to_local(lat, lon)
    stamps = [as_number(fields[k]) for k in TIME_FIELDS if k in fields]
    stamp = next((s for s in stamps if s is not None), None)
    if stamp is not None:
        values["NAV_UTC"] = stamp
    values.update({suffix: fields[key] for key, suffix in TEXT_FIELDS.items() if key in fields})
    if not name or any(k not in values for k in REQUIRED):
        return None
    return {f"{name}_{suffix}": value for suffix, value in values.items()}


def extrapolate(x: float, y: float, speed: float, heading: float, age: float, decay_start: float,
                decay_end: float) -> tuple[float, float]:
    """Where a contact last seen `age` seconds ago is now: straight on at its speed until
    `decay_start`, then slowing linearly to a stop at `decay_end` (MOOS-IvP's LinearExtrapolator)."""
    if age <= 0:
        return x, y
    if age <= decay_start:
        travelled = speed * age
    elif decay_end <= decay_start:
        travelled = speed * decay_start
    else:
        slowing = min(age, decay_end) - decay_start
        now_speed = speed * (1 - slowing / (decay_end - decay_start))
        travelled = speed * decay_start + (speed + now_speed) / 2 * slowing
    a = math.radians(heading)
    return x + travelled * math.sin(a), y + travelled * math.cos(a)


def velocity(heading, speed):
    """(vx, vy) of a marine heading (degrees, 0 = north, 90 = east) and a speed; numpy-friendly,
    plain math for two floats (the closing speed asks for single ones every iteration)."""
    if are_floats(heading, speed):
        a = math.radians(heading)
        return speed * math.sin(a), speed * math.cos(a)
    a = np.radians(heading)
    return np.multiply(speed, np.sin(a)), np.multiply(speed, np.cos(a))


def cpa_distance(osx: float, osy: float, os_heading, os_speed, cnx: float, cny: float, cnh: float,
                 cnv: float, time_on_leg: float) -> np.ndarray:
    """Closest distance between ownship on each (heading, speed) and the contact on its straight track,
    over the next `time_on_leg` seconds; broadcasts over array headings and speeds."""
    ovx, ovy = np.broadcast_arrays(*velocity(os_heading, os_speed))
    cpa = leg_cpa(osx - cnx, osy - cny, np.atleast_1d(ovx), np.atleast_1d(ovy), *velocity(cnh, cnv), time_on_leg)
    return cpa.reshape(ovx.shape)


def leg_cpa(rx: float, ry: float, ovx, ovy, cvx: float, cvy: float, time_on_leg: float) -> np.ndarray:
    """The CPA from ownship-minus-contact position (rx, ry), ownship velocities (arrays) and the
    contact's velocity. In place and without hypot or masked division: the helm runs this for every
    contact every iteration (numpy's hypot is several times slower than sqrt of the squares). The
    scalars enter as Python floats, so single-precision grids stay single precision."""
    rx, ry, cvx, cvy = float(rx), float(ry), float(cvx), float(cvy)
    vx = ovx - cvx
    vy = ovy - cvy
    vv = vx * vx
    vv += vy * vy
    t = vx * rx
    t += vy * ry
    t /= -np.maximum(vv, 1e-12)       # where the relative velocity is 0, so is the numerator: t = 0
    np.clip(t, 0.0, time_on_leg, out=t)
    vx *= t
    vx += rx
    vy *= t
    vy += ry
    vx *= vx
    vy *= vy
    vx += vy
    return np.sqrt(vx, out=vx)


def closing_speed(osx: float, osy: float, osh: float, osv: float, cnx: float, cny: float, cnh: float,
                  cnv: float) -> float:
    """How fast the range is shrinking now (m/s; negative when opening)."""
    rx, ry = osx - cnx, osy - cny
    rng = math.hypot(rx, ry)
    if rng == 0:
        return 0.0
    vx, vy = _relative_velocity(osh, osv, cnh, cnv)
    return -(rx * vx + ry * vy) / rng


def _relative_velocity(osh: float, osv: float, cnh: float, cnv: float) -> tuple[float, float]:
    """Ownship's velocity minus the contact's, for one heading and speed each: plain floats (`velocity`'s
    scalar form), as numpy on scalars costs ten times more (the contact manager asks this of every
    contact every iteration)."""
    (ovx, ovy), (cvx, cvy) = velocity(float(osh), float(osv)), velocity(float(cnh), float(cnv))
    return ovx - cvx, ovy - cvy


def cpa_range(osx: float, osy: float, osh: float, osv: float,
              cnx: float, cny: float, cnh: float, cnv: float, horizon: float) -> float:
    """Closest distance between ownship and contact over the next `horizon` s, both holding course and
    speed: `cpa_distance` for one heading and speed, in plain floats."""
    rx, ry = osx - cnx, osy - cny
    vx, vy = _relative_velocity(osh, osv, cnh, cnv)
    vv = vx * vx + vy * vy
    t = min(max(-(vx * rx + vy * ry) / max(vv, 1e-12), 0.0), horizon)    # as leg_cpa, even below 1e-6 m/s
    return math.hypot(rx + vx * t, ry + vy * t)


def relative_bearing(osx: float, osy: float, osh: float, cnx: float, cny: float) -> float:
    """Bearing of the contact from ownship's bow, degrees in [0, 360)."""
    absolute = math.degrees(math.atan2(cnx - osx, cny - osy))
    return (absolute - osh) % 360.0
