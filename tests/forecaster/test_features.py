"""Feature extraction on known shapes, scaling, windows, padding, and the real DWH composites."""
import math
from datetime import datetime, timedelta, timezone

import numpy as np
import pyproj
import pytest
from shapely import affinity
from shapely.geometry import MultiPolygon, Point, box

from oilspill_moos.forecaster.features import (
    FEATURE_INDEX, FEATURE_NAMES, TARGET_NAMES, Environment, FeatureScaler, feature_matrix, interpolate,
    latest_window, make_windows, observation_features, pad_by_trend, to_lonlat)
from oilspill_moos.forecaster.readers import read_polygons

from helpers import DWH, requires_shared

RELEASE = datetime(2010, 4, 21, 3, 0, tzinfo=timezone.utc)
CALM = Environment(wind_u=3.0, wind_v=-1.0, current_u=0.1, current_v=0.05, sea_temp_c=27.5)
F = FEATURE_INDEX


def feats(plane_geometry, time=RELEASE + timedelta(hours=6), env=CALM, multipolygon="largest"):
    return observation_features(to_lonlat(plane_geometry), time, env, release_time=RELEASE,
                                multipolygon=multipolygon)


def test_there_are_25_distinct_named_features():
    assert len(FEATURE_NAMES) == 25 == len(set(FEATURE_NAMES))
    assert set(TARGET_NAMES) <= set(FEATURE_NAMES)


def test_circle_is_compact_round_and_at_its_centre():
    f = feats(Point(20_000, -5_000).buffer(4_000, quad_segs=128))
    assert f[F["compactness"]] == pytest.approx(1.0, abs=1e-3)
    assert f[F["convexity"]] == pytest.approx(1.0, abs=1e-9)
    assert f[F["aspect_ratio"]] == pytest.approx(1.0, abs=1e-3)
    assert f[F["area_km2"]] == pytest.approx(math.pi * 16, rel=1e-3)
    assert (f[F["centroid_x_km"]], f[F["centroid_y_km"]]) == pytest.approx((20.0, -5.0), abs=1e-3)
    assert f[F["distance_km"]] == pytest.approx(math.hypot(20, 5), abs=1e-3)


@pytest.mark.parametrize("angle", [0.0, 30.0, 75.0, 120.0])
def test_rectangle_aspect_ratio_and_orientation(angle):
    rect = affinity.rotate(box(-4_000, -1_000, 4_000, 1_000), angle, origin=(0, 0))
    f = feats(affinity.translate(rect, 5_000, 8_000))
    assert f[F["aspect_ratio"]] == pytest.approx(4.0, rel=1e-4)
    theta = math.degrees(0.5 * math.atan2(f[F["orientation_sin2"]], f[F["orientation_cos2"]]))
    assert (theta - angle + 90) % 180 - 90 == pytest.approx(0.0, abs=0.05)
    assert f[F["compactness"]] == pytest.approx(4 * math.pi * 16 / 20 ** 2, rel=1e-4)
    assert f[F["perimeter_km"]] == pytest.approx(20.0, rel=1e-4)


def test_area_is_equal_area_far_from_the_wellhead():
    """Geodesic area on the ellipsoid is the reference; the plane must agree away from its centre."""
    square = box(-86.0, 29.5, -85.5, 30.0)
    geod_area = abs(pyproj.Geod(ellps="WGS84").geometry_area_perimeter(square)[0]) / 1e6
    f = observation_features(square, RELEASE, CALM, release_time=RELEASE)
    assert f[F["area_km2"]] == pytest.approx(geod_area, rel=1e-4)


def test_multipolygon_largest_component_or_union():
    big, small = Point(0, 0).buffer(3_000), Point(20_000, 0).buffer(1_000)
    both = MultiPolygon([big, small])
    largest, union = feats(both), feats(both, multipolygon="union")
    assert largest[F["area_km2"]] == pytest.approx(big.area / 1e6, rel=1e-3)
    assert union[F["area_km2"]] == pytest.approx((big.area + small.area) / 1e6, rel=1e-3)
    assert largest[F["n_components"]] == union[F["n_components"]] == 2
    assert largest[F["largest_fraction"]] == pytest.approx(9 / 10, rel=1e-3)
    assert union[F["centroid_x_km"]] == pytest.approx(20 * 1 / 10, abs=0.02)  # area-weighted
    with pytest.raises(ValueError, match="multipolygon"):
        feats(both, multipolygon="smallest")


def test_time_and_environment_features():
    f = feats(Point(0, 0).buffer(1_000), time=datetime(2010, 4, 22, 6, 0, tzinfo=timezone.utc))
    assert f[F["hours_since_release"]] == pytest.approx(27.0)
    assert (f[F["hour_sin"]], f[F["hour_cos"]]) == pytest.approx((1.0, 0.0), abs=1e-12)
    assert list(f[F["wind_u"]:]) == [3.0, -1.0, 0.1, 0.05, 27.5]


def test_nan_environment_is_refused_by_name():
    with pytest.raises(ValueError, match="wind_v"):
        feats(Point(0, 0).buffer(1_000), env=Environment(1.0, math.nan, 0.0, 0.0, 28.0))


