"""Predicted features -> a boundary polygon.

Design choice: the forecast moves and reshapes the *last observed* polygon rather than drawing a new
shape. On the equal-area plane one affine map is applied to every part of that polygon:

    p' = c_new + R(θ_new) · diag(√(s·q), √(s/q)) · R(−θ_old) · (p − c_old)

with c the centroid, θ the major-axis angle (from ``orientation_cos2/sin2``), s = A_new/A_old the
area ratio (from ``log_area_km2``) and q = aspect_new/aspect_old. The determinant is s, so the
selected part's area becomes exactly the predicted area; its centroid lands exactly on the predicted
centroid; for an ellipse the new aspect ratio and orientation are exactly the predicted ones. Fine
boundary detail (lobes, fingers) is carried over from the observation, which is what persistence
would do too, so any skill over persistence comes from the predicted motion and deformation.
"""
from __future__ import annotations

import math

import numpy as np
from shapely import affinity
from shapely.geometry.base import BaseGeometry

from .features import (FEATURE_INDEX, MAX_ASPECT_RATIO, TARGET_NAMES, polygon_parts, select_geometry,
                       second_moments, shape_axes, to_lonlat, to_plane)


def target_values(features: np.ndarray, names=TARGET_NAMES) -> dict[str, float]:
    """The named entries of a 25-feature row, as the dict ``rebuild_boundary`` takes."""
    return {name: float(features[FEATURE_INDEX[name]]) for name in names}


def rebuild_boundary(last_geometry: BaseGeometry, predicted, *, multipolygon: str = "largest",
                     names=TARGET_NAMES) -> BaseGeometry:
    """The last observed EPSG:4326 geometry moved/scaled/rotated to match ``predicted`` targets.

    ``predicted`` is a mapping name -> value, or a sequence in ``names`` order, holding
    centroid_x_km, centroid_y_km, log_area_km2, aspect_ratio, orientation_cos2, orientation_sin2.
    ``multipolygon`` must be the mode the features were computed with.
    """
    values = dict(predicted) if isinstance(predicted, dict) else dict(zip(names, map(float, predicted), strict=True))
    missing = [n for n in TARGET_NAMES if n not in values]
    if missing:
        raise ValueError(f"predicted targets lack {', '.join(missing)}")
    if not all(math.isfinite(values[n]) for n in TARGET_NAMES):
        raise ValueError(f"predicted targets are not finite: {values}")
    plane = to_plane(last_geometry)
    area, centroid, cov = second_moments(select_geometry(plane, multipolygon))
    aspect_old, theta_old = shape_axes(cov)
    area_ratio = math.exp(values["log_area_km2"]) * 1e6 / area
    aspect_ratio = min(max(values["aspect_ratio"], 1.0), MAX_ASPECT_RATIO) / aspect_old
    c2, s2 = values["orientation_cos2"], values["orientation_sin2"]
    theta_new = 0.5 * math.atan2(s2, c2) if math.hypot(c2, s2) > 1e-9 else theta_old
    stretch = np.diag([math.sqrt(area_ratio * aspect_ratio), math.sqrt(area_ratio / aspect_ratio)])
    matrix = _rotation(theta_new) @ stretch @ _rotation(-theta_old)
    target = np.array([values["centroid_x_km"], values["centroid_y_km"]]) * 1e3
    offset = target - matrix @ centroid
    moved = affinity.affine_transform(plane, [matrix[0, 0], matrix[0, 1], matrix[1, 0], matrix[1, 1], *offset])
    return to_lonlat(moved)


def _rotation(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def outline(geometry: BaseGeometry) -> list[tuple[float, float]]:
    """Exterior ring of the largest part (open: no repeated first point), for a one-ring boundary."""
    parts = polygon_parts(to_plane(geometry))
    if not parts:
        raise ValueError("geometry holds no polygon")
    largest = to_lonlat(parts[0])
    return [tuple(map(float, xy)) for xy in np.asarray(largest.exterior.coords)[:-1]]

