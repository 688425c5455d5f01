"""Spill-polygon files (GeoJSON, ESRI shapefile) -> one valid EPSG:4326 MultiPolygon per observation.

Rules, so a bad file never turns into a silent wrong forecast:
- GeoJSON with a ``crs`` member uses it; without one it is EPSG:4326 as RFC 7946 defines, but only if
  every coordinate is a plausible lon/lat (otherwise the CRS is evidently missing: error).
- A shapefile needs its ``.prj`` (or an explicit ``crs=``): without it the CRS is unknown, so error.
- Other CRSs are reprojected to EPSG:4326 with pyproj.
- No polygon at all: error. Null or non-polygon features are skipped and listed in ``skipped``.
- An invalid polygon is repaired with ``shapely.make_valid`` (polygonal parts kept) and listed in
  ``repaired``; with ``repair=False`` it is an error naming the feature and the reason.
Every error is a ``PolygonFileError`` whose text starts with the file (and feature) it is about.
"""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pyproj
import shapefile  # pyshp
import shapely
from shapely.geometry import MultiPolygon, Polygon, shape
from shapely.validation import explain_validity

WGS84 = pyproj.CRS("EPSG:4326")
_DATE_IN_NAME = re.compile(r"(\d{4})-?(\d{2})-?(\d{2})(?:[T_ -]?(\d{2}):?(\d{2})(?::?(\d{2}))?Z?)?")
_TIME_PROPERTIES = ("time", "datetime", "date", "timestamp", "acquired")


class PolygonFileError(ValueError):
    """A polygon file that cannot give a trustworthy observation."""

    def __init__(self, path, message: str, feature: int | None = None):
        self.path, self.feature = Path(path), feature
        where = f"{path}" if feature is None else f"{path}: feature #{feature + 1}"
        super().__init__(f"{where}: {message}")


@dataclass
class PolygonFile:
    """The polygons of one file, in EPSG:4326, with what was done to get them."""

    path: Path
    geometry: MultiPolygon
    properties: list[dict]
    source_crs: str
    time: datetime | None = None
    repaired: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)

    @property
    def polygons(self) -> list[Polygon]:
        return list(self.geometry.geoms)


def _polygonal(geometry) -> list[Polygon]:
    return [p for p in shapely.get_parts(geometry) if isinstance(p, Polygon) and not p.is_empty] + [
        q for m in shapely.get_parts(geometry) if isinstance(m, MultiPolygon) for q in m.geoms if not q.is_empty]


def _clean(path, index: int, geometry, repair: bool, repaired: list[str]) -> list[Polygon]:
    """Polygons of one feature, valid, or a clear error."""
    if not np.isfinite(shapely.get_coordinates(geometry)).all():
        raise PolygonFileError(path, "non-finite coordinate (NaN or infinity)", index)
    if geometry.is_valid:
        return _polygonal(geometry)
    reason = explain_validity(geometry)
    if not repair:
        raise PolygonFileError(path, f"invalid geometry ({reason})", index)
    fixed = _polygonal(shapely.make_valid(geometry))
    repaired.append(f"feature #{index + 1}: {reason}; repaired with make_valid")
    return fixed


def _reproject(polygons: list[Polygon], crs: pyproj.CRS) -> list[Polygon]:
    if crs.equals(WGS84, ignore_axis_order=True):
        return polygons
    transformer = pyproj.Transformer.from_crs(crs, WGS84, always_xy=True)
    return [shapely.transform(p, lambda xy: np.column_stack(transformer.transform(xy[:, 0], xy[:, 1])))
            for p in polygons]


def _parse_crs(path, text: str) -> pyproj.CRS:
    try:
        return pyproj.CRS.from_user_input(text)
    except pyproj.exceptions.CRSError as exc:
        raise PolygonFileError(path, f"unreadable CRS {text[:60]!r}: {exc}") from None


def _check_lonlat(path, polygons: list[Polygon]) -> None:
    minx, miny, maxx, maxy = shapely.total_bounds(polygons)
    if minx < -180 or maxx > 180 or miny < -90 or maxy > 90:
        raise PolygonFileError(path, f"coordinates ({minx:.6g}..{maxx:.6g}, {miny:.6g}..{maxy:.6g}) are not "
                                     "lon/lat degrees and no CRS is declared")


def _properties(path, feature: dict, index: int) -> dict:
    props = feature.get("properties")
    if props is None:
        return {}
    if not isinstance(props, dict):
        raise PolygonFileError(path, f"'properties' is a {type(props).__name__}, not an object", index)
    return props


