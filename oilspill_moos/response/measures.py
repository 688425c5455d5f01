"""What a responder reads off a containment run: pure functions of the true spill, the patrol
plan and the vessels' tracks (mission metres, mission seconds), no MOOS.

* `perimeter_coverage`: the share of the true spill's perimeter within `reach` metres of a
  patrolling vessel, now;
* `manned_at`: when each vessel first got within `reach` of its own patrol after a push (the
  arc is manned from then on), so `max(...) - push` is the time until every arc is manned;
* `largest_revisit_gap`: the longest any point of the patrolled perimeter went without a vessel
  within `reach`;
* `patrol_offsets`: how far each vessel's patrol lies from the true boundary (signed: negative
  where the patrol runs over oil);
* `oil_containment`: the true oil inside the patrol loop and outside it.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.base import BaseGeometry

Track = Sequence[tuple[float, float, float]]   # (time, x, y) in time order


def outer_rings(spill: BaseGeometry) -> BaseGeometry:
    """The spill's perimeter: the exterior rings of its parts (holes are inside the oil)."""
    return shapely.multilinestrings([p.exterior for p in getattr(spill, "geoms", [spill])])


def perimeter_coverage(spill: BaseGeometry, positions: Sequence[Sequence[float]], reach: float) -> float:
    """Share (0..1) of the spill's perimeter within `reach` metres of any of `positions`."""
    rings = outer_rings(spill)
    if rings.length <= 0:
        return 0.0
    if len(positions) == 0:
        return 0.0
    covered = shapely.union_all(shapely.buffer(shapely.points(np.asarray(positions, float)), reach, quad_segs=32))
    return float(rings.intersection(covered).length / rings.length)


def positions_at(tracks: Mapping[str, Track], when: float, stale: float = 30.0) -> dict[str, tuple[float, float]]:
    """Each vehicle's position at time `when`, linearly between its reports; a vehicle with no
    report within `stale` seconds of `when` is left out."""
    found = {}
    for name, track in tracks.items():
        t = np.fromiter((p[0] for p in track), float, len(track))
        if len(t) == 0 or when < t[0] - stale or when > t[-1] + stale:
            continue
        xy = np.asarray([p[1:] for p in track], float)
        found[name] = (float(np.interp(when, t, xy[:, 0])), float(np.interp(when, t, xy[:, 1])))
    return found


def manned_at(tracks: Mapping[str, Track], patrols: Mapping[str, Sequence[Sequence[float]]], after: float,
              reach: float) -> dict[str, float | None]:
    """Per vehicle, the first report at or after `after` within `reach` metres of its patrol
    (a polyline of waypoints); None if it never got there."""
    found: dict[str, float | None] = {}
    for name, patrol in patrols.items():
        line = shapely.LineString(patrol) if len(patrol) > 1 else shapely.Point(patrol[0])
        track = [p for p in tracks.get(name, ()) if p[0] >= after]
        if not track:
            found[name] = None
            continue
        near = shapely.dwithin(line, shapely.points(np.asarray([p[1:] for p in track], float)), reach)
        hits = np.flatnonzero(near)
        found[name] = float(track[hits[0]][0]) if len(hits) else None
    return found


def largest_revisit_gap(loop: Sequence[Sequence[float]], tracks: Mapping[str, Track], start: float, end: float,
                        reach: float, spacing: float = 100.0, step: float = 10.0) -> tuple[float, tuple[float, float]]:
    """The longest time (s) in [start, end] that a point of the closed `loop` went without any
    vessel within `reach` metres, and that point.  The loop is sampled every `spacing` metres and
    the tracks every `step` seconds; the wait before a point's first visit counts as a gap."""
    ring = shapely.LinearRing(loop)
    samples = shapely.get_coordinates(shapely.line_interpolate_point(
        ring, np.arange(0.0, ring.length, min(spacing, ring.length / 3))))
    times = np.arange(start, end + step / 2, step)
    visited = np.zeros((len(times), len(samples)), dtype=bool)
    for track in tracks.values():
        t = np.fromiter((p[0] for p in track), float, len(track))
        if len(t) == 0:
            continue
        xy = np.asarray([p[1:] for p in track], float)
        live = (times >= t[0]) & (times <= t[-1])
        where = np.column_stack([np.interp(times, t, xy[:, 0]), np.interp(times, t, xy[:, 1])])
        gaps = np.hypot(*(where[:, np.newaxis, :] - samples[np.newaxis, :, :]).transpose(2, 0, 1))
        visited |= live[:, np.newaxis] & (gaps <= reach)
    worst, point = 0.0, (float(samples[0, 0]), float(samples[0, 1]))
    for j in range(len(samples)):
        stamps = np.concatenate([[start], times[visited[:, j]], [end]])
        gap = float(np.max(np.diff(stamps)))
        if gap > worst:
            worst, point = gap, (float(samples[j, 0]), float(samples[j, 1]))
    return worst, point


@dataclass(frozen=True)
class Offset:
    """How a patrol lies against the true boundary: median and extremes of the signed distance
    (m; negative over oil) of its points from the spill's perimeter."""

    median_m: float
    nearest_m: float
    farthest_m: float
    over_oil: float     # share of the patrol's points over oil


def patrol_offsets(spill: BaseGeometry, patrols: Mapping[str, Sequence[Sequence[float]]],
                   spacing: float = 100.0) -> dict[str, Offset]:
    """Per vehicle, the signed distance of its patrol (sampled every `spacing` metres) from the
    true spill's perimeter."""
    rings = outer_rings(spill)
    shapely.prepare(spill)
    found = {}
    for name, patrol in patrols.items():
        line = shapely.LineString(patrol) if len(patrol) > 1 else shapely.LineString([patrol[0], patrol[0]])
        points = shapely.line_interpolate_point(line, np.append(np.arange(0.0, line.length, spacing), line.length))
        inside = shapely.contains(spill, points) | shapely.touches(spill, points)
        signed = np.where(inside, -1.0, 1.0) * shapely.distance(rings, points)
        found[name] = Offset(float(np.median(signed)), float(signed.min()), float(signed.max()), float(inside.mean()))
    return found


@dataclass(frozen=True)
class Containment:
    inside_m2: float
    outside_m2: float

    @property
    def share_inside(self) -> float:
        total = self.inside_m2 + self.outside_m2
        return self.inside_m2 / total if total > 0 else 0.0


def oil_containment(spill: BaseGeometry, loop: Sequence[Sequence[float]]) -> Containment:
    """The true oil's area inside the closed patrol loop and outside it."""
    region = shapely.Polygon(loop)
    if not region.is_valid:
        region = shapely.make_valid(region)
    inside = spill.intersection(region).area
    return Containment(float(inside), float(spill.area - inside))
