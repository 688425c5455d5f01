"""The oil-spill mission's messages, one codec each, imported by sender and receiver alike.

Each message has its writer and its reader here, built on moosdb_py.formats (booleans, numbers,
key=value lists, seglists), so two apps never keep their own idea of a message:

| Message | Written by | Read by |
|---|---|---|
| boundary line (TCP, JSON or `pts={}`) | the forecaster (`boundary_line`) | pPathAssign (`parse_boundary_line`) |
| `OILSPILL_FORECAST` | pPathAssign (`format_forecast`) | pMarineViewer (`parse_forecast`) |
| `STARTING_POSITION_UPDATES_<V>`, `OIL_PATH_UPDATES_<V>` | pPathAssign (`points_update`) | the helm's BHV_Waypoint (`parse_points_update`) |
| `VEHICLE_COORDINATES` | pCoordinates (`coordinates_report`) | pPathAssign (`parse_report`) |
| `NODE_REPORT` | pNodeReporter | pPathAssign (`parse_report`) |
| `OIL_SENSOR_REQUEST` | pOilSampler (`format_request`) | uFldOilSensor (`parse_request`) |
| `OIL_OBSERVATION`, `OIL_SENSOR_REPORT_<V>` | uFldOilSensor, pOilSampler (`format_observation`) | pOilSampler, uFldOilFusion, pMarineViewer (`parse_observation`) |
| `OILSPILL_BOUNDARY`, `VIEW_POLYGON` | pPathAssign, uFldOilSensor (`polygon_string`) | uFldOilFusion (`parse_polygon_string`), viewers |
"""
from __future__ import annotations

import json
import math
import re
import time as _time
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from moosdb_py import formats
from moosdb_py.config import parse_float
from moosdb_py.formats import FormatError, format_number, parse_pairs

# ---- the boundary line: forecaster -> pPathAssign over TCP ---------------------------------------


class BoundaryError(ValueError):
    """A boundary line pPathAssign refuses; str() goes back to the sender after `ERR `."""


@dataclass(frozen=True)
class Boundary:
    """A predicted spill outline in local metres, with the forecast it came from."""

    polygon: tuple[tuple[float, float], ...]
    time: float | None = None     # when the outline is valid (UTC s): issue time + horizon
    horizon_h: float = 0.0
    uncertainty_m: float = 0.0
    source: str = "tcp"

    @property
    def issued(self) -> float | None:
        """When the forecast was made; the lines of one forecast (one per horizon) share it."""
        return None if self.time is None else self.time - 3600.0 * self.horizon_h


def boundary_line(polygon, horizon_h: float, *, time: float | None = None, crs: str = "EPSG:4326",
                  uncertainty_m: float = 0.0, source: str = "ltc-rk4") -> bytes:
    """Encode one boundary as the JSON line; `polygon` is a shapely Polygon or a sequence of (x, y)."""
    coords = list(polygon.exterior.coords) if hasattr(polygon, "exterior") else list(polygon)
    if len(coords) < 3:
        raise ValueError(f"a boundary needs at least 3 vertices, got {len(coords)}")
    points = [[float(x), float(y)] for x, y in coords]
    if not all(math.isfinite(v) for p in points for v in p):
        raise ValueError("boundary polygon holds NaN or infinite coordinates")
    if crs not in ("EPSG:4326", "local"):
        raise ValueError(f"crs must be 'EPSG:4326' or 'local', not {crs!r}")
    message = {"type": "boundary", "time": _time.time() if time is None else float(time),
               "horizon_h": float(horizon_h), "crs": crs, "polygon": points,
               "uncertainty_m": float(uncertainty_m), "source": source}
    return (json.dumps(message, separators=(",", ":")) + "\n").encode("utf-8")


def parse_polygon_spec(text: str) -> list[tuple[float, float]]:
    """`pts={x1,y1:x2,y2:...}[,label=..]` -> vertices (a third number per vertex, z, is ignored)."""
    if "pts={" not in "".join(text.split()).lower():
        raise BoundaryError("expected a JSON object or pts={x1,y1:x2,y2:...}")
    try:
        return formats.parse_seglist(text)
    except FormatError as err:
        raise BoundaryError(str(err)) from None