def test_scaler_zscore_clip_zero_variance_and_round_trip():
    rng = np.random.default_rng(1)
    x = rng.normal(5.0, 2.0, (500, 25))
    x[:, 3] = 7.0  # constant column
    scaler = FeatureScaler.fit(x)
    assert scaler.std[3] == 1.0
    z = scaler.transform(x)
    assert np.abs(z).max() <= 3.0 and np.allclose(z[:, 3], 0.0)
    assert abs(z[:, 0].mean()) < 0.05
    assert scaler.transform(np.full((1, 25), 1e6)).max() == 3.0
    cols = [0, 5]
    inside = x[:10][:, cols]
    assert np.allclose(scaler.inverse_transform(scaler.transform(inside, cols), cols), inside)
    again = FeatureScaler.from_dict(scaler.to_dict())
    assert np.array_equal(again.mean, scaler.mean) and np.array_equal(again.std, scaler.std)
    bad = np.zeros((3, 25))
    bad[2, 4] = np.nan
    with pytest.raises(ValueError, match="convexity is nan at row 2"):
        FeatureScaler.fit(bad)


def growing_drifting_sequence(hours):
    """A circle whose log-area and centroid grow linearly in time: trends are exact."""
    geoms = [to_lonlat(Point(600.0 * h, -200.0 * h).buffer(1_500 * math.exp(0.02 * h), quad_segs=32))
             for h in hours]
    times = [RELEASE + timedelta(hours=float(h)) for h in hours]
    return np.asarray(hours, float), feature_matrix(geoms, times, [CALM] * len(hours), release_time=RELEASE)


@pytest.fixture(scope="module")
def hourly():
    return growing_drifting_sequence(np.arange(2, 62))


def test_hourly_windows_shape_elapsed_and_targets(hourly):
    times, x = hourly
    w = make_windows([(times, x)], scale="hourly")
    assert w.inputs.shape[1:] == (16, 25) and w.targets.shape[1:] == (4, len(TARGET_NAMES))
    assert w.end_time_h.max() <= 48 and np.allclose(w.elapsed_h, 1.0)
    k = int(np.flatnonzero(w.n_padded == 0)[0])
    e = int(np.searchsorted(times, w.end_time_h[k]))
    assert np.allclose(w.inputs[k], x[e - 15:e + 1])
    cols = [F[n] for n in TARGET_NAMES]
    assert np.allclose(w.targets[k], x[[e + 3, e + 7, e + 11, e + 15]][:, cols])


def test_padding_extends_the_trend_exactly(hourly):
    times, x = hourly
    t, padded = pad_by_trend(times[:5], x[:5], 16)
    assert np.allclose(t, np.arange(-9, 7))
    truth = growing_drifting_sequence(np.arange(-9, 2))[1]
    for name in ("log_area_km2", "centroid_x_km", "centroid_y_km", "hours_since_release", "hour_sin", "doy_cos"):
        assert np.allclose(padded[:11, F[name]], truth[:, F[name]], atol=1e-6), name
    assert np.allclose(padded[:11, F["wind_u"]], CALM.wind_u)
    with pytest.raises(ValueError, match="need 2"):
        pad_by_trend(times[:1], x[:1], 16)


def test_irregular_steps_and_interpolated_targets(hourly):
    times, x = hourly
    keep = np.array([0, 1, 3, 4, 7, 9, 10, 13, 14, 15, 18, 20, 21, 22, 25, 26, 28, 30, 31, 40, 59])
    w = make_windows([(times[keep], x[keep])], scale=None, min_observed=16)
    assert len(w) > 0
    assert set(np.unique(w.elapsed_h[:, 1:])) - {1.0, 2.0, 3.0, 9.0, 19.0} == set()
    k = 0
    cols = [F[n] for n in TARGET_NAMES]
    expected = interpolate(times[keep], x[keep], w.end_time_h[k] + np.array([3, 7, 11, 15.0]))[:, cols]
    assert np.allclose(w.targets[k], expected)


def test_daily_scale_and_short_sequences(hourly):
    times, x = hourly
    daily = make_windows([(times, x)], scale="daily", min_observed=2)
    assert len(daily) >= 1 and np.allclose(daily.elapsed_h, 24.0)
    assert (daily.n_padded >= 14).all()
    none = make_windows([(times[:20], x[:20])], scale="hourly", pad=False)
    assert len(none) == 0
    with pytest.raises(ValueError, match="scale"):
        make_windows([(times, x)], scale="weekly")


def test_latest_window_pads_a_short_observation_history(hourly):
    times, x = hourly
    inputs, elapsed, n_padded = latest_window(times[:6], x[:6])
    assert inputs.shape == (16, 25) and n_padded == 10 and np.allclose(elapsed, 1.0)
    assert np.allclose(inputs[-6:], x[:6])
    with pytest.raises(ValueError, match="increase"):
        latest_window(times[[0, 2, 1]], x[:3])


@requires_shared("data/dwh")
def test_real_dwh_composites_feature_check():
    """Areas of the largest NOAA/NESDIS polygon and of all of them, as the data README measured."""
    rows = {}
    for day, largest_km2, total_km2, parts in (("17", 26_141.9, 26_800.7, 11), ("19", 20_612.1, 21_269.4, 46),
                                              ("20", 13_944.9, 23_081.5, 260)):
        obs = read_polygons(DWH / f"dwh-2010-05-{day}.geojson")
        env = Environment(0.0, 0.0, 0.0, 0.0, 28.0)
        f = observation_features(obs.geometry, obs.time, env, release_time=RELEASE)
        u = observation_features(obs.geometry, obs.time, env, release_time=RELEASE, multipolygon="union")
        assert f[F["area_km2"]] == pytest.approx(largest_km2, rel=2e-4)
        assert u[F["area_km2"]] == pytest.approx(total_km2, rel=2e-4)
        assert f[F["n_components"]] == parts
        rows[day] = f
    assert rows["20"][F["hours_since_release"]] - rows["19"][F["hours_since_release"]] == pytest.approx(24.0)
    assert 27.0 < rows["19"][F["centroid_lat"]] < 30.0 and -91.0 < rows["19"][F["centroid_lon"]] < -86.0
