"""What the learned correction sees: features that say how the spill moves and changes, never where or when.

Nothing absolute goes in: no position, no distance to a wellhead, no time since release, no clock or
season. Each observation is described on a plane centred on the latest observation's centroid
(``SpillPlane``), in a frame turned so that the forcing-predicted drift at the latest observation
points along +x. Translating or rotating the whole input (polygons with their forcing) therefore leaves
every feature unchanged, and the model's outputs, expressed in that frame, move with the input.
Definitions of every feature are in ``docs/forecaster-features.md``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import lru_cache

import numpy as np
import pyproj
import shapely
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.base import BaseGeometry
from shapely.geometry.polygon import orient

# Wellhead position given by the paper (28°44'12" N, 88°23'14" W): the centre of the map plane the
# rest of the project draws on (``to_plane``); the forecaster itself works on ``SpillPlane``.
DWH_LAT = 28.0 + 44.0 / 60 + 12.0 / 3600
DWH_LON = -(88.0 + 23.0 / 60 + 14.0 / 3600)
EQUAL_AREA_CRS = f"+proj=laea +lat_0={DWH_LAT:.6f} +lon_0={DWH_LON:.6f} +datum=WGS84 +units=m +no_defs"

HORIZONS_H = (3, 7, 11, 15)
WINDOW = 16
MAX_ASPECT_RATIO = 1000.0
FRAME_CELL_DEG = 0.25       # SpillPlane projections are centred on this grid (one pyproj set-up per cell)
CALM_MS = 1e-3              # below this drift speed the frame keeps east as +x

STEP_FEATURES = (
    "observed", "dt_h", "obs_u", "obs_v", "drift_u", "drift_v", "resid_u", "resid_v",
    "wind_u", "wind_v", "current_u", "current_v", "rel_log_area", "log_area_rate", "log_aspect",
    "orient_cos2", "orient_sin2", "log_parts", "largest_fraction", "compactness", "rel_x_km", "rel_y_km",
    "log_area_km2", "error_u", "error_v", "forcing_ahead", "cv_weight",
)
FEATURE_NAMES = STEP_FEATURES
FEATURE_INDEX = {name: i for i, name in enumerate(FEATURE_NAMES)}
# What the correction predicts per horizon: drift residual (frame x, y, km) and log area ratio
# against the physics prior.
TARGET_NAMES = ("resid_x_km", "resid_y_km", "log_area_ratio")


# ---------------------------------------------------------------------------------------------------
# The equal-area plane

@lru_cache(maxsize=1)
def _transformers() -> tuple[pyproj.Transformer, pyproj.Transformer]:
    return (pyproj.Transformer.from_crs("EPSG:4326", EQUAL_AREA_CRS, always_xy=True),
            pyproj.Transformer.from_crs(EQUAL_AREA_CRS, "EPSG:4326", always_xy=True))


def lonlat_to_plane(lon, lat):
    """Vectorised lon/lat degrees -> x/y metres east/north of the wellhead on the equal-area plane."""
    return _transformers()[0].transform(lon, lat)


def plane_to_lonlat(x, y):
    """Vectorised equal-area x/y metres -> lon/lat degrees."""
    return _transformers()[1].transform(x, y)


@lru_cache(maxsize=64)
def local_frame(lon0: float, lat0: float):
    """(to_local, to_lonlat): vectorised lon/lat <-> metres on a Lambert azimuthal equal-area plane
    centred on (lon0, lat0). Areas are exact and, within a few hundred km, distances and angles too."""
    crs = f"+proj=laea +lat_0={lat0:.6f} +lon_0={lon0:.6f} +datum=WGS84 +units=m +no_defs"
    forward = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    backward = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    return forward.transform, backward.transform


def to_plane(geometry: BaseGeometry) -> BaseGeometry:
    """An EPSG:4326 geometry on the equal-area plane (metres)."""
    return shapely.transform(geometry, lambda xy: np.column_stack(lonlat_to_plane(xy[:, 0], xy[:, 1])))


def to_lonlat(geometry: BaseGeometry) -> BaseGeometry:
    """An equal-area-plane geometry (metres) back in EPSG:4326."""
    return shapely.transform(geometry, lambda xy: np.column_stack(plane_to_lonlat(xy[:, 0], xy[:, 1])))


# ---------------------------------------------------------------------------------------------------
# One observation

@dataclass(frozen=True)
class Environment:
    """Forcing at the spill: wind and surface current (m/s, towards east/north) and sea temperature."""

    wind_u: float
    wind_v: float
    current_u: float
    current_v: float
    sea_temp_c: float

    def as_array(self) -> np.ndarray:
        return np.array([self.wind_u, self.wind_v, self.current_u, self.current_v, self.sea_temp_c])


def polygon_parts(geometry: BaseGeometry) -> list[Polygon]:
    """The non-empty polygons of a Polygon/MultiPolygon/GeometryCollection, largest first."""
    parts = [g for g in shapely.get_parts(geometry) if isinstance(g, Polygon) and not g.is_empty]
    for g in shapely.get_parts(geometry):
        if isinstance(g, MultiPolygon):
            parts.extend(p for p in g.geoms if not p.is_empty)
    return sorted(parts, key=lambda p: p.area, reverse=True)


def second_moments(plane_geometry: BaseGeometry) -> tuple[float, np.ndarray, np.ndarray]:
    """(area, centroid, 2x2 covariance of the filled region) from Green's theorem over every ring."""
    area = 0.0
    first = np.zeros(2)
    second = np.zeros(3)  # ∫x², ∫xy, ∫y² about the origin of a local shift
    shift = np.asarray(plane_geometry.centroid.coords[0])
    for poly in polygon_parts(plane_geometry):
        poly = orient(poly, 1.0)  # exterior counter-clockwise, holes clockwise: signed sums just add
        for ring in (poly.exterior, *poly.interiors):
            xy = np.asarray(ring.coords) - shift
            x0, y0, x1, y1 = xy[:-1, 0], xy[:-1, 1], xy[1:, 0], xy[1:, 1]
            cross = x0 * y1 - x1 * y0
            area += cross.sum() / 2
            first += [((x0 + x1) * cross).sum() / 6, ((y0 + y1) * cross).sum() / 6]
            second += [(cross * (x0 * x0 + x0 * x1 + x1 * x1)).sum() / 12,
                        (cross * (x0 * y1 + 2 * x0 * y0 + 2 * x1 * y1 + x1 * y0)).sum() / 24,
                        (cross * (y0 * y0 + y0 * y1 + y1 * y1)).sum() / 12]
    if area <= 0:
        raise ValueError("geometry has no area")
    mean = first / area
    cxx = second[0] / area - mean[0] ** 2
    cxy = second[1] / area - mean[0] * mean[1]
    cyy = second[2] / area - mean[1] ** 2
    return area, mean + shift, np.array([[cxx, cxy], [cxy, cyy]])


