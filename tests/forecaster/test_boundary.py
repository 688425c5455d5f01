"""Boundary rebuild: the affine map lands exactly on the predicted centroid, area, aspect and axis."""
import math
from datetime import datetime, timezone

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
import shapely
from shapely import affinity
from shapely.geometry import MultiPolygon, Point

from oilspill_moos.forecaster.boundary import outline, rebuild_boundary, target_values
from oilspill_moos.forecaster.features import (FEATURE_INDEX as F, Environment, TARGET_NAMES,
                                               observation_features, to_lonlat, to_plane)

T0 = datetime(2010, 4, 24, 16, 43, tzinfo=timezone.utc)
ENV = Environment(4.0, 1.0, 0.1, 0.0, 28.0)


def features_of(geometry, multipolygon="largest"):
    return observation_features(geometry, T0, ENV, release_time=T0, multipolygon=multipolygon)


def ellipse(cx, cy, a, b, angle_deg):
    disc = Point(0, 0).buffer(1.0, quad_segs=64)
    shape = affinity.rotate(affinity.scale(disc, a, b, origin=(0, 0)), angle_deg, origin=(0, 0))
    return to_lonlat(affinity.translate(shape, cx, cy))


def axis_deg(f):
    return math.degrees(0.5 * math.atan2(f[F["orientation_sin2"]], f[F["orientation_cos2"]]))


def test_unchanged_targets_give_back_the_same_polygon():
    last = ellipse(5_000, -3_000, 6_000, 2_000, 20)
    again = rebuild_boundary(last, target_values(features_of(last)))
    assert shapely.hausdorff_distance(to_plane(again), to_plane(last)) < 1.0  # metres


def test_move_grow_stretch_and_turn_hit_the_prediction():
    last = ellipse(0, 0, 6_000, 2_000, 0)
    want = {"centroid_x_km": 12.0, "centroid_y_km": -4.0, "log_area_km2": math.log(2 * math.pi * 12),
            "aspect_ratio": 2.0, "orientation_cos2": 0.0, "orientation_sin2": 1.0}  # axis at 45°
    got = features_of(rebuild_boundary(last, want))
    for name in ("centroid_x_km", "centroid_y_km", "log_area_km2", "aspect_ratio"):
        assert got[F[name]] == pytest.approx(want[name], rel=1e-4, abs=1e-3), name
    assert axis_deg(got) == pytest.approx(45.0, abs=0.05)


def test_array_in_target_order_and_multipart_polygons_keep_their_parts():
    lobes = to_lonlat(MultiPolygon([Point(0, 0).buffer(3_000), Point(9_000, 2_000).buffer(1_500)]))
    f = features_of(lobes)
    values = [f[F[n]] for n in TARGET_NAMES]
    values[0] += 5.0  # 5 km east
    moved = rebuild_boundary(lobes, values)
    g = features_of(moved)
    assert g[F["n_components"]] == 2
    assert g[F["centroid_x_km"]] == pytest.approx(f[F["centroid_x_km"]] + 5.0, abs=1e-3)
    assert g[F["largest_fraction"]] == pytest.approx(f[F["largest_fraction"]], rel=1e-6)


def test_union_mode_scales_the_total_area():
    lobes = to_lonlat(MultiPolygon([Point(0, 0).buffer(3_000), Point(9_000, 2_000).buffer(1_500)]))
    want = target_values(features_of(lobes, "union"))
    want["log_area_km2"] += math.log(1.5)
    got = features_of(rebuild_boundary(lobes, want, multipolygon="union"), "union")
    assert got[F["log_area_km2"]] == pytest.approx(want["log_area_km2"], abs=1e-6)


def test_bad_predictions_are_refused():
    last = ellipse(0, 0, 3_000, 1_000, 10)
    good = target_values(features_of(last))
    with pytest.raises(ValueError, match="not finite"):
        rebuild_boundary(last, {**good, "log_area_km2": math.nan})
    with pytest.raises(ValueError, match="lack aspect_ratio"):
        rebuild_boundary(last, {k: v for k, v in good.items() if k != "aspect_ratio"})


def test_outline_is_the_open_exterior_ring_of_the_largest_part():
    lobes = to_lonlat(MultiPolygon([Point(0, 0).buffer(1_000, quad_segs=8), Point(9_000, 0).buffer(3_000, quad_segs=8)]))
    ring = outline(lobes)
    assert len(ring) == 32 and ring[0] != ring[-1]
    assert shapely.geometry.Polygon(ring).contains(to_lonlat(Point(9_000, 0)))


@settings(max_examples=25, deadline=None)
@given(a=st.floats(500, 20_000), ratio=st.floats(1.0, 8.0), angle=st.floats(0, 180),
       dx=st.floats(-50, 50), dy=st.floats(-50, 50), growth=st.floats(-1.0, 1.5),
       new_ratio=st.floats(1.0, 8.0), new_angle=st.floats(0, 180))
def test_rebuilt_ellipse_matches_any_prediction(a, ratio, angle, dx, dy, growth, new_ratio, new_angle):
    last = ellipse(3_000, -2_000, a, a / ratio, angle)
    f = features_of(last)
    want = {"centroid_x_km": f[F["centroid_x_km"]] + dx, "centroid_y_km": f[F["centroid_y_km"]] + dy,
            "log_area_km2": f[F["log_area_km2"]] + growth, "aspect_ratio": new_ratio,
            "orientation_cos2": math.cos(math.radians(2 * new_angle)),
            "orientation_sin2": math.sin(math.radians(2 * new_angle))}
    got = features_of(rebuild_boundary(last, want))
    for name in ("centroid_x_km", "centroid_y_km", "log_area_km2"):
        assert got[F[name]] == pytest.approx(want[name], abs=1e-3), name
    assert got[F["aspect_ratio"]] == pytest.approx(new_ratio, rel=2e-3)
    if new_ratio > 1.05:  # a near-disc has no meaningful axis
        assert (axis_deg(got) - new_angle + 90) % 180 - 90 == pytest.approx(0.0, abs=0.5)
