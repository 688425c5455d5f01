"""GeoJSON and shapefile readers: CRS handling, repair, clear errors, and the real DWH composites."""
import json
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pyproj
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
import shapefile
import shapely
from shapely.geometry import Point, box, mapping

from oilspill_moos.forecaster.readers import PolygonFileError, read_polygons, time_from_name

from helpers import DWH, requires_shared

GEOD = pyproj.Geod(ellps="WGS84")
UTM16 = pyproj.CRS("EPSG:32616")


def geodesic_km2(geometry):
    return abs(GEOD.geometry_area_perimeter(geometry)[0]) / 1e6


def write_geojson(path, geometries, crs=None, properties=None):
    doc = {"type": "FeatureCollection",
           "features": [{"type": "Feature", "geometry": None if g is None else mapping(g),
                         "properties": (properties or {})} for g in geometries]}
    if crs:
        doc["crs"] = {"type": "name", "properties": {"name": crs}}
    path.write_text(json.dumps(doc))
    return path


@requires_shared("data/dwh")
def test_dwh_may_17_polygons_area_and_time():
    obs = read_polygons(DWH / "dwh-2010-05-17.geojson")
    assert len(obs.polygons) == 11 and obs.source_crs == "EPSG:4326"
    assert obs.time == datetime(2010, 5, 17, tzinfo=timezone.utc)
    assert geodesic_km2(obs.geometry) == pytest.approx(26_800.2, rel=1e-4)
    assert not obs.repaired and not obs.skipped


@requires_shared("data/dwh")
def test_dwh_may_19_lacks_area_property_and_still_reads():
    obs = read_polygons(DWH / "dwh-2010-05-19.geojson")
    assert len(obs.polygons) == 46
    assert all("area" not in p for p in obs.properties)


@requires_shared("data/dwh")
def test_dwh_may_20_repairs_the_self_intersecting_ring_or_refuses_it():
    obs = read_polygons(DWH / "dwh-2010-05-20.geojson")
    # each part is valid; parts may overlap a little (objectid 236 with 220 and 199), as in the source
    assert len(obs.polygons) == 260 and all(p.is_valid for p in obs.polygons)
    assert len(obs.repaired) == 1 and obs.repaired[0].startswith("feature #222:")
    with pytest.raises(PolygonFileError, match=r"dwh-2010-05-20.geojson: feature #222: invalid geometry \(Ring Self-intersection"):
        read_polygons(DWH / "dwh-2010-05-20.geojson", repair=False)


def test_empty_collection_and_only_points_are_errors(tmp_path):
    with pytest.raises(PolygonFileError, match="empty.geojson: no polygons"):
        read_polygons(write_geojson(tmp_path / "empty.geojson", []))
    with pytest.raises(PolygonFileError, match="points.geojson: no polygons"):
        read_polygons(write_geojson(tmp_path / "points.geojson", [Point(-88, 28), None]))


def test_skips_null_and_point_features_but_keeps_polygons(tmp_path):
    obs = read_polygons(write_geojson(tmp_path / "mixed.geojson", [None, Point(-88, 28), box(-88.5, 28.5, -88.4, 28.6)]))
    assert len(obs.polygons) == 1 and len(obs.skipped) == 2


@pytest.mark.parametrize("bad", ["NaN", "Infinity"])
def test_non_finite_coordinates_are_refused(tmp_path, bad):
    path = tmp_path / "nan.geojson"
    path.write_text('{"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [%s, 1], [0, 0]]]}' % bad)
    with pytest.raises(PolygonFileError, match="feature #1: non-finite coordinate"):
        read_polygons(path)


def test_projected_coordinates_without_crs_are_refused(tmp_path):
    path = write_geojson(tmp_path / "utm.geojson", [box(300_000, 3_100_000, 310_000, 3_110_000)])
    with pytest.raises(PolygonFileError, match="not lon/lat degrees and no CRS is declared"):
        read_polygons(path)


def test_declared_projected_crs_is_reprojected(tmp_path):
    square = box(300_000, 3_170_000, 310_000, 3_180_000)
    obs = read_polygons(write_geojson(tmp_path / "utm.geojson", [square], crs="EPSG:32616"))
    minx, miny, maxx, maxy = obs.geometry.bounds
    assert -90 < minx < maxx < -88 and 28 < miny < maxy < 29
    assert geodesic_km2(obs.geometry) == pytest.approx(100.0, rel=2e-3)  # UTM scale factor ~0.9996