def shape_axes(cov: np.ndarray) -> tuple[float, float]:
    """(aspect ratio, major-axis angle in radians from east, counter-clockwise) of a covariance."""
    cxx, cxy, cyy = cov[0, 0], cov[0, 1], cov[1, 1]
    spread = math.hypot(cxx - cyy, 2 * cxy)
    major, minor = (cxx + cyy + spread) / 2, (cxx + cyy - spread) / 2
    aspect = math.sqrt(major / minor) if minor > major / MAX_ASPECT_RATIO ** 2 else MAX_ASPECT_RATIO
    # A disc has no axis: report 0 (east) rather than noise.
    theta = 0.5 * math.atan2(2 * cxy, cxx - cyy) if spread > 1e-6 * (cxx + cyy) else 0.0
    return aspect, theta


def check_finite(features: np.ndarray, where: str = "features") -> None:
    """Refuse NaN/inf features, naming the first offending row and feature."""
    bad = ~np.isfinite(features)
    if bad.any():
        row, col = np.argwhere(bad)[0]
        name = FEATURE_NAMES[col] if features.shape[-1] == len(FEATURE_NAMES) else f"column {col}"
        raise ValueError(f"{where}: {name} is {features[row, col]} at row {row}")


# ---------------------------------------------------------------------------------------------------
# Scaling

