"""`ScenarioMap` ties the mission's local frame to the world of a spill scenario.

A simulated fleet cannot circle a 10 km slick at 2 m/s in a test, so the scenario is shrunk about
the mission origin by `map_scale` (1 = true size); everything that crosses between the MOOS side
and the forecaster (uFldOilSensor's truth, uFldOilFusion's feedback) goes through it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from moosdb_py.geodesy import LocalGrid


@dataclass(frozen=True)
class ScenarioMap:
    """Mission local metres <-> a scenario's lon/lat, the scenario shrunk by `map_scale` about the origin."""

    grid: LocalGrid
    map_scale: float = 1.0

    def __post_init__(self):
        if not (math.isfinite(self.map_scale) and self.map_scale > 0):
            raise ValueError(f"map_scale {self.map_scale!r} must be a positive number")

    def to_lonlat(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        lat, lon = self.grid.to_latlon(np.asarray(x, float) / self.map_scale, np.asarray(y, float) / self.map_scale)
        return np.asarray(lon), np.asarray(lat)

    def to_local(self, geometry: BaseGeometry) -> BaseGeometry:
        """An EPSG:4326 geometry ([lon, lat] coordinates) in mission metres."""
        def forward(coords):
            x, y = self.grid.to_local(coords[:, 1], coords[:, 0])
            return np.column_stack([x, y]) * self.map_scale
        return shapely.transform(geometry, forward)

    def real_metres(self, metres: float) -> float:
        return metres / self.map_scale
