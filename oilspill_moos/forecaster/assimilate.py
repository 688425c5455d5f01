"""Feedback ingestion: the fleet's oil observations re-anchor the spill before the next model step.

Method (issue 9, the paper's "Feedback Integration & Adaptation"). Every forecast starts from the
latest observed footprint; between satellite passes that footprint grows stale. The vessels' sensors say, at points around the forecast boundary, whether oil lies within
their range. We fit the forecast outline to those answers with a similarity map about its
centroid (shift dx, dy and scale s, three numbers: the sensors see the edge at a few dozen points,
too few for a free shape) minimising, on the equal-area plane in metres,

    sum over detections     max(0, d(p) - r)      (oil was within r: the edge is at most r away)
  + sum over non-detections max(0, r - d(p))      (no oil within r: the edge is further than r)
  + 0.01 (|shift| + sqrt(A) |log s|)             (among equally good fits, the smallest change)

where d is the signed distance from p to the outline (negative inside). The forecast outline moved
by the fitted shift (and scaled only when ``rescale``; operationally not, see ``RESCALE``) is
appended to the observation history at the median observation time as a new "observed" polygon,
so the next forecast starts from it: the re-anchoring. Nothing else about the model changes, and
without observations (or with ``--feedback`` not given) the forecast is exactly the one without
feedback, which is how the two are compared (``benchmarks/feedback_bench.py``).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import shapely
from scipy.optimize import minimize
from shapely import affinity
from shapely.geometry.base import BaseGeometry

from .features import lonlat_to_plane, to_lonlat, to_plane

TIE_BREAK = 0.01
WINDOW_H = 1.0   # readings used for one re-anchoring: the last hour's (about one pass of the loop)
# The operational re-anchoring moves the outline but keeps its size: on the out-of-distribution split
# (benchmarks/feedback_bench.py) shift and scale cost IoU on average (-0.006 to -0.025 at the later
# cycles), the shift alone never did (+0.004 to +0.007) and cut the centroid error by 11-14 %.
RESCALE = False


@dataclass(frozen=True)
class SensorReadings:
    """Point observations in EPSG:4326: oil within ``range_m`` metres of (lon, lat) or not."""

    lon: np.ndarray
    lat: np.ndarray
    oil: np.ndarray
    range_m: np.ndarray
    utc: np.ndarray     # seconds since the epoch, the simulated world's clock

    def __len__(self) -> int:
        return len(self.oil)

    def time(self) -> datetime:
        """The median observation time: when the re-anchored outline is valid."""
        return datetime.fromtimestamp(float(np.median(self.utc)), tz=timezone.utc)

    def recent(self, after: datetime, window_h: float) -> "SensorReadings":
        """Readings newer than ``after`` and within ``window_h`` hours of the newest one."""
        newest = self.utc.max(initial=-np.inf)
        keep = (self.utc > after.timestamp()) & (self.utc >= newest - 3600.0 * window_h)
        return SensorReadings(*(a[keep] for a in (self.lon, self.lat, self.oil, self.range_m, self.utc)))


def readings(rows) -> SensorReadings:
    """SensorReadings from dicts with lon, lat, oil, range_m and utc (the feedback file's lines)."""
    rows = list(rows)
    columns = {k: np.array([float(r[k]) for r in rows], dtype=float) for k in ("lon", "lat", "range_m", "utc")}
    oil = np.array([bool(r["oil"]) for r in rows], dtype=bool)
    if not all(np.isfinite(c).all() for c in columns.values()) or (columns["range_m"] < 0).any():
        raise ValueError("observations hold non-finite numbers or a negative range")
    return SensorReadings(columns["lon"], columns["lat"], oil, columns["range_m"], columns["utc"])


def read_feedback(path: Path) -> SensorReadings:
    """The JSON-lines file uFldOilFusion writes (one accepted observation per line)."""
    path = Path(path)
    rows = []
    if path.exists():
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            if line.strip():
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError as exc:
                    raise ValueError(f"{path}:{number}: not JSON ({exc.msg})") from None
    try:
        return readings(rows)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: bad observation ({exc})") from None


def _signed_distance(prepared: BaseGeometry, edge: BaseGeometry, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    d = shapely.distance(edge, shapely.points(x, y))
    return np.where(shapely.contains_xy(prepared, x, y), -d, d)


def fit_similarity(outline: BaseGeometry, xy: np.ndarray, oil: np.ndarray, range_m: np.ndarray,
                   max_shift: float | None = None) -> tuple[float, float, float, float]:
    """(dx, dy, scale, misfit in metres) of the similarity map about the centroid that best explains
    the readings (planar metres; see the module docstring). Identity when nothing disagrees."""
    centre = np.array(outline.centroid.coords[0])
    size = math.sqrt(outline.area)
    max_shift = size if max_shift is None else max_shift
    prepared = shapely.Polygon(outline.exterior) if outline.geom_type == "Polygon" else outline
    shapely.prepare(prepared)
    edge = prepared.boundary
    want_in = oil.astype(bool)

    def cost(params) -> float:
        dx, dy, log_s = params
        s = math.exp(log_s)
        q = centre + (xy - centre - (dx, dy)) / s            # the readings mapped back onto the prior outline
        sd = s * _signed_distance(prepared, edge, q[:, 0], q[:, 1])
        miss = np.where(want_in, np.maximum(0.0, sd - range_m), np.maximum(0.0, range_m - sd))
        return float(miss.sum() / len(miss) + TIE_BREAK * (math.hypot(dx, dy) + size * abs(log_s)))

    # Coarse grid first: with few flips the misfit is flat in places, where a local search stalls.
    grid = np.linspace(-max_shift, max_shift, 9)
    starts = [(dx, dy, ls) for dx in grid for dy in grid for ls in (-0.3, 0.0, 0.3)]
    best = min(starts, key=cost)
    step = 2 * max_shift / 8
    simplex = np.array([best, np.add(best, (step, 0, 0)), np.add(best, (0, step, 0)), np.add(best, (0, 0, 0.15))])
    result = minimize(cost, best, method="Nelder-Mead",
                      options={"initial_simplex": simplex, "xatol": 0.5, "fatol": 1e-3, "maxiter": 400})
    dx, dy, log_s = result.x if result.fun <= cost(best) else best
    return float(dx), float(dy), math.exp(log_s), float(min(result.fun, cost(best)))


def reanchor(prior: BaseGeometry, obs: SensorReadings, max_shift: float | None = None,
             rescale: bool = True) -> BaseGeometry:
    """The EPSG:4326 outline ``prior`` (what the fleet was told) moved, and scaled unless not
    ``rescale``, to fit ``obs``."""
    if len(obs) == 0:
        return prior
    plane = to_plane(prior)
    x, y = lonlat_to_plane(obs.lon, obs.lat)
    dx, dy, scale, _ = fit_similarity(plane, np.column_stack([x, y]), obs.oil, obs.range_m, max_shift)
    scale = scale if rescale else 1.0
    centre = plane.centroid
    moved = affinity.translate(affinity.scale(plane, scale, scale, origin=centre), dx, dy)
    return to_lonlat(moved)


def ingest(forecaster, geometries: list, times: list[datetime], environments, obs: SensorReadings,
           window_h: float = WINDOW_H, release_time: datetime | None = None):
    """The observation history with the re-anchored outline appended (when ``obs`` has readings newer
    than the last polygon; the last ``window_h`` hours of them). The prior is the model's forecast for
    the readings' median time."""
    obs = obs.recent(times[-1], window_h)
    if len(obs) == 0 or len(geometries) < 2:
        return geometries, times, environments
    when = obs.time()
    lead_h = (when - times[-1]).total_seconds() / 3600
    # the forecast for the readings' own time (any horizon): an outline valid an hour before or after
    # them would be appended with the wrong time, and read as motion by the next forecast
    prior = forecaster.forecast(geometries, times, environments, release_time, horizons_h=(max(lead_h, 1e-3),))[0].geometry
    environments = None if environments is None else [*environments, environments[-1]]
    return reanchored_history(geometries, prior, obs), [*times, when], environments


def reanchored_history(geometries: list, prior: BaseGeometry, obs: SensorReadings) -> list:
    """The history with ``prior`` re-anchored on ``obs`` appended, and every earlier observation moved by
    the same shift: the observed motion (which the forecaster's forcing-error estimate and features read)
    stays what it was, and only where the spill is changes. Appending the anchor alone would turn the
    fit's shift into a velocity, extrapolated over the next horizon."""
    anchor = reanchor(prior, obs, rescale=RESCALE)
    shift = np.subtract(to_plane(anchor).centroid.coords[0], to_plane(prior).centroid.coords[0])
    if not np.any(shift):
        return [*geometries, anchor]
    moved = [to_lonlat(affinity.translate(to_plane(g), *shift)) for g in geometries]
    return [*moved, anchor]