@dataclass
class FeatureScaler:
    """z-score from training statistics, clipped to ±``clip`` σ; zero-variance columns get σ = 1."""

    mean: np.ndarray
    std: np.ndarray
    clip: float = 3.0

    @classmethod
    def fit(cls, features: np.ndarray, clip: float = 3.0) -> "FeatureScaler":
        flat = np.asarray(features, dtype=float).reshape(-1, np.shape(features)[-1])
        if len(flat) == 0:
            raise ValueError("cannot fit a scaler on no observations")
        check_finite(flat, where="scaler training data")
        mean, std = flat.mean(axis=0), flat.std(axis=0)
        std = np.where(std > 1e-9 * np.maximum(1.0, np.abs(mean)), std, 1.0)
        return cls(mean=mean, std=std, clip=clip)

    def _columns(self, columns):
        return slice(None) if columns is None else list(columns)

    def transform(self, features: np.ndarray, columns=None) -> np.ndarray:
        """Scale ``features`` whose last axis is all columns, or the listed ``columns`` only."""
        cols = self._columns(columns)
        z = (np.asarray(features, dtype=float) - self.mean[cols]) / self.std[cols]
        return np.clip(z, -self.clip, self.clip)

    def inverse_transform(self, scaled: np.ndarray, columns=None) -> np.ndarray:
        cols = self._columns(columns)
        return np.asarray(scaled, dtype=float) * self.std[cols] + self.mean[cols]

    def to_dict(self) -> dict:
        return {"feature_names": list(FEATURE_NAMES), "mean": self.mean.tolist(),
                "std": self.std.tolist(), "clip": self.clip}

    @classmethod
    def from_dict(cls, data: dict) -> "FeatureScaler":
        if list(data.get("feature_names", FEATURE_NAMES)) != list(FEATURE_NAMES):
            raise ValueError("scaler was fitted on a different feature set")
        return cls(mean=np.asarray(data["mean"], float), std=np.asarray(data["std"], float),
                   clip=float(data["clip"]))




def as_utc(time: datetime) -> datetime:
    """Naive times are UTC."""
    return time.replace(tzinfo=timezone.utc) if time.tzinfo is None else time.astimezone(timezone.utc)


# ---------------------------------------------------------------------------------------------------
# The spill's own plane and the per-observation description

def repaired(geometry: BaseGeometry) -> MultiPolygon:
    """Every polygon part of ``geometry`` made valid (overlapping parts merged), as one MultiPolygon."""
    parts = polygon_parts(shapely.make_valid(geometry))
    merged = shapely.union_all(parts) if parts else MultiPolygon()
    return MultiPolygon(polygon_parts(merged))


@dataclass(frozen=True)
class SpillPlane:
    """Metres on an equal-area plane whose origin is ``origin_lonlat`` (the latest centroid)."""

    centre: tuple[float, float]          # projection centre (on the FRAME_CELL_DEG grid)
    origin: tuple[float, float]          # the latest centroid in projection metres

    @classmethod
    def about(cls, geometry: BaseGeometry) -> "SpillPlane":
        lon, lat = geometry.centroid.coords[0]
        centre = (round(lon / FRAME_CELL_DEG) * FRAME_CELL_DEG, round(lat / FRAME_CELL_DEG) * FRAME_CELL_DEG)
        plane = cls(centre, (0.0, 0.0))
        _, c, _ = second_moments(plane.to_plane(geometry))
        return cls(centre, (float(c[0]), float(c[1])))

    def to_plane(self, geometry: BaseGeometry) -> BaseGeometry:
        forward, _ = local_frame(*self.centre)
        ox, oy = self.origin
        return shapely.transform(geometry, lambda xy: np.column_stack(forward(xy[:, 0], xy[:, 1])) - (ox, oy))

    def to_lonlat(self, geometry: BaseGeometry) -> BaseGeometry:
        _, backward = local_frame(*self.centre)
        ox, oy = self.origin
        return shapely.transform(geometry, lambda xy: np.column_stack(backward(xy[:, 0] + ox, xy[:, 1] + oy)))