def parse_boundary_line(line: str, grid=None) -> Boundary:
    """One forecaster line -> Boundary in local metres.

    JSON polygons in EPSG:4326 are [lon, lat] pairs (x before y, as pyproj's
    always_xy) and need `grid` (the mission's LatOrigin/LongOrigin).
    """
    text = line.strip()
    if not text:
        raise BoundaryError("empty line")
    if not text.startswith("{"):
        return Boundary(polygon=tuple(parse_polygon_spec(text)), source="pts")
    try:
        message = json.loads(text)
    except json.JSONDecodeError as exc:
        raise BoundaryError(f"bad JSON: {exc.msg} at column {exc.colno}") from None
    if not isinstance(message, dict):
        raise BoundaryError("JSON line must be an object")
    if message.get("type", "boundary") != "boundary":
        raise BoundaryError(f"unknown message type {message.get('type')!r}")
    vertices = message.get("polygon")
    if not isinstance(vertices, list) or not all(isinstance(v, list) and len(v) == 2 for v in vertices):
        raise BoundaryError("'polygon' must be a list of [x, y] pairs")
    try:
        xy = np.asarray(vertices, dtype=float).reshape(-1, 2)
        number = {key: float(message.get(key, default)) for key, default in
                  (("horizon_h", 0.0), ("uncertainty_m", 0.0))}
        stamp = None if message.get("time") is None else float(message["time"])
    except (TypeError, ValueError):
        raise BoundaryError("'polygon', 'time', 'horizon_h' and 'uncertainty_m' must be numbers") from None
    if not np.all(np.isfinite(xy)) or not all(map(math.isfinite, number.values())):
        raise BoundaryError("non-finite number in boundary")
    crs = message.get("crs", "local")
    if crs == "EPSG:4326":
        if grid is None:
            raise BoundaryError("EPSG:4326 boundary but the mission has no LatOrigin/LongOrigin")
        if np.any(np.abs(xy[:, 1]) > 90) or np.any(np.abs(xy[:, 0]) > 180):
            raise BoundaryError("EPSG:4326 polygon must be [lon, lat] pairs in degrees")
        x, y = grid.to_local(xy[:, 1], xy[:, 0])
        xy = np.column_stack([x, y])
    elif crs != "local":
        raise BoundaryError(f"crs must be 'EPSG:4326' or 'local', not {crs!r}")
    return Boundary(polygon=tuple(map(tuple, xy.tolist())), time=stamp, source=str(message.get("source", "json")),
                    **number)


def operating_area(spec: str | None, radius: float) -> Polygon | None:
    """`operating_area` (a pts={} polygon) wins over `operating_radius` (a circle about the origin)."""
    if spec:
        return Polygon(parse_polygon_spec(spec))
    return shapely.buffer(Point(0.0, 0.0), radius) if radius > 0 else None


# ---- pPathAssign's posts ---------------------------------------------------------------------------


def format_points(points: Iterable[Iterable[float]]) -> str:
    """Vertices as the `x,y:x,y` list BHV_Waypoint reads (decimetre precision)."""
    return formats.format_points(points, 1, fixed=True)


def points_update(points: Iterable[Iterable[float]], **extra: str | float) -> str:
    """A BHV_Waypoint update: `points=x,y:...` then `#key=value` for each extra (`repeat`, `speed`)."""
    fields = [f"points={format_points(points)}"]
    fields += [f"{key}={format_number(value, 6) if isinstance(value, float) else value}" for key, value in extra.items()]
    return "#".join(fields)


def parse_points_update(text: str) -> tuple[list[tuple[float, float]], dict[str, str]]:
    """`points=x,y:...#repeat=forever` -> (points, {'repeat': 'forever'}), as the helm reads the update."""
    pairs = parse_pairs(text, sep="#")
    if "points" not in pairs:
        raise FormatError(f"no points= in update {text!r}")
    return formats.parse_seglist(pairs.pop("points")), pairs


_UNSAFE = re.compile(r"[\s,={}#]+")


def format_forecast(boundary: Boundary, cycle: int) -> str:
    """OILSPILL_FORECAST: one accepted horizon with what a viewer needs to draw it and its band.

    `pts={..}` goes last and the source loses the characters that separate MOOS fields, so the
    string splits on commas outside the braces like any VIEW_* string.
    """
    fields = [f"cycle={cycle}", f"horizon={format_number(boundary.horizon_h, 3)}"]
    if boundary.time is not None:
        fields.append(f"valid={format_number(boundary.time, 3)}")
    fields += [f"uncertainty={format_number(boundary.uncertainty_m, 3)}",
               f"source={_UNSAFE.sub('_', boundary.source) or 'unknown'}",
               f"pts={{{format_points(boundary.polygon)}}}"]
    return ",".join(fields)


def parse_forecast(text: str) -> tuple[Boundary, int]:
    """OILSPILL_FORECAST -> (the horizon's Boundary, its cycle); BoundaryError saying what is wrong."""
    if "pts={" not in "".join(text.split()).lower():
        raise BoundaryError("needs cycle=, horizon= and pts={..}")
    try:
        fields = parse_pairs("".join(text.split()))
    except FormatError as err:
        raise BoundaryError(str(err)) from None
    if "cycle" not in fields or "horizon" not in fields:
        raise BoundaryError("needs cycle=, horizon= and pts={..}")
    try:
        cycle = parse_float(fields["cycle"], "cycle", lo=0)
        horizon = parse_float(fields["horizon"], "horizon")
        uncertainty = parse_float(fields.get("uncertainty", "0"), "uncertainty", lo=0)
        valid = parse_float(fields["valid"], "valid") if "valid" in fields else None
    except ValueError as err:
        raise BoundaryError(str(err)) from None
    vertices = parse_polygon_spec(text)
    if len(vertices) < 3 or not cycle.is_integer():
        raise BoundaryError("needs a whole cycle number and 3 points at least")
    return Boundary(tuple(map(tuple, vertices)), time=valid, horizon_h=horizon, uncertainty_m=uncertainty,
                    source=fields.get("source", "")), int(cycle)


