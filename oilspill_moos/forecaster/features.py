"""The 25-number description of one spill observation, its scaling, and the model's 16-step windows.

Definitions of every feature are in ``docs/forecaster-features.md``. All lengths and areas are measured
on one Lambert azimuthal equal-area plane centred on the Deepwater Horizon wellhead (``EQUAL_AREA_CRS``):
areas are exact there and shapes are nearly undistorted across the northern Gulf, so a circle stays a
circle and orientation means compass orientation.
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

# Wellhead position given by the paper (28°44'12" N, 88°23'14" W).
DWH_LAT = 28.0 + 44.0 / 60 + 12.0 / 3600
DWH_LON = -(88.0 + 23.0 / 60 + 14.0 / 3600)
EQUAL_AREA_CRS = f"+proj=laea +lat_0={DWH_LAT:.6f} +lon_0={DWH_LON:.6f} +datum=WGS84 +units=m +no_defs"

GEOMETRY_FEATURES = (
    "area_km2", "log_area_km2", "perimeter_km", "compactness", "convexity",
    "aspect_ratio", "orientation_cos2", "orientation_sin2", "n_components", "largest_fraction",
)
POSITION_FEATURES = ("centroid_lon", "centroid_lat", "centroid_x_km", "centroid_y_km", "distance_km")
TIME_FEATURES = ("hours_since_release", "hour_sin", "hour_cos", "doy_sin", "doy_cos")
ENVIRONMENT_FEATURES = ("wind_u", "wind_v", "current_u", "current_v", "sea_temp_c")
FEATURE_NAMES = GEOMETRY_FEATURES + POSITION_FEATURES + TIME_FEATURES + ENVIRONMENT_FEATURES
FEATURE_INDEX = {name: i for i, name in enumerate(FEATURE_NAMES)}

# What the models forecast: exactly what boundary.rebuild_boundary needs to move and reshape a polygon.
TARGET_NAMES = ("centroid_x_km", "centroid_y_km", "log_area_km2", "aspect_ratio",
                "orientation_cos2", "orientation_sin2")
TARGET_INDICES = tuple(FEATURE_INDEX[name] for name in TARGET_NAMES)

HORIZONS_H = (3, 7, 11, 15)
WINDOW = 16
MULTIPOLYGON_MODES = ("largest", "union")
# Multi-scale sequences (paper, "Multi-Scale Temporal Modeling"): step between inputs and the latest
# time a window may end at (None: no limit).
SCALES = {"hourly": {"step_h": 1.0, "max_end_h": 48.0}, "daily": {"step_h": 24.0, "max_end_h": None}}
MAX_ASPECT_RATIO = 1000.0


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


def select_geometry(plane_geometry: BaseGeometry, multipolygon: str = "largest") -> BaseGeometry:
    """Largest component (the paper's rule) or the union of all parts, on the plane."""
    if multipolygon not in MULTIPOLYGON_MODES:
        raise ValueError(f"multipolygon must be one of {MULTIPOLYGON_MODES}, not {multipolygon!r}")
    parts = polygon_parts(plane_geometry)
    if not parts:
        raise ValueError("geometry holds no polygon")
    return parts[0] if multipolygon == "largest" else shapely.union_all(parts)


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


def _as_utc(time: datetime) -> datetime:
    return time.replace(tzinfo=timezone.utc) if time.tzinfo is None else time.astimezone(timezone.utc)


def time_features(time: datetime, release_time: datetime) -> np.ndarray:
    """Hours since release plus time of day and day of year on the unit circle."""
    time, release_time = _as_utc(time), _as_utc(release_time)
    hours = (time - release_time).total_seconds() / 3600.0
    day_angle = 2 * math.pi * (time.hour + time.minute / 60 + time.second / 3600) / 24
    year_angle = 2 * math.pi * (time.timetuple().tm_yday - 1 + day_angle / (2 * math.pi)) / 365.25
    return np.array([hours, math.sin(day_angle), math.cos(day_angle), math.sin(year_angle), math.cos(year_angle)])


def observation_features(geometry: BaseGeometry, time: datetime, environment: Environment, *,
                         release_time: datetime, multipolygon: str = "largest") -> np.ndarray:
    """The 25 features (``FEATURE_NAMES`` order) of one EPSG:4326 spill geometry."""
    plane = to_plane(geometry)
    parts = polygon_parts(plane)
    if not parts:
        raise ValueError("observation geometry holds no polygon")
    total_area = sum(p.area for p in parts)
    chosen = select_geometry(plane, multipolygon)
    area, centroid, cov = second_moments(chosen)
    perimeter = chosen.length
    aspect, theta = shape_axes(cov)
    lon, lat = plane_to_lonlat(centroid[0], centroid[1])
    geometry_part = [
        area / 1e6, math.log(area / 1e6), perimeter / 1e3, 4 * math.pi * area / perimeter ** 2,
        area / chosen.convex_hull.area, aspect, math.cos(2 * theta), math.sin(2 * theta),
        float(len(parts)), parts[0].area / total_area,
    ]
    position_part = [lon, lat, centroid[0] / 1e3, centroid[1] / 1e3, math.hypot(*centroid) / 1e3]
    row = np.concatenate([geometry_part, position_part, time_features(time, release_time),
                          environment.as_array()])
    check_finite(row[None, :], where="observation features")
    return row


def feature_matrix(geometries, times, environments, *, release_time: datetime,
                   multipolygon: str = "largest") -> np.ndarray:
    """[T, 25] features of a sequence of observations."""
    rows = [observation_features(g, t, e, release_time=release_time, multipolygon=multipolygon)
            for g, t, e in zip(geometries, times, environments, strict=True)]
    return np.vstack(rows) if rows else np.empty((0, len(FEATURE_NAMES)))


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


# ---------------------------------------------------------------------------------------------------
# Sequences, padding and windows

_ANGLE_PAIRS = ((FEATURE_INDEX["hour_sin"], FEATURE_INDEX["hour_cos"], 24.0),
                (FEATURE_INDEX["doy_sin"], FEATURE_INDEX["doy_cos"], 24.0 * 365.25))
_TREND = [FEATURE_INDEX[n] for n in GEOMETRY_FEATURES + POSITION_FEATURES if n != "area_km2"]


def shift_time(rows: np.ndarray, dt_h: float | np.ndarray) -> np.ndarray:
    """Feature rows with the time features moved ``dt_h`` hours exactly (clock angles rotated).

    ``rows`` is one row (broadcast over every ``dt_h``) or one row per ``dt_h``.
    """
    dt = np.atleast_1d(np.asarray(dt_h, dtype=float))
    out = np.array(np.broadcast_to(np.asarray(rows, dtype=float), (len(dt), len(FEATURE_NAMES))))
    out[:, FEATURE_INDEX["hours_since_release"]] += dt
    for s, c, period in _ANGLE_PAIRS:
        angle = np.arctan2(out[:, s], out[:, c]) + 2 * np.pi * dt / period
        out[:, s], out[:, c] = np.sin(angle), np.cos(angle)
    return out


def _make_consistent(rows: np.ndarray) -> np.ndarray:
    """Repair extrapolated/interpolated rows so derived features agree with the trended ones."""
    i = FEATURE_INDEX
    rows[:, i["area_km2"]] = np.exp(rows[:, i["log_area_km2"]])
    rows[:, i["perimeter_km"]] = np.maximum(rows[:, i["perimeter_km"]], 1e-6)
    for name in ("compactness", "convexity", "largest_fraction"):
        rows[:, i[name]] = np.clip(rows[:, i[name]], 1e-6, 1.0)
    rows[:, i["aspect_ratio"]] = np.clip(rows[:, i["aspect_ratio"]], 1.0, MAX_ASPECT_RATIO)
    rows[:, i["n_components"]] = np.maximum(rows[:, i["n_components"]], 1.0)
    norm = np.hypot(rows[:, i["orientation_cos2"]], rows[:, i["orientation_sin2"]])
    norm = np.where(norm > 1e-9, norm, 1.0)
    rows[:, i["orientation_cos2"]] /= norm
    rows[:, i["orientation_sin2"]] /= norm
    x, y = rows[:, i["centroid_x_km"]], rows[:, i["centroid_y_km"]]
    rows[:, i["centroid_lon"]], rows[:, i["centroid_lat"]] = plane_to_lonlat(x * 1e3, y * 1e3)
    rows[:, i["distance_km"]] = np.hypot(x, y)
    return rows


def interpolate(times_h: np.ndarray, features: np.ndarray, new_times_h: np.ndarray) -> np.ndarray:
    """Features at ``new_times_h`` (inside the observed span) by linear interpolation in time.

    Time features are recomputed exactly from the preceding observation rather than interpolated.
    """
    times_h, features = np.asarray(times_h, float), np.asarray(features, float)
    new = np.asarray(new_times_h, float)
    if len(times_h) == 0 or new.min(initial=times_h[0]) < times_h[0] - 1e-9 or new.max(initial=times_h[-1]) > times_h[-1] + 1e-9:
        raise ValueError("interpolation times fall outside the observed span")
    out = np.column_stack([np.interp(new, times_h, features[:, c]) for c in range(features.shape[1])])
    before = np.clip(np.searchsorted(times_h, new, side="right") - 1, 0, len(times_h) - 1)
    timed = shift_time(features[before], new - times_h[before])
    columns = [FEATURE_INDEX[name] for name in TIME_FEATURES]
    out[:, columns] = timed[:, columns]
    return _make_consistent(out)


def pad_by_trend(times_h: np.ndarray, features: np.ndarray, length: int, trend_points: int = 4
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Prepend observations until the sequence has ``length`` steps (the paper's padding).

    Padded steps are spaced by the median observed step. Geometry and position features follow the
    least-squares linear trend of the first ``trend_points`` observations (log area rather than area,
    so the area stays positive), time features are exact, and the environment is held at its first
    value. Needs at least two observations.
    """
    times_h, features = np.asarray(times_h, float), np.asarray(features, float)
    missing = length - len(times_h)
    if missing <= 0:
        return times_h, features
    if len(times_h) < 2:
        raise ValueError(f"cannot extrapolate a trend from {len(times_h)} observation(s); need 2")
    step = float(np.median(np.diff(times_h)))
    new_times = times_h[0] - step * np.arange(missing, 0, -1)
    rows = shift_time(features[0], new_times - times_h[0])
    k = min(trend_points, len(times_h))
    slope, intercept = np.polyfit(times_h[:k], features[:k][:, _TREND], 1)
    rows[:, _TREND] = new_times[:, None] * slope + intercept
    rows = _make_consistent(rows)
    return np.concatenate([new_times, times_h]), np.vstack([rows, features])


def resample(times_h: np.ndarray, features: np.ndarray, step_h: float) -> tuple[np.ndarray, np.ndarray]:
    """Regular sequence every ``step_h`` hours from the first observation (interpolated)."""
    times_h = np.asarray(times_h, float)
    new = np.arange(times_h[0], times_h[-1] + 1e-9, step_h)
    return new, interpolate(times_h, features, new)


def elapsed_hours(times_h: np.ndarray) -> np.ndarray:
    """Time since the previous step; the first step gets the median step of the sequence."""
    times_h = np.asarray(times_h, float)
    if len(times_h) < 2:
        return np.ones_like(times_h)
    diffs = np.diff(times_h)
    if (diffs <= 0).any():
        raise ValueError("observation times must increase strictly")
    return np.concatenate([[np.median(diffs)], diffs])


@dataclass
class Windows:
    """Model samples. Arrays are raw (unscaled) features; scale with a fitted ``FeatureScaler``."""

    inputs: np.ndarray        # [N, window, 25]
    elapsed_h: np.ndarray     # [N, window] hours since the previous step
    targets: np.ndarray       # [N, len(horizons), len(target_names)]
    sequence: np.ndarray      # [N] index of the source sequence
    end_time_h: np.ndarray    # [N] time of the last input step (same clock as the sequence times)
    n_padded: np.ndarray      # [N] leading steps made up by trend padding
    horizons_h: tuple = HORIZONS_H
    target_names: tuple = TARGET_NAMES
    scale: str = "hourly"

    def __len__(self) -> int:
        return len(self.inputs)


def latest_window(times_h, features, window: int = WINDOW) -> tuple[np.ndarray, np.ndarray, int]:
    """The input window ending at the last observation, for an operational forecast.

    Returns (inputs [window, 25], elapsed_h [window], number of padded steps). A sequence shorter
    than ``window`` is padded by trend extrapolation (``pad_by_trend``).
    """
    times_h, features = np.asarray(times_h, float), np.asarray(features, float)
    check_finite(features, where="observation sequence")
    elapsed_hours(times_h)
    n_padded = max(0, window - len(times_h))
    t, x = pad_by_trend(times_h[-window:], features[-window:], window)
    return x, elapsed_hours(t), n_padded


def make_windows(sequences, *, window: int = WINDOW, horizons_h=HORIZONS_H, scale: str | None = "hourly",
                 target_names=TARGET_NAMES, stride: int = 1, min_observed: int = 4,
                 pad: bool = True) -> Windows:
    """Sliding windows over many sequences, each ``(times_h, features [T, 25])``.

    ``scale`` picks a multi-scale view (``SCALES``: "hourly" inputs ending within the first 48 h, or
    "daily" inputs); ``None`` keeps the observations as they are (irregular steps allowed). Targets
    are the listed features at the last input time + each horizon, interpolated from the full
    original sequence. Windows with fewer than ``window`` real steps (but at least ``min_observed``)
    are completed by ``pad_by_trend`` when ``pad``; otherwise they are left out.
    """
    target_cols = [FEATURE_INDEX[n] for n in target_names]
    max_end = None
    step = None
    if scale is not None:
        if scale not in SCALES:
            raise ValueError(f"scale must be one of {tuple(SCALES)} or None, not {scale!r}")
        step, max_end = SCALES[scale]["step_h"], SCALES[scale]["max_end_h"]
    if min_observed < 2:
        raise ValueError("min_observed must be >= 2 (padding extrapolates a trend)")
    inputs, elapsed, targets, seq_ids, ends, padded = [], [], [], [], [], []
    for s, (times_h, feats) in enumerate(sequences):
        times_h, feats = np.asarray(times_h, float), np.asarray(feats, float)
        check_finite(feats, where=f"sequence {s}")
        elapsed_hours(times_h)
        t, x = (times_h, feats) if step is None else resample(times_h, feats, step)
        seq_ends = []
        for e in range(len(t) - 1, -1, -stride):
            end = t[e]
            if end + max(horizons_h) > times_h[-1] + 1e-9 or (max_end is not None and end > max_end + 1e-9):
                continue
            start = max(0, e - window + 1)
            real = e - start + 1
            if real < window and (not pad or real < min_observed):
                continue
            wt, wx = pad_by_trend(t[start:e + 1], x[start:e + 1], window)
            inputs.append(wx)
            elapsed.append(elapsed_hours(wt))
            seq_ends.append(end)
            padded.append(window - real)
        if seq_ends:
            when = (np.asarray(seq_ends)[:, None] + np.asarray(horizons_h, float)).ravel()
            targets.extend(interpolate(times_h, feats, when)[:, target_cols].reshape(len(seq_ends), -1, len(target_cols)))
            seq_ids += [s] * len(seq_ends)
            ends += seq_ends
    n_t, n_h = len(target_cols), len(horizons_h)
    order = np.lexsort((np.asarray(ends), np.asarray(seq_ids))) if seq_ids else np.array([], int)
    return Windows(
        inputs=np.asarray(inputs, float).reshape(-1, window, len(FEATURE_NAMES))[order],
        elapsed_h=np.asarray(elapsed, float).reshape(-1, window)[order],
        targets=np.asarray(targets, float).reshape(-1, n_h, n_t)[order],
        sequence=np.asarray(seq_ids, int)[order], end_time_h=np.asarray(ends, float)[order],
        n_padded=np.asarray(padded, int)[order], horizons_h=tuple(horizons_h),
        target_names=tuple(target_names), scale=scale or "native",
    )