def _declared_crs(path, doc) -> str | None:
    """The name in a GeoJSON 2008 ``crs`` member, or None when there is no such member."""
    crs = doc.get("crs") if isinstance(doc, dict) else None
    if crs is None:
        return None
    name = crs.get("properties", {}).get("name") if isinstance(crs, dict) and isinstance(crs.get("properties"), dict) else None
    if not isinstance(name, str):
        raise PolygonFileError(path, "'crs' member without a properties.name string")
    return name


def _geojson_features(path, doc) -> list[tuple[dict | None, dict]]:
    kind = doc.get("type") if isinstance(doc, dict) else None
    if kind == "FeatureCollection":
        features = doc.get("features")
        if not isinstance(features, list):
            raise PolygonFileError(path, "FeatureCollection without a 'features' list")
        return [(f.get("geometry"), _properties(path, f, i)) if isinstance(f, dict) else (None, {})
                for i, f in enumerate(features)]
    if kind == "Feature":
        return [(doc.get("geometry"), _properties(path, doc, 0))]
    if kind in ("Polygon", "MultiPolygon", "GeometryCollection"):
        return [(doc, {})]
    raise PolygonFileError(path, f"not a GeoJSON FeatureCollection, Feature or polygon (type {kind!r})")


def read_geojson(path, *, crs=None, repair: bool = True) -> PolygonFile:
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise PolygonFileError(path, f"cannot read: {exc}") from None
    except json.JSONDecodeError as exc:
        raise PolygonFileError(path, f"line {exc.lineno}: not JSON ({exc.msg})") from None
    declared = crs if crs is not None else _declared_crs(path, doc)
    polygons, properties, repaired, skipped = [], [], [], []
    for index, (geom, props) in enumerate(_geojson_features(path, doc)):
        if geom is None:
            skipped.append(f"feature #{index + 1}: no geometry")
            continue
        try:
            with np.errstate(invalid="ignore"):  # NaN coordinates are reported by _clean, by feature
                geometry = shape(geom)
        except (ValueError, TypeError, KeyError, IndexError, AttributeError, shapely.errors.ShapelyError) as exc:
            raise PolygonFileError(path, f"malformed geometry ({exc})", index) from None
        parts = _clean(path, index, geometry, repair, repaired)
        if not parts:
            skipped.append(f"feature #{index + 1}: {geometry.geom_type}, not a polygon")
            continue
        polygons += parts
        properties.append(props)
    if not polygons:
        raise PolygonFileError(path, "no polygons")
    if declared is None:
        _check_lonlat(path, polygons)
        source = "EPSG:4326 (RFC 7946 default; no crs member)"
        target = WGS84
    else:
        target = _parse_crs(path, str(declared))
        source = str(declared)
    return PolygonFile(path=path, geometry=MultiPolygon(_reproject(polygons, target)), properties=properties,
                       source_crs=source, repaired=repaired, skipped=skipped)


def read_shapefile(path, *, crs=None, repair: bool = True) -> PolygonFile:
    path = Path(path)
    prj = path.with_suffix(".prj")
    if crs is None and not prj.exists():
        raise PolygonFileError(path, f"missing CRS: no {prj.name} beside it (pass crs= to state it)")
    target = _parse_crs(path, str(crs) if crs is not None else prj.read_text(errors="replace"))
    try:
        reader = shapefile.Reader(str(path))
    except (shapefile.ShapefileException, OSError) as exc:
        raise PolygonFileError(path, f"cannot read shapefile: {exc}") from None
    polygons, properties, repaired, skipped = [], [], [], []
    with reader:
        for index, record in enumerate(reader.iterShapeRecords()):
            if record.shape.shapeType == shapefile.NULL:
                skipped.append(f"feature #{index + 1}: null shape")
                continue
            geometry = shape(record.shape.__geo_interface__)
            parts = _clean(path, index, geometry, repair, repaired)
            if not parts:
                skipped.append(f"feature #{index + 1}: {geometry.geom_type}, not a polygon")
                continue
            polygons += parts
            properties.append(record.record.as_dict())
    if not polygons:
        raise PolygonFileError(path, "no polygons")
    return PolygonFile(path=path, geometry=MultiPolygon(_reproject(polygons, target)), properties=properties,
                       source_crs=target.to_string(), repaired=repaired, skipped=skipped)


def time_from_name(path) -> datetime | None:
    """UTC time written in a file name (``dwh-2010-05-17``, ``slick_20100424T1643``), if any."""
    match = _DATE_IN_NAME.search(Path(path).stem)
    if not match:
        return None
    parts = [int(p) if p else 0 for p in match.groups()]
    try:
        return datetime(*parts, tzinfo=timezone.utc)
    except ValueError:
        return None


