"""Local x/y metres about LatOrigin/LongOrigin, as MOOS-IvP computes them.

MOOS-IvP (built with its default USE_UTM) places the local grid on the UTM zone
that contains the origin: x = easting - origin easting, y = northing - origin
northing, WGS84.  We do the same with pyproj so that positions posted by our
uSimMarine agree with the C++ apps and with pMarineViewer.
"""
from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from pyproj import Transformer


@lru_cache(maxsize=16)
def _utm_transformers(zone: int, south: bool) -> tuple[Transformer, Transformer]:
    """(lat/lon -> UTM, UTM -> lat/lon) for a zone; built once, as pyproj set-up is slow."""
    utm = f"+proj=utm +zone={zone}{' +south' if south else ''} +ellps=WGS84 +datum=WGS84 +units=m +no_defs"
    return (Transformer.from_crs("EPSG:4326", utm, always_xy=True),
            Transformer.from_crs(utm, "EPSG:4326", always_xy=True))


def utm_zone(long_origin: float) -> int:
    """The UTM zone number (1..60) that MOOS picks for an origin longitude."""
    return int(math.floor((long_origin + 180.0) / 6.0)) % 60 + 1


class LocalGrid:
    """Converts between lat/lon (degrees, WGS84) and local metres (x east, y north)."""

    def __init__(self, lat_origin: float, long_origin: float):
        lat_origin = float(lat_origin)
        long_origin = float(long_origin)
        if not (math.isfinite(lat_origin) and -90.0 < lat_origin < 90.0):
            raise ValueError(f"LatOrigin {lat_origin!r} is not a latitude in (-90, 90)")
        if not (math.isfinite(long_origin) and -180.0 <= long_origin <= 180.0):
            raise ValueError(f"LongOrigin {long_origin!r} is not a longitude in [-180, 180]")
        self.lat_origin = lat_origin
        self.long_origin = long_origin
        self.zone = utm_zone(long_origin)
        self._forward, self._inverse = _utm_transformers(self.zone, lat_origin < 0)
        self.origin_easting, self.origin_northing = self._forward.transform(long_origin, lat_origin)

    def to_local(self, lat, lon):
        """(lat, lon) degrees -> (x, y) metres; scalars or arrays of any matching shape."""
        if type(lat) is float and type(lon) is float:     # one position (a vehicle's, each AppTick): no arrays
            east, north = self._forward.transform(lon, lat)
            return east - self.origin_easting, north - self.origin_northing
        east, north = self._forward.transform(np.asarray(lon, dtype=float), np.asarray(lat, dtype=float))
        return _like(lat, east - self.origin_easting), _like(lat, north - self.origin_northing)

    def to_latlon(self, x, y):
        """(x, y) metres -> (lat, lon) degrees; scalars or arrays of any matching shape."""
        if type(x) is float and type(y) is float:
            lon, lat = self._inverse.transform(x + self.origin_easting, y + self.origin_northing)
            return lat, lon
        east = np.asarray(x, dtype=float) + self.origin_easting
        north = np.asarray(y, dtype=float) + self.origin_northing
        lon, lat = self._inverse.transform(east, north)
        return _like(x, lat), _like(x, lon)

    def __repr__(self) -> str:
        return f"LocalGrid(lat_origin={self.lat_origin}, long_origin={self.long_origin})"


def mission_grid(mission) -> LocalGrid | None:
    """The mission's local grid, or None when it gives no LatOrigin/LongOrigin."""
    if mission is None or mission.lat_origin is None or mission.long_origin is None:
        return None
    return LocalGrid(mission.lat_origin, mission.long_origin)


def _like(template, values):
    """Return a Python float when the caller passed scalars, else an ndarray."""
    if np.ndim(template) == 0:
        return float(values)
    return np.asarray(values, dtype=float)