def test_bad_crs_malformed_json_unknown_format_missing_file(tmp_path):
    with pytest.raises(PolygonFileError, match="unreadable CRS"):
        read_polygons(write_geojson(tmp_path / "x.geojson", [box(0, 0, 1, 1)], crs="EPSG:nonsense"))
    bad = tmp_path / "bad.geojson"
    bad.write_text('{"type": "FeatureCollection",\n "features": [')
    with pytest.raises(PolygonFileError, match="bad.geojson: line 2: not JSON"):
        read_polygons(bad)
    (tmp_path / "slick.kml").write_text("<kml/>")
    with pytest.raises(PolygonFileError, match="unknown polygon format"):
        read_polygons(tmp_path / "slick.kml")
    with pytest.raises(PolygonFileError, match="no such file"):
        read_polygons(tmp_path / "absent.shp")


def write_shapefile(path, polygons, prj_crs=None):
    with shapefile.Writer(str(path), shapeType=shapefile.POLYGON) as writer:
        writer.field("name", "C")
        for k, poly in enumerate(polygons):
            writer.shape(mapping(poly))
            writer.record(f"slick{k}")
    if prj_crs is not None:
        Path(path).with_suffix(".prj").write_text(prj_crs.to_wkt(pyproj.enums.WktVersion.WKT1_ESRI))
    return Path(path).with_suffix(".shp")


def test_shapefile_with_prj_is_read_and_reprojected(tmp_path):
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", UTM16, always_xy=True)
    lonlat = [box(-88.5, 28.6, -88.3, 28.8), Point(-88.0, 28.9).buffer(0.05)]
    utm = [shapely.transform(p, lambda xy: np.column_stack(to_utm.transform(xy[:, 0], xy[:, 1]))) for p in lonlat]
    obs = read_polygons(write_shapefile(tmp_path / "slick_20100424T1643", utm, UTM16))
    assert len(obs.polygons) == 2 and obs.properties[1]["name"] == "slick1"
    assert geodesic_km2(obs.geometry) == pytest.approx(sum(geodesic_km2(p) for p in lonlat), rel=1e-6)
    assert obs.time == datetime(2010, 4, 24, 16, 43, tzinfo=timezone.utc)


def test_shapefile_without_prj_needs_an_explicit_crs(tmp_path):
    path = write_shapefile(tmp_path / "noprj", [box(-88.5, 28.6, -88.3, 28.8)])
    with pytest.raises(PolygonFileError, match=r"noprj.shp: missing CRS: no noprj.prj"):
        read_polygons(path)
    assert len(read_polygons(path, crs="EPSG:4326").polygons) == 1


def test_time_from_properties_name_or_argument(tmp_path):
    stamped = write_geojson(tmp_path / "obs.geojson", [box(-88.5, 28.6, -88.3, 28.8)],
                            properties={"time": "2010-04-25T12:30:00Z"})
    assert read_polygons(stamped).time == datetime(2010, 4, 25, 12, 30, tzinfo=timezone.utc)
    given = datetime(2010, 4, 26, 6, 0)
    assert read_polygons(stamped, time=given).time == given.replace(tzinfo=timezone.utc)
    assert time_from_name("nesdis_2010-04-28_1200.shp") == datetime(2010, 4, 28, 12, 0, tzinfo=timezone.utc)
    assert time_from_name("slick.geojson") is None
    bad = write_geojson(tmp_path / "badtime.geojson", [box(-88.5, 28.6, -88.3, 28.8)], properties={"time": "noon"})
    with pytest.raises(PolygonFileError, match="'time' = 'noon' is not an ISO time"):
        read_polygons(bad)


json_values = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=False, width=32) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
        st.sampled_from(["type", "features", "geometry", "coordinates", "crs", "properties", "name"]), inner, max_size=4),
    max_leaves=20)
numbers = st.floats(min_value=-200, max_value=200, allow_nan=False) | st.just(float("inf"))
rings = st.lists(st.lists(numbers, min_size=1, max_size=3), min_size=0, max_size=6)
polygon = st.fixed_dictionaries({"type": st.just("Polygon"), "coordinates": st.lists(rings, max_size=2)})
feature = st.fixed_dictionaries({"type": st.just("Feature"), "geometry": polygon | json_values,
                                 "properties": json_values})
geojson_like = st.fixed_dictionaries({
    "type": st.sampled_from(["FeatureCollection", "Feature", "Polygon", "MultiPolygon", "Point", "Bogus"]),
    "features": st.lists(feature, max_size=3) | json_values, "geometry": polygon | json_values,
    "coordinates": st.lists(rings, max_size=2) | json_values, "crs": json_values | st.just(None)})


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(doc=geojson_like | json_values)
@example(doc={"type": "MultiPolygon", "coordinates": [[], [[0.0]]]})  # once crashed shapely with IndexError
def test_any_json_gives_polygons_or_a_polygon_file_error(tmp_path, doc):
    path = tmp_path / "fuzz.geojson"
    path.write_text(json.dumps(doc))
    try:
        obs = read_polygons(path)
    except PolygonFileError as exc:
        assert str(exc).startswith(str(path))
    else:
        assert obs.polygons and all(p.is_valid for p in obs.polygons)
