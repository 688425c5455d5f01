"""What the operations map shows, as plain data: MOOS strings in, JSON-ready updates out.

Pure (no sockets, no clocks): `Scene.apply(key, value, ...)` turns one piece of shoreside mail
into the updates the page needs, and `Scene.snapshot()` is everything a newly opened page needs.
The live app and the alog replay feed the same Scene, so the page cannot tell them apart.
Formats: NODE_REPORT from docs/spec/field-apps.md §3.3, VIEW_* and geometry strings from docs/spec/ivp-helm.md §5.7,
§6.5 and §8.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import shapely

from behaviors.contacts import NodeRecord, NodeRecordError
from behaviors.geometry import GeometryError, parse_point, parse_polygon, parse_seglist
from moosdb_py.formats import FormatError, parse_bool, parse_pairs, split_fields, unquote
from oilspill_moos import messages
from oilspill_moos.messages import parse_observation

VIEW_KINDS = {"VIEW_POLYGON": "polygon", "VIEW_SEGLIST": "seglist", "VIEW_POINT": "point"}
# Shoreside variables the map is drawn from; the *-suffixed ones are per vehicle (…_ABE).
NOTE_KEYS = {"OILSPILL_WARNING": "warning", "OILSPILL_DROPPED": "dropped", "OILSPILL_REJOINED": "rejoined",
             "OIL_FUSION_WARNING": "warning"}
# NODE_REPORT_LOCAL: a single-vehicle mission's own pNodeReporter (no shoreside to bridge it to NODE_REPORT).
REPORT_KEYS = ("NODE_REPORT", "NODE_REPORT_LOCAL")
SUBSCRIPTIONS = (*REPORT_KEYS, *VIEW_KINDS, "OILSPILL_BOUNDARY", "OILSPILL_FORECAST", "OILSPILL_STATUS",
                 *NOTE_KEYS, "OIL_OBSERVATION", "OIL_OBSERVED_EDGE", "OIL_FUSION_SKILL")
WILDCARDS = ("OILSPILL_PHASE*", "STARTING_POSITION_UPDATES_*", "OIL_PATH_UPDATES_*")


class ViewError(ValueError):
    """A NODE_REPORT, VIEW_* or update string the map cannot draw; the message quotes it."""


@dataclass(frozen=True)
class NodeReport:
    name: str
    x: float
    y: float
    heading: float = 0.0
    speed: float = 0.0
    mode: str = ""
    type: str = ""
    color: str = ""
    length: float = 0.0
    time: float | None = None

    @property
    def phase(self) -> str:
        """The helm's leaf mode: `MODE@ACTIVE:OIL-PATH` -> `OIL-PATH`, `MODE@INACTIVE` -> `INACTIVE`."""
        return self.mode.rpartition("@")[2].rpartition(":")[2] or self.mode


def parse_node_report(text: str, grid=None) -> NodeReport:
    """A NODE_REPORT (keys in any case, LONG as well as LON); a report with only LAT/LON is placed
    with `grid` (the mission's LocalGrid), as with `coord_policy_global`."""
    try:
        record = NodeRecord.parse(text, grid)
    except NodeRecordError as exc:
        raise ViewError(str(exc)) from None
    return NodeReport(name=record.name, x=record.x, y=record.y, heading=record.heading, speed=record.speed,
                      mode=record.field("mode"), type=record.type, color=record.field("color"),
                      length=record.length, time=record.time)


def _properties(key: str, text: str) -> dict[str, str]:
    """The `key=value` fields of a VIEW_* string (keys lower-cased), split as every MOOS string is
    (formats.split_fields: commas inside `pts={...}` or quotes do not split; quotes go); a bare word is no field."""
    for prefix in ("radial::", "format=radial"):
        if text.lower().lstrip().startswith(prefix):
            text = text.lstrip()[len(prefix):]
    try:
        items = split_fields(text)
    except FormatError as exc:
        raise ViewError(f"{key} {text[:80]!r}: {exc}") from None
    props = {}
    for item in items:
        name, sep, value = item.partition("=")
        if sep and name.strip():
            props[name.strip().lower()] = unquote(value)
    return props