def polygon_string(polygon: Polygon | Iterable[Iterable[float]], label: str, **extra: str) -> str:
    """A MOOS `pts={x,y:...},label=..[,key=value]` polygon (OILSPILL_BOUNDARY, VIEW_POLYGON), decimetres."""
    points = polygon.exterior.coords[:-1] if isinstance(polygon, Polygon) else polygon
    return formats.format_pairs([("pts", "{" + format_points(points) + "}"), ("label", label), *extra.items()])


def parse_polygon_string(text: str) -> tuple[list[tuple[float, float]], dict[str, str]]:
    """`pts={...},label=..` -> (vertices, the other fields); BoundaryError saying what is wrong."""
    vertices = parse_polygon_spec(text)
    try:
        fields = parse_pairs("".join(text.split()))
    except FormatError as err:
        raise BoundaryError(str(err)) from None
    fields.pop("pts", None)
    return vertices, fields


# ---- reports: VEHICLE_COORDINATES (pCoordinates), NODE_REPORT (pNodeReporter) ------------------------


def coordinates_report(vname: str, x: float, y: float, utc: float) -> str:
    """The VEHICLE_COORDINATES value pPathAssign reads."""
    return f"vname={vname},x={x:.2f},y={y:.2f},utc={utc:.2f}"


def parse_report(text: str) -> dict[str, str]:
    """`KEY=val,KEY=val` (NODE_REPORT, VEHICLE_COORDINATES) -> dict with lower-case keys."""
    return parse_pairs(text)


# ---- oil sensing: OIL_SENSOR_REQUEST, OIL_SENSOR_REPORT_<V>, OIL_OBSERVATION -------------------------


def format_request(vname: str, ident: int, x: float, y: float) -> str:
    """OIL_SENSOR_REQUEST: what lies at (x, y) for vehicle `vname`'s request `ident`."""
    return f"vname={vname},id={ident},x={x:.2f},y={y:.2f}"


def _numbers(fields: dict[str, str], keys: Iterable[str], what: str) -> list[float]:
    """The named fields as finite MOOS numbers; ValueError saying which rule was broken."""
    try:
        return [formats.parse_number(fields[key]) for key in keys]
    except FormatError as err:
        if "finite" in str(err):
            raise ValueError(f"{what}: non-finite number") from None
        raise ValueError(f"{what}: {', '.join(keys)} must be numbers") from None


def parse_request(text: str) -> tuple[str, int, float, float]:
    """`vname=abe,id=3,x=..,y=..` -> (vname, id, x, y); ValueError naming what is wrong."""
    fields = parse_pairs(text)
    missing = [k for k in ("vname", "id", "x", "y") if k not in fields]
    if missing:
        raise ValueError(f"request {text!r} lacks {missing[0]}")
    ident, x, y = _numbers(fields, ("id", "x", "y"), f"request {text!r}")
    vname = fields["vname"].lower()
    if not vname:
        raise ValueError(f"request {text!r}: empty vname or non-finite position")
    if not ident.is_integer():
        raise ValueError(f"request {text!r}: id, x, y must be numbers")
    return vname, int(ident), x, y


class ObservationRejected(ValueError):
    """An observation the fusion will not use; str() is the reason posted in OIL_FUSION_WARNING."""


@dataclass(frozen=True)
class Observation:
    vname: str
    id: int
    utc: float
    x: float
    y: float
    oil: bool
    range_m: float = 0.0
    thickness: str = ""


def parse_observation(text: str) -> Observation:
    """`vname=abe,id=3,utc=..,x=..,y=..,oil=1,range=..` -> Observation, or ObservationRejected saying why."""
    try:
        fields = parse_pairs(text)
    except ValueError as exc:
        raise ObservationRejected(f"malformed observation {text!r}: {exc}") from None
    missing = [k for k in ("vname", "id", "utc", "x", "y", "oil") if k not in fields]
    if missing:
        raise ObservationRejected(f"observation {text!r} lacks {', '.join(missing)}")
    what = f"observation {text!r}"
    try:
        ident, utc, x, y, range_m = _numbers({"range": "0", **fields}, ("id", "utc", "x", "y", "range"), what)
        oil = formats.parse_bool(fields["oil"])
        if not ident.is_integer():
            raise ValueError(f"{what}: id must be a whole number")
    except ValueError as exc:
        message = str(exc) if "non-finite" in str(exc) else f"{what}: id, utc, x, y, range must be numbers, oil 0 or 1"
        raise ObservationRejected(message) from None
    if range_m < 0:
        raise ObservationRejected(f"{what}: non-finite number or negative range")
    return Observation(vname=fields["vname"].lower(), id=int(ident), utc=utc, x=x, y=y, oil=oil, range_m=range_m,
                       thickness=fields.get("thickness", ""))


def format_observation(obs: Observation) -> str:
    text = (f"vname={obs.vname},id={obs.id},utc={obs.utc:.2f},x={format_number(obs.x, 2)},y={format_number(obs.y, 2)},"
            f"oil={int(obs.oil)},range={format_number(obs.range_m, 2)}")
    return text + (f",thickness={obs.thickness}" if obs.thickness else "")
