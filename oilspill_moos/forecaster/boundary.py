"""What is pushed to pPathAssign for a forecast footprint: one ring.

pPathAssign plans one containment loop around one polygon, but a forecast may have several parts.
The documented choice: the outline that encloses every part holding at least ``MIN_PART_FRACTION``
of the footprint's area — the exterior ring of that part when there is one, otherwise the convex
hull of those parts — so the fleet encircles all the oil that matters, and slivers do not stretch the
loop.
"""
from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

from .features import polygon_parts, to_lonlat, to_plane

MIN_PART_FRACTION = 0.05


def outline(geometry: BaseGeometry) -> list[tuple[float, float]]:
    """The enclosing ring (open: no repeated first point) of an EPSG:4326 footprint, in lon/lat."""
    parts = polygon_parts(to_plane(geometry))
    if not parts:
        raise ValueError("geometry holds no polygon")
    total = sum(p.area for p in parts)
    kept = [p for p in parts if p.area >= MIN_PART_FRACTION * total]
    ring = kept[0] if len(kept) == 1 else shapely.union_all(kept).convex_hull
    return [tuple(map(float, xy)) for xy in np.asarray(to_lonlat(ring).exterior.coords)[:-1]]