@dataclass(frozen=True)
class Marker:
    """One VIEW_POLYGON / VIEW_SEGLIST / VIEW_POINT: drawn while active, erased by label."""

    kind: str
    label: str
    points: tuple[tuple[float, float], ...]
    active: bool = True
    style: tuple[tuple[str, str], ...] = ()   # edge_color, vertex_size, ... as posted

    def as_update(self) -> dict:
        return {"t": "marker", "kind": self.kind, "label": self.label, "active": self.active,
                "points": [list(p) for p in self.points], "style": dict(self.style)}


def parse_view(key: str, text: str) -> Marker:
    """A VIEW_POLYGON (point list or radial form), VIEW_SEGLIST or VIEW_POINT string.

    An inactive marker may come without geometry: it only names what to erase."""
    kind = VIEW_KINDS.get(key)
    if kind is None:
        raise ViewError(f"{key} is not a VIEW_POLYGON, VIEW_SEGLIST or VIEW_POINT")
    props = _properties(key, text)
    try:
        active = parse_bool(props.pop("active", "true"))
    except FormatError as exc:
        raise ViewError(f"{key} {text[:80]!r}: active: {exc}") from None
    label = props.pop("label", "")
    try:
        if kind == "point":
            points = [parse_point(text)]
        elif kind == "polygon" and "pts={" not in text.replace(" ", "").lower():
            points = parse_polygon(text).tolist()   # radial forms (always convex); spills are point lists
        else:
            points = parse_seglist(text).tolist()
    except GeometryError as exc:
        if active:
            raise ViewError(f"{key} {text!r}: {exc}") from None
        points = []
    for name in ("x", "y", "pts", "radius", "snap", "format"):
        props.pop(name, None)
    return Marker(kind, label or f"{kind}-{text.strip()[:40]}", tuple(map(tuple, points)), active,
                  tuple(sorted(props.items())))


@dataclass(frozen=True)
class Forecast:
    """One horizon of a forecast (pPathAssign's OILSPILL_FORECAST) and its uncertainty band:
    the ground within `uncertainty_m` of the outline, i.e. the outline buffered out minus it
    buffered in, as rings to fill even-odd."""

    cycle: int
    horizon_h: float
    points: tuple[tuple[float, float], ...]
    uncertainty_m: float = 0.0
    valid: float | None = None
    source: str = ""
    band: tuple[tuple[tuple[float, float], ...], ...] = ()

    def as_update(self) -> dict:
        return {"cycle": self.cycle, "horizon": self.horizon_h, "valid": self.valid, "uncertainty": self.uncertainty_m,
                "source": self.source, "points": [list(p) for p in self.points],
                "band": [[list(p) for p in ring] for ring in self.band]}


def uncertainty_band(points, width: float) -> tuple:
    """Rings (outer and holes, decimetres) of the ground within `width` of the closed outline."""
    if width <= 0:
        return ()
    ring = shapely.LinearRing(points)
    band = shapely.buffer(ring, width, quad_segs=4)
    return tuple(tuple(map(tuple, np.round(shapely.get_coordinates(r), 1).tolist()))
                 for r in shapely.get_rings(shapely.get_parts(band)))


def parse_forecast(text: str) -> Forecast:
    """`cycle=2,horizon=7,valid=<utc>,uncertainty=120,source=ltc-rk4,pts={x,y:...}` (pPathAssign),
    read by the mission's one codec (oilspill_moos.messages.parse_forecast)."""
    try:
        boundary, cycle = messages.parse_forecast(text)
    except messages.BoundaryError as exc:
        raise ViewError(f"OILSPILL_FORECAST {text[:80]!r}: {exc}") from None
    return Forecast(cycle=cycle, horizon_h=boundary.horizon_h, points=boundary.polygon,
                    uncertainty_m=boundary.uncertainty_m, valid=boundary.time, source=boundary.source,
                    band=uncertainty_band(boundary.polygon, boundary.uncertainty_m))


