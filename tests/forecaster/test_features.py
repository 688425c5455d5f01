"""Features of the learned correction: shapes on known geometries, nothing absolute, padding, scaling, and
the real DWH composites."""
import math

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import MultiPolygon, Point, box

from oilspill_moos.forecaster import features as F
from oilspill_moos.forecaster.engine import prepare
from oilspill_moos.forecaster.physics import DriftParameters
from oilspill_moos.forecaster.readers import read_polygons

from helpers import DWH, requires_shared

I = F.FEATURE_INDEX


def test_feature_names_are_distinct_and_none_says_where_or_when():
    assert len(set(F.FEATURE_NAMES)) == len(F.FEATURE_NAMES)
    for banned in ("lon", "lat", "distance", "since_release", "hour_", "doy", "centroid_x", "sea_temp"):
        assert not any(banned in name for name in F.FEATURE_NAMES), banned


def test_circle_and_rectangle_shapes():
    circle = F.Shape.of(Point(1_000, -2_000).buffer(3_000, quad_segs=64))
    assert circle.area == pytest.approx(math.pi * 9e6, rel=1e-3)
    assert np.allclose(circle.centroid, [1_000, -2_000], atol=1.0)
    assert F.shape_axes(circle.cov)[0] == pytest.approx(1.0, abs=1e-3)
    rect = F.Shape.of(affinity.rotate(box(0, 0, 8_000, 2_000), 30, origin=(0, 0)))
    aspect, theta = F.shape_axes(rect.cov)
    assert aspect == pytest.approx(4.0, rel=1e-6) and math.degrees(theta) == pytest.approx(30.0, abs=1e-6)
    two = F.Shape.of(MultiPolygon([Point(0, 0).buffer(3_000), Point(20_000, 0).buffer(1_000)]))
    assert two.n_parts == 2 and two.largest_fraction == pytest.approx(0.9, rel=1e-3)


def sequence(shift=(0.0, 0.0), hours=(0, 1, 3, 4, 6)):
    slick = Point(0, 0).buffer(2_000, quad_segs=32)
    geoms = [affinity.translate(affinity.scale(slick, 1 + 0.04 * h, 1 + 0.02 * h), 600.0 * h + shift[0], 200.0 * h + shift[1])
             for h in hours]
    shapes = [F.Shape.of(g) for g in geoms]
    times = 3600.0 * np.asarray(hours, float)
    envs = np.array([[5.0, 1.0, 0.1, 0.05]] * len(hours))
    return shapes, times, envs


def drift_of(envs):
    from oilspill_moos.forecaster.physics import drift_velocity
    return lambda i0, i1: drift_velocity(envs[i1])


def test_features_ignore_where_and_when_and_pad_at_the_front():
    shapes, times, envs = sequence()
    x, dt, angle = F.window_features(shapes, times, envs, drift_of(envs))
    far_shapes, _, _ = sequence(shift=(300_000.0, -150_000.0))
    later = times + 86_400.0 * 40
    y, dt2, angle2 = F.window_features(far_shapes, later, envs, drift_of(envs))
    assert np.allclose(x, y) and np.allclose(dt, dt2) and angle == angle2
    assert x.shape == (F.WINDOW, len(F.FEATURE_NAMES))
    assert np.all(x[:-5] == 0) and np.all(x[-5:, I["observed"]] == 1)
    assert np.allclose(dt[-4:], [1, 2, 1, 2])
    # observed velocity (600, 200) m/h in the frame of the drift velocity (0.25, 0.08) m/s
    speed = math.hypot(600, 200) / 3600
    assert math.hypot(*x[-1, [I["obs_u"], I["obs_v"]]]) == pytest.approx(speed, rel=1e-3)
    assert x[-1, I["drift_v"]] == pytest.approx(0.0, abs=1e-12) and x[-1, I["drift_u"]] > 0
    assert x[-1, I["rel_log_area"]] == 0 and x[-1, I["rel_x_km"]] == 0


def test_forcing_ahead_says_only_whether_horizon_forcing_was_given():
    shapes, times, envs = sequence()
    held, _, _ = F.window_features(shapes, times, envs, drift_of(envs))
    ahead, _, _ = F.window_features(shapes, times, envs, drift_of(envs), forcing_ahead=True)
    column = I["forcing_ahead"]
    assert np.all(ahead[-5:, column] == 1) and np.all(ahead[:-5, column] == 0) and np.all(held[:, column] == 0)
    assert np.array_equal(np.delete(ahead, column, axis=1), np.delete(held, column, axis=1))


def test_prepare_refuses_bad_input_by_name():
    g = F.to_lonlat(Point(0, 0).buffer(1_000))
    from datetime import datetime, timezone
    t0 = datetime(2020, 5, 1, 12)
    with pytest.raises(ValueError, match="no observations"):
        prepare([], [])
    with pytest.raises(ValueError, match="strictly increase"):
        prepare([g, g], [t0, t0])
    with pytest.raises(ValueError, match="non-finite"):
        prepare([g], [t0], [F.Environment(1.0, math.nan, 0.0, 0.0, 28.0)])
    naive, aware = prepare([g], [t0]), prepare([g], [t0.replace(tzinfo=timezone.utc)])
    assert naive.times_s.tolist() == aware.times_s.tolist()


def test_scaler_zscore_clip_zero_variance_and_round_trip():
    rng = np.random.default_rng(1)
    n = len(F.FEATURE_NAMES)
    x = rng.normal(5.0, 2.0, (500, n))
    x[:, 3] = 7.0  # constant column
    scaler = F.FeatureScaler.fit(x)
    assert scaler.std[3] == 1.0
    z = scaler.transform(x)
    assert np.abs(z).max() <= 3.0 and np.allclose(z[:, 3], 0.0)
    again = F.FeatureScaler.from_dict(scaler.to_dict())
    assert np.array_equal(again.mean, scaler.mean) and np.array_equal(again.std, scaler.std)
    bad = np.zeros((3, n))
    bad[2, 4] = np.nan
    with pytest.raises(ValueError, match="drift_u is nan at row 2"):
        F.FeatureScaler.fit(bad)


@requires_shared("data/dwh")
def test_real_dwh_composites_shapes():
    """Areas of the largest NOAA/NESDIS polygon and of all of them, as the data README measured."""
    for day, largest_km2, total_km2, parts in (("17", 26_141.9, 26_800.7, 11), ("19", 20_612.1, 21_269.4, 46),
                                              ("20", 13_944.9, 23_081.5, 260)):
        obs = read_polygons(DWH / f"dwh-2010-05-{day}.geojson")
        plane = F.SpillPlane.about(obs.geometry)
        shape = F.Shape.of(plane.to_plane(obs.geometry))
        assert shape.area / 1e6 == pytest.approx(total_km2, rel=2e-3)
        assert shape.largest_fraction * shape.area / 1e6 == pytest.approx(largest_km2, rel=2e-3)
        assert shape.n_parts == parts
        assert np.allclose(shape.centroid, 0.0, atol=1e-3)      # the plane's origin is the centroid
