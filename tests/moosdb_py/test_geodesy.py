"""LocalGrid: the origin, round trips, true distances, vectorised use and bad origins."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod

from moosdb_py.geodesy import LocalGrid, utm_zone

# The s1_alpha origin (Forest Lake, Maine).
LAT0, LON0 = 43.825300, -70.330400


def test_origin_maps_to_zero_and_back():
    grid = LocalGrid(LAT0, LON0)
    x, y = grid.to_local(LAT0, LON0)
    assert (x, y) == pytest.approx((0.0, 0.0), abs=1e-6)
    lat, lon = grid.to_latlon(0.0, 0.0)
    assert (lat, lon) == pytest.approx((LAT0, LON0), abs=1e-9)
    assert isinstance(x, float) and isinstance(lat, float)


def test_zone_follows_origin_longitude():
    assert utm_zone(LON0) == 19
    assert utm_zone(-71.087) == 19  # MIT sailing pavilion
    assert utm_zone(10.0) == 32
    assert utm_zone(180.0) == 1


def test_axes_point_east_and_north_with_true_lengths():
    grid = LocalGrid(LAT0, LON0)
    geod = Geod(ellps="WGS84")
    lat_n, lon_n = grid.to_latlon(0.0, 1000.0)
    lat_e, lon_e = grid.to_latlon(1000.0, 0.0)
    az_n, _, dist_n = geod.inv(LON0, LAT0, lon_n, lat_n)
    az_e, _, dist_e = geod.inv(LON0, LAT0, lon_e, lat_e)
    # UTM grid north differs from true north by the meridian convergence (about 1 deg here).
    assert abs(az_n) < 2.0 and abs(az_e - 90.0) < 2.0
    # UTM scale error is below 0.1 % inside a zone.
    assert dist_n == pytest.approx(1000.0, rel=1e-3)
    assert dist_e == pytest.approx(1000.0, rel=1e-3)


def test_vectorised_arrays_keep_their_shape():
    grid = LocalGrid(LAT0, LON0)
    xs = np.array([[0.0, 60.0, 150.0], [-500.0, 2000.0, 10.0]])
    ys = np.array([[-20.0, -40.0, -160.0], [300.0, -2000.0, 0.0]])
    lat, lon = grid.to_latlon(xs, ys)
    assert lat.shape == xs.shape and lon.shape == xs.shape
    x2, y2 = grid.to_local(lat, lon)
    np.testing.assert_allclose(x2, xs, atol=1e-6)
    np.testing.assert_allclose(y2, ys, atol=1e-6)


def test_southern_hemisphere_origin():
    grid = LocalGrid(-33.86, 151.21)
    lat, lon = grid.to_latlon(250.0, -125.0)
    assert lat < -33.86 and lon > 151.21
    assert grid.to_local(lat, lon) == pytest.approx((250.0, -125.0), abs=1e-6)


@pytest.mark.parametrize("lat, lon", [(91.0, 0.0), (0.0, 200.0), (math.nan, 0.0)])
def test_bad_origin_is_a_clear_error(lat, lon):
    with pytest.raises(ValueError, match="Origin"):
        LocalGrid(lat, lon)


@settings(max_examples=40, deadline=None)
@given(
    lat0=st.floats(-70.0, 70.0),
    lon0=st.floats(-179.0, 179.0),
    x=st.floats(-20000.0, 20000.0),
    y=st.floats(-20000.0, 20000.0),
)
def test_round_trip_local_latlon_local(lat0, lon0, x, y):
    grid = LocalGrid(lat0, lon0)
    lat, lon = grid.to_latlon(x, y)
    assert grid.to_local(lat, lon) == pytest.approx((x, y), abs=1e-4)


@settings(max_examples=100)
@given(x=st.floats(-5e4, 5e4), y=st.floats(-5e4, 5e4))
def test_one_position_converts_as_an_array_of_one_does(x, y):
    """Plain floats take pyproj's scalar call (a vehicle's position each AppTick): the same numbers, as floats."""
    grid = LocalGrid(LAT0, LON0)
    lat, lon = grid.to_latlon(x, y)
    assert (lat, lon) == tuple(float(v[0]) for v in grid.to_latlon(np.array([x]), np.array([y])))
    assert type(lat) is float and type(lon) is float
    back = grid.to_local(lat, lon)
    assert back == tuple(float(v[0]) for v in grid.to_local(np.array([lat]), np.array([lon])))
    assert type(back[0]) is float and type(back[1]) is float