def _points_update(text: str, what: str) -> list[list[float]]:
    """`points=x,y:x,y[#repeat=forever#...]` (pPathAssign's STARTING_POSITION / OIL_PATH updates)."""
    body = text.split("#")[0].strip()
    key, sep, value = body.partition("=")
    if not sep or key.strip().lower() != "points":
        raise ViewError(f"{what} {text!r}: expected points=x,y:...")
    try:
        return parse_seglist(value).tolist()
    except GeometryError as exc:
        raise ViewError(f"{what} {text!r}: {exc}") from None


def _fields(key: str, text: str) -> list[list[str]]:
    """A `key=value` status line as [key, value] rows, for the page to show one field a row."""
    try:
        return [list(pair) for pair in parse_pairs(text).items()]
    except ValueError as exc:
        raise ViewError(f"{key} {text[:80]!r}: {exc}") from None


def _suffix(key: str, prefix: str) -> str:
    return key[len(prefix):].lstrip("_").lower()


@dataclass(frozen=True)
class Button:
    """A pMarineViewer button: `button_one = DEPLOY # DEPLOY_ALL=true # MOOS_MANUAL_OVERRIDE_ALL=false`."""

    label: str
    pokes: tuple[tuple[str, float | str], ...]


def _poke_value(raw: str) -> float | str:
    if len(raw) >= 2 and raw[0] == raw[-1] == '"':
        return raw[1:-1]
    try:
        value = float(raw)
    except ValueError:
        return raw
    return value if math.isfinite(value) else raw


def parse_button(text: str) -> Button:
    """One `button_<n>` line: `#`-separated items, the one without `=` the label (optional: a
    repeated `button_one = MOOS_MANUAL_OVERRIDE_ALL=false` line adds pokes to button one), the
    others `VAR=value` pokes. Numbers are poked as doubles, anything else (or a "quoted" number) as
    a string, as pMarineViewer does."""
    label, pokes = "", []
    for item in (part.strip() for part in text.split("#")):
        key, sep, raw = item.partition("=")
        key, raw = key.strip(), raw.strip()
        if not sep:
            if label or not item:
                raise ViewError(f"button {text!r}: expected LABEL # VAR=value # ...")
            label = item
        elif not key or " " in key:
            raise ViewError(f"button {text!r}: {item!r} is not VAR=value")
        else:
            pokes.append((key, _poke_value(raw)))
    return Button(label, tuple(pokes))


def merge_button(lines: list[Button]) -> Button:
    """The lines of one button joined: the first label (else the first poke's text), every poke in order."""
    pokes = tuple(p for line in lines for p in line.pokes)
    if not pokes:
        raise ViewError(f"button {lines[0].label!r}: no VAR=value to poke")
    key, value = pokes[0]
    label = next((line.label for line in lines if line.label), f"{key}={value:g}" if isinstance(value, float)
                 else f"{key}={value}")
    return Button(label, pokes)


def parse_action(text: str) -> Button:
    """A pMarineViewer `action` menu line: `MENU_KEY=deploy # DEPLOY=true # RETURN=false` (named by
    its MENU_KEY) or plain `RETURN=true` (named by itself)."""
    line = parse_button(text)
    if line.label or not line.pokes:
        raise ViewError(f"action {text!r}: expected [MENU_KEY=name #] VAR=value # ...")
    (key, value), *rest = line.pokes
    if key.upper() == "MENU_KEY":
        if not rest:
            raise ViewError(f"action {text!r}: MENU_KEY without a VAR=value to poke")
        return Button(str(value), tuple(rest))
    return merge_button([line])


@dataclass
class Vehicle:
    report: NodeReport
    seen: float                                  # MOOS time of the last report
    trail: deque = field(default_factory=deque)  # (x, y) pairs, oldest first

    def as_update(self) -> dict:
        r = self.report
        return {"t": "vehicle", "name": r.name, "x": r.x, "y": r.y, "hdg": r.heading, "spd": r.speed,
                "mode": r.mode, "phase": r.phase, "type": r.type, "color": r.color, "len": r.length,
                "seen": self.seen}