@dataclass(frozen=True)
class Shape:
    """One observation on the plane: area (m^2), centroid (m), covariance, perimeter, parts."""

    area: float
    centroid: np.ndarray
    cov: np.ndarray
    perimeter: float
    n_parts: int
    largest_fraction: float

    @classmethod
    def of(cls, plane_geometry: BaseGeometry) -> "Shape":
        parts = polygon_parts(plane_geometry)
        if not parts:
            raise ValueError("observation geometry holds no polygon")
        area, centroid, cov = second_moments(plane_geometry)
        return cls(area, centroid, cov, float(sum(p.length for p in parts)), len(parts), parts[0].area / area)


def rotation(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def frame_angle(drift_velocity: np.ndarray) -> float:
    """Angle (radians from east) of the frame's +x axis: the forcing-predicted drift, or east when calm."""
    u, v = float(drift_velocity[0]), float(drift_velocity[1])
    return math.atan2(v, u) if math.hypot(u, v) > CALM_MS else 0.0


def window_features(shapes: list[Shape], times_s: np.ndarray, environments: np.ndarray, drift_of,
                    window: int = WINDOW, drift_error=(0.0, 0.0), forcing_ahead: bool = False,
                    cv_weight: float = 0.0) -> tuple[np.ndarray, np.ndarray, float]:
    """(features [window, F], elapsed hours [window], frame angle) of the latest ``window`` observations.

    ``environments`` [T, 4] wind u/v and current u/v at each observation; ``drift_of(i0, i1)`` the
    forcing-predicted drift velocity [2] m/s averaged between observations i0 and i1; ``drift_error``
    the forcing's drift error estimated from the whole history (``engine.forcing_error``, m/s,
    plane axes), repeated on every observed row; ``forcing_ahead`` whether forcing over the horizon was
    given (else the prior holds the latest forcing), 1 or 0 on every observed row; ``cv_weight`` how far
    the corrected prior was moved towards the observed constant velocity
    (``engine.constant_velocity_weight``), on every observed row. Fewer than
    ``window`` observations are padded at the front with rows of zeros (``observed`` = 0, dt = 0).
    """
    n = len(shapes)
    if n == 0 or len(times_s) != n or len(environments) != n:
        raise ValueError("need one time and one forcing row per observation")
    times_s = np.asarray(times_s, float)
    if np.any(np.diff(times_s) <= 0):
        raise ValueError("observation times must strictly increase")
    angle = frame_angle(drift_of(n - 1, n - 1))
    turn = rotation(-angle)
    last = shapes[-1]
    error = turn @ np.asarray(drift_error, float)
    rows = []
    first = max(0, n - window)
    for i in range(first, n):
        s = shapes[i]
        row = np.zeros(len(FEATURE_NAMES))
        row[0] = 1.0
        if i > 0:
            dt = times_s[i] - times_s[i - 1]
            observed = (s.centroid - shapes[i - 1].centroid) / dt
            drift = np.asarray(drift_of(i - 1, i), float)
            row[1] = dt / 3600
            row[2:4] = turn @ observed
            row[4:6] = turn @ drift
            row[6:8] = turn @ (observed - drift)
            row[13] = (math.log(s.area) - math.log(shapes[i - 1].area)) / (dt / 3600)
        else:
            row[4:6] = turn @ np.asarray(drift_of(0, 0), float)
        env = np.asarray(environments[i], float)
        row[8:10] = turn @ env[0:2]
        row[10:12] = turn @ env[2:4]
        row[12] = math.log(s.area / last.area)
        aspect, theta = shape_axes(s.cov)
        row[14] = math.log(aspect)
        row[15], row[16] = math.cos(2 * (theta - angle)), math.sin(2 * (theta - angle))
        row[17] = math.log(s.n_parts)
        row[18] = s.largest_fraction
        row[19] = min(4 * math.pi * s.area / s.perimeter ** 2, 1.0)
        row[20:22] = turn @ (s.centroid - last.centroid) / 1e3
        row[22] = math.log(s.area / 1e6)
        row[23:25] = error
        row[25] = float(forcing_ahead)
        row[26] = cv_weight
        rows.append(row)
    x = np.vstack(rows)
    elapsed = np.concatenate([[0.0], np.diff(times_s[first:]) / 3600])
    pad = window - len(x)
    if pad > 0:
        x = np.vstack([np.zeros((pad, x.shape[1])), x])
        elapsed = np.concatenate([np.zeros(pad), elapsed])
    check_finite(x, where="window features")
    return x, elapsed, angle