def _time_from_properties(path, properties: list[dict]) -> datetime | None:
    for key in _TIME_PROPERTIES:
        values = {str(p[key]) for p in properties if p.get(key) not in (None, "")}
        if len(values) > 1:
            raise PolygonFileError(path, f"features disagree on '{key}' ({len(values)} different values)")
        if values:
            text = values.pop()
            try:
                moment = datetime.fromisoformat(text.replace("Z", "+00:00"))
            except ValueError:
                raise PolygonFileError(path, f"'{key}' = {text!r} is not an ISO time") from None
            return moment.replace(tzinfo=timezone.utc) if moment.tzinfo is None else moment.astimezone(timezone.utc)
    return None


def read_polygons(path, *, crs=None, repair: bool = True, time: datetime | None = None) -> PolygonFile:
    """One observation from a ``.geojson``/``.json`` or ``.shp`` file, with its time when known.

    The time is ``time`` if given, else a shared ``time``/``datetime``/``date`` property, else a date
    in the file name; ``None`` if none of these says.
    """
    path = Path(path)
    if not path.exists():
        raise PolygonFileError(path, "no such file")
    suffix = path.suffix.lower()
    if suffix in (".geojson", ".json"):
        result = read_geojson(path, crs=crs, repair=repair)
    elif suffix == ".shp":
        result = read_shapefile(path, crs=crs, repair=repair)
    else:
        raise PolygonFileError(path, f"unknown polygon format {suffix!r} (expected .geojson, .json or .shp)")
    if time is not None:
        result.time = time.replace(tzinfo=timezone.utc) if time.tzinfo is None else time
    else:
        result.time = _time_from_properties(path, result.properties) or time_from_name(path)
    return result


# ---------------------------------------------------------------------------------------------------
# Forcing files

FORCING_FIELDS = ("wind_u", "wind_v", "current_u", "current_v")


def _forcing_time(path, where: str, text) -> datetime:
    try:
        time = datetime.fromisoformat(str(text).strip().replace("Z", "+00:00"))
    except ValueError:
        raise PolygonFileError(path, f"{where}: time {text!r} is not ISO 8601 (e.g. 2010-05-20T06:00Z)") from None
    return time.replace(tzinfo=timezone.utc) if time.tzinfo is None else time.astimezone(timezone.utc)


def _forcing_row(path, where: str, record: dict):
    from .features import Environment

    missing = [k for k in ("time", *FORCING_FIELDS) if k not in record or record[k] in (None, "")]
    if missing:
        raise PolygonFileError(path, f"{where}: missing {', '.join(missing)}")
    try:
        values = [float(record[k]) for k in FORCING_FIELDS]
        sea_temp = float(record.get("sea_temp_c") or 0.0)
    except (TypeError, ValueError):
        raise PolygonFileError(path, f"{where}: wind and current must be numbers (m/s)") from None
    if not all(np.isfinite(values)) or not np.isfinite(sea_temp):
        raise PolygonFileError(path, f"{where}: non-finite wind or current")
    return _forcing_time(path, where, record["time"]), Environment(*values, sea_temp)


def read_forcing(path) -> list[tuple[datetime, "Environment"]]:
    """Forcing rows (time, Environment) in time order from a CSV (header ``time,wind_u,wind_v,current_u,
    current_v[,sea_temp_c]``) or JSON file (a list of objects with those keys, or ``{"forcing": [...]}``).
    Times are ISO 8601; naive times are UTC. Every error names the file and line or entry."""
    import csv

    path = Path(path)
    if not path.is_file():
        raise PolygonFileError(path, "no such forcing file")
    text = path.read_text()
    rows = []
    if path.suffix.lower() == ".json":
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise PolygonFileError(path, f"line {exc.lineno}: not JSON ({exc.msg})") from None
        records = doc.get("forcing") if isinstance(doc, dict) else doc
        if not isinstance(records, list) or not all(isinstance(r, dict) for r in records):
            raise PolygonFileError(path, 'expected a list of {"time":..., "wind_u":..., ...} objects')
        rows = [_forcing_row(path, f"entry #{i + 1}", r) for i, r in enumerate(records)]
    else:
        reader = csv.DictReader(text.splitlines())
        if reader.fieldnames is None or "time" not in reader.fieldnames:
            raise PolygonFileError(path, f"line 1: header must name time,{','.join(FORCING_FIELDS)}")
        rows = [_forcing_row(path, f"line {n}", r) for n, r in enumerate(reader, start=2)]
    if not rows:
        raise PolygonFileError(path, "no forcing rows")
    return sorted(rows, key=lambda r: r[0])