@dataclass
class Scene:
    """The operations picture of one shoreside community."""

    trail_length: int = 200
    grid: object | None = None                   # LocalGrid for LAT/LON-only reports
    vehicles: dict[str, Vehicle] = field(default_factory=dict)
    markers: dict[tuple[str, str], Marker] = field(default_factory=dict)
    boundary: list[list[float]] | None = None
    boundary_text: str = ""
    forecasts: dict[float, Forecast] = field(default_factory=dict)   # by horizon, all of one cycle
    starts: dict[str, list[float]] = field(default_factory=dict)
    loops: dict[str, list[list[float]]] = field(default_factory=dict)
    phase: str = ""
    commanded: dict[str, str] = field(default_factory=dict)   # OILSPILL_PHASE_<V>: what the shore asked
    status: str = ""
    notes: deque = field(default_factory=lambda: deque(maxlen=50))
    observations: deque = field(default_factory=lambda: deque(maxlen=1000))   # the vessels' oil samples
    observed_edge: list[list[float]] = field(default_factory=list)           # uFldOilFusion's flip points
    skill: str = ""
    ended: str = ""                              # why the mission is over (the last picture stays)

    def apply(self, key: str, value, time: float, community: str = "") -> list[dict]:
        """One piece of mail -> the page updates it causes; raises ViewError on a string it cannot read."""
        text = value if isinstance(value, str) else f"{value:g}" if isinstance(value, float) else str(value)
        if key in REPORT_KEYS:
            return self._report(parse_node_report(text, self.grid), time)
        if key in VIEW_KINDS:
            marker = parse_view(key, text)
            if marker.active:
                self.markers[(marker.kind, marker.label)] = marker
            else:
                self.markers.pop((marker.kind, marker.label), None)
            return [marker.as_update()]
        if key == "OILSPILL_BOUNDARY":
            try:
                vertices, fields = messages.parse_polygon_string(text)
            except messages.BoundaryError as exc:
                raise ViewError(f"OILSPILL_BOUNDARY {text[:80]!r}: {exc}") from None
            boundary = [list(v) for v in vertices]
            pushed = text != self.boundary_text
            self.boundary, self.boundary_text = boundary, text
            label = fields.get("label", "")
            return [{"t": "boundary", "points": self.boundary, "label": label},
                    *([self.note("event", f"boundary in force: {label or 'pushed'}, {len(boundary)} vertices", time)]
                      if pushed else [])]
        if key == "OILSPILL_FORECAST":
            forecast = parse_forecast(text)
            fresh = not self.forecasts or any(f.cycle != forecast.cycle for f in self.forecasts.values())
            if fresh:
                self.forecasts = {}   # a new forecast: the horizons of the last one are stale
            self.forecasts[forecast.horizon_h] = forecast
            return [{"t": "forecasts", "forecasts": self._forecast_updates()},
                    *([self.note("event", f"forecast cycle {forecast.cycle} ({forecast.source or 'no source'})",
                                 time)] if fresh else [])]
        if key == "OILSPILL_PHASE":
            changed = text != self.phase
            self.phase = text
            return [{"t": "phase", "phase": text}, *([self.note("phase", f"fleet phase {text}", time)] if changed else [])]
        if key.startswith("OILSPILL_PHASE_"):
            name = _suffix(key, "OILSPILL_PHASE")
            names = list(self.vehicles) if name == "all" else [name]
            self.commanded.update(dict.fromkeys(names, text))
            return [{"t": "commanded", "name": n, "phase": text} for n in names]
        if key.startswith("STARTING_POSITION_UPDATES"):
            name = _suffix(key, "STARTING_POSITION_UPDATES")
            self.starts[name] = _points_update(text, key)[-1]  # the route's end; the points before go round the spill
            return [{"t": "start", "name": name, "point": self.starts[name]}]
        if key.startswith("OIL_PATH_UPDATES"):
            name = _suffix(key, "OIL_PATH_UPDATES")
            self.loops[name] = _points_update(text, key)
            return [{"t": "loop", "name": name, "points": self.loops[name]}]
        if key == "OILSPILL_STATUS":
            fields = _fields(key, text)
            self.status = text
            return [{"t": "status", "text": text, "fields": fields}]
        if key == "OIL_OBSERVATION":
            try:
                obs = parse_observation(text)
            except ValueError as exc:
                raise ViewError(f"OIL_OBSERVATION: {exc}") from None
            update = {"t": "obs", "vname": obs.vname, "x": obs.x, "y": obs.y, "oil": obs.oil, "range": obs.range_m}
            self.observations.append(update)
            return [update]
        if key == "OIL_OBSERVED_EDGE":
            try:
                self.observed_edge = parse_seglist(text).tolist() if text.strip() else []
            except GeometryError as exc:
                raise ViewError(f"OIL_OBSERVED_EDGE {text!r}: {exc}") from None
            return [{"t": "edge", "points": self.observed_edge}]
        if key == "OIL_FUSION_SKILL":
            fields = _fields(key, text)
            self.skill = text
            return [{"t": "skill", "text": text, "fields": fields}]
        if key in NOTE_KEYS:
            return [self.note(NOTE_KEYS[key], text, time)]
        return []

    def note(self, level: str, text: str, time: float) -> dict:
        """A line for the page's log (warnings, dropped vehicles, refused mail, button presses)."""
        entry = {"t": "note", "level": level, "text": text, "time": time}
        self.notes.append(entry)
        return entry

    def end(self, why: str, time: float) -> list[dict]:
        """The mission is over (its MOOSDB went away, or the viewer is stopping): the page says so and
        keeps the last picture."""
        if self.ended:
            return []
        self.ended = why
        return [{"t": "ended", "text": why, "time": time}, self.note("ended", f"mission ended: {why}", time)]

    def resume(self, why: str, time: float) -> list[dict]:
        """The MOOSDB answers again (a mission started anew on its port)."""
        if not self.ended:
            return []
        self.ended = ""
        return [{"t": "resumed"}, self.note("event", why, time)]

    def _report(self, report: NodeReport, time: float) -> list[dict]:
        """A vehicle's report; its first one and every change of its helm phase go to the log."""
        vehicle = self.vehicles.get(report.name.lower())
        notes = []
        if vehicle is None:
            vehicle = self.vehicles[report.name.lower()] = Vehicle(report, time, deque(maxlen=self.trail_length))
            notes.append(self.note("event", f"{report.name} reporting, {report.phase or 'no helm mode'}", time))
        elif report.phase != vehicle.report.phase:
            notes.append(self.note("phase", f"{report.name}: {vehicle.report.phase or '-'} -> {report.phase}", time))
        vehicle.report, vehicle.seen = report, time
        vehicle.trail.append((report.x, report.y))
        return [vehicle.as_update(), *notes]

    def _forecast_updates(self) -> list[dict]:
        return [self.forecasts[h].as_update() for h in sorted(self.forecasts)]

    def snapshot(self) -> dict:
        """Everything a page needs to draw the picture from scratch."""
        return {"vehicles": [{**v.as_update(), "trail": [list(p) for p in v.trail]} for v in self.vehicles.values()],
                "markers": [m.as_update() for m in self.markers.values()],
                "boundary": self.boundary, "forecasts": self._forecast_updates(), "starts": self.starts,
                "loops": self.loops, "phase": self.phase,
                "commanded": self.commanded, "status": self.status, "notes": list(self.notes),
                "status_fields": _fields("OILSPILL_STATUS", self.status),
                "skill_fields": _fields("OIL_FUSION_SKILL", self.skill),
                "observations": list(self.observations), "observed_edge": self.observed_edge, "skill": self.skill,
                "trail_length": self.trail_length, "ended": self.ended}
