"""Perimeter planning for oil-spill containment: pure geometry, no MOOS.

A predicted spill polygon becomes a stand-off region around it, and the fleet
shares that region's perimeter in one of two ways: each vessel patrols its own
arc of it, back and forth (`plan_arcs`, for perimeters tens of kilometres long),
or each runs the whole loop from its own evenly spaced point, so the spacing
stays even for as long as everyone keeps the same speed (`plan_containment`).
Where the first arc or point goes (the rotation) and who goes where (the
assignment) are chosen to minimise the *longest* transit, because the perimeter
is manned only once the last vehicle is on it.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from scipy.optimize import linear_sum_assignment, minimize_scalar
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import maximum_bipartite_matching
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.polygon import orient

Point = tuple[float, float]


class PlanError(ValueError):
    """A boundary or fleet the planner cannot work with; str() is the reason sent back to the forecaster."""


def containment_region(boundary, standoff: float, simplify: float = 0.5) -> Polygon:
    """The polygon the fleet circles: the spill grown outward by `standoff` metres.

    Holes are dropped (the fleet contains the outside edge); self-intersecting
    input is repaired with `make_valid`; separate patches that stay apart after
    buffering are wrapped in their convex hull, since one loop must enclose all
    of them.  The result is counter-clockwise, so every loop runs the same way.
    """
    if not np.isfinite(standoff) or standoff < 0:
        raise PlanError(f"stand-off distance {standoff!r} must be a finite number >= 0")
    parts = _polygon_parts(boundary)
    # GEOS buffers a polygon by a vanishing distance (1e-163, found by hypothesis) to an empty one:
    # below a micrometre there is nothing to grow.
    distance = standoff if standoff >= 1e-6 else 0.0
    grown = shapely.union_all([shapely.buffer(Polygon(p.exterior), distance, quad_segs=4) for p in parts])
    if isinstance(grown, MultiPolygon):
        grown = grown.convex_hull
    region = Polygon(grown.exterior)
    if simplify > 0:
        region = region.simplify(simplify, preserve_topology=True)
    if region.is_empty or region.area <= 0:
        raise PlanError("boundary encloses no area")
    return orient(region, sign=1.0)


def _polygon_parts(boundary) -> list[Polygon]:
    """Valid, non-empty polygons from a vertex list or any shapely geometry."""
    if isinstance(boundary, shapely.Geometry):
        geometry = boundary
    else:
        try:
            vertices = np.asarray(boundary, dtype=float)
        except (TypeError, ValueError) as exc:
            raise PlanError(f"polygon vertices are not numbers: {exc}") from None
        if vertices.ndim != 2 or vertices.shape[1] != 2:
            raise PlanError("polygon must be a list of [x, y] pairs")
        if not np.all(np.isfinite(vertices)):
            raise PlanError("polygon has a non-finite coordinate")
        if len(np.unique(vertices, axis=0)) < 3:
            raise PlanError(f"polygon needs at least 3 distinct points, got {len(np.unique(vertices, axis=0))}")
        geometry = Polygon(vertices)
    if geometry.is_empty:
        raise PlanError("polygon is empty")
    if not geometry.is_valid:
        geometry = shapely.make_valid(geometry)
    parts = [g for g in shapely.get_parts(geometry) if isinstance(g, Polygon) and g.area > 0]
    parts += [p for g in shapely.get_parts(geometry) if isinstance(g, MultiPolygon) for p in g.geoms]
    if not parts:
        raise PlanError("polygon encloses no area (degenerate or collinear points)")
    return parts


def perimeter_points(region: Polygon, arcs: np.ndarray) -> np.ndarray:
    """Points at the given arc distances along the region's exterior (any array shape + (2,))."""
    arcs = np.asarray(arcs, dtype=float)
    ring = np.asarray(region.exterior.coords)
    along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ring, axis=0).T))])
    at = arcs.ravel() % along[-1]   # linear along each edge, as shapely.line_interpolate_point, without its per-point cost
    return np.column_stack([np.interp(at, along, ring[:, 0]), np.interp(at, along, ring[:, 1])]).reshape(arcs.shape + (2,))


def evenly_spaced_arcs(perimeter: float, n: int, offset: float = 0.0) -> np.ndarray:
    """Arc distances of n points spaced perimeter/n apart, the first at `offset`."""
    return (offset + perimeter * np.arange(n) / n) % perimeter


def bottleneck_assignment(cost: np.ndarray) -> tuple[np.ndarray, float]:
    """Column for each row of a square cost matrix, minimising the largest cost.

    Threshold search: the smallest cost value t for which the edges with cost <= t
    still hold a perfect matching is the optimal bottleneck; among the matchings
    under t, linear assignment then picks the one with the smallest total.
    """
    cost = np.asarray(cost, dtype=float)
    if cost.ndim != 2 or cost.shape[0] != cost.shape[1]:
        raise PlanError(f"cost matrix must be square, got shape {cost.shape}")
    values = np.unique(cost)
    lo, hi = 0, len(values) - 1
    while lo < hi:
        mid = (lo + hi) // 2
        if _has_perfect_matching(cost <= values[mid]):
            hi = mid
        else:
            lo = mid + 1
    threshold = values[lo]
    _, columns = linear_sum_assignment(np.where(cost <= threshold, cost, np.inf))
    return columns, float(threshold)


def _has_perfect_matching(allowed: np.ndarray) -> bool:
    matching = maximum_bipartite_matching(csr_matrix(allowed.astype(np.int8)), perm_type="column")
    return bool(np.all(matching >= 0))


def greedy_assignment(cost: np.ndarray) -> np.ndarray:
    """Each row in turn takes its cheapest free column: the baseline the optimal plan is measured against."""
    cost = np.asarray(cost, dtype=float)
    free = np.ones(cost.shape[1], dtype=bool)
    columns = np.empty(cost.shape[0], dtype=int)
    for row in range(cost.shape[0]):
        columns[row] = int(np.argmin(np.where(free, cost[row], np.inf)))
        free[columns[row]] = False
    return columns


def ring_path(region: Polygon, from_arc: float, to_arc: float) -> np.ndarray:
    """Waypoints along the region's exterior, in its direction, from arc distance `from_arc` to
    `to_arc` (to_arc >= from_arc, at most one perimeter further): both ends and the ring's vertices
    between them."""
    ring = np.asarray(region.exterior.coords)[:-1]
    perimeter = region.exterior.length
    vertex_arcs = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ring, axis=0).T))])
    tolerance = 1e-9 * max(perimeter, 1.0)
    start = from_arc % perimeter
    end = start + min(max(to_arc - from_arc, 0.0), perimeter)
    laps = np.concatenate([vertex_arcs, vertex_arcs + perimeter])
    between = np.flatnonzero((laps > start + tolerance) & (laps < end - tolerance))
    ends = perimeter_points(region, np.array([start, end]))
    return np.concatenate([ends[:1], ring[between % len(ring)], ends[1:]])


def containment_loop(region: Polygon, start_arc: float) -> np.ndarray:
    """The whole perimeter as waypoints from arc distance `start_arc`, in the region's direction.

    The closing edge back to the first point is implied (BHV_Waypoint with
    repeat=forever goes from the last point to the first).
    """
    return ring_path(region, start_arc, start_arc + region.exterior.length)[:-1]


def arc_patrol(region: Polygon, arc_start: float, arc_length: float, entry: float) -> np.ndarray:
    """Back and forth along the arc [arc_start, arc_start + arc_length], from the point `entry` where
    the vessel joins it: forward to the far end, back to the near end, forward to the entry again
    (implied by repeat=forever).  A cycle is twice the arc; every point of it is revisited at most
    one cycle apart, its ends once per cycle and its middle twice."""
    entry = arc_start + (entry - arc_start) % region.exterior.length
    entry = min(entry, arc_start + arc_length)
    end = arc_start + arc_length
    parts = [ring_path(region, entry, end), ring_path(region, arc_start, end)[::-1][1:],
             ring_path(region, arc_start, entry)[1:-1]]
    path = np.concatenate(parts)
    keep = np.concatenate([[True], np.hypot(*np.diff(path, axis=0).T) > 1e-6])  # no zero-length legs
    return path[keep]


@dataclass(frozen=True)
class Plan:
    """Who starts where, and the patrol each one runs.  Costs are metres, or seconds when speeds were given.

    With `arcs` (vehicle -> (arc start, arc length), arc distances along the region's exterior)
    each vessel patrols its own arc back and forth from its start; without, each runs the whole
    loop from its start.
    """

    region: Polygon
    offset: float
    starts: dict[str, Point]
    start_arcs: dict[str, float]
    transit: dict[str, float]
    arcs: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def vehicles(self) -> list[str]:
        return list(self.starts)

    @property
    def bottleneck(self) -> float:
        return max(self.transit.values())

    def loop(self, vehicle: str) -> np.ndarray:
        """The waypoints `vehicle` repeats for ever: its arc back and forth, or the whole loop."""
        if vehicle in self.arcs:
            return arc_patrol(self.region, *self.arcs[vehicle], self.start_arcs[vehicle])
        return containment_loop(self.region, self.start_arcs[vehicle])


def _transit_costs(points: np.ndarray, positions: np.ndarray, speeds: np.ndarray) -> np.ndarray:
    """Vehicle x point transit cost for point arrays of shape (..., n, 2)."""
    gaps = points[..., np.newaxis, :, :] - positions[:, np.newaxis, :]
    return np.hypot(gaps[..., 0], gaps[..., 1]) / speeds[:, np.newaxis]


def _fleet(positions: Mapping[str, Sequence[float]], speeds: Mapping[str, float] | None):
    """Names, an (n, 2) array of positions and an (n,) array of speeds, checked."""
    if not positions:
        raise PlanError("no vehicles to plan for")
    names = list(positions)
    where = np.asarray([positions[name] for name in names], dtype=float)
    if where.shape != (len(names), 2) or not np.all(np.isfinite(where)):
        raise PlanError("vehicle positions must be finite x,y pairs")
    pace = np.ones(len(names)) if speeds is None else np.asarray([speeds[name] for name in names], dtype=float)
    if not np.all(pace > 0):
        raise PlanError("vehicle speeds must be > 0")
    return names, where, pace


def _best_rotation(spacing: float, rotations: int, costs) -> tuple[float, np.ndarray]:
    """The offset (about [0, spacing)) and assignment with the smallest (longest, total) transit.

    `costs(offset)` is the vehicle x target cost matrix for one rotation.  For each of
    `rotations` offsets the bottleneck assignment is exact; the best offset is then refined
    continuously with that assignment held, and kept only if re-assignment confirms it is no worse.
    """
    def solve(offset: float) -> tuple[float, float, np.ndarray]:
        cost = costs(offset)
        columns, worst = bottleneck_assignment(cost)
        return worst, float(cost[np.arange(len(cost)), columns].sum()), columns

    offsets = np.linspace(0.0, spacing, max(rotations, 1), endpoint=False)
    best_offset, (best_worst, best_total, best_columns) = min(
        ((offset, solve(offset)) for offset in offsets), key=lambda item: item[1][:2]
    )
    step = spacing / max(rotations, 1)

    def held(offset: float) -> float:
        cost = costs(offset)
        return float(cost[np.arange(len(cost)), best_columns].max())

    refined = minimize_scalar(held, bounds=(best_offset - step, best_offset + step), method="bounded",
                              options={"xatol": 1e-3 * step})
    candidate = solve(float(refined.x))
    if candidate[:2] < (best_worst, best_total):
        best_offset, best_columns = float(refined.x), candidate[2]
    return float(best_offset), best_columns   # unwrapped: the columns index the targets at this very offset


def plan_containment(
    region: Polygon,
    positions: Mapping[str, Sequence[float]],
    speeds: Mapping[str, float] | None = None,
    rotations: int = 64,
) -> Plan:
    """Spread the vehicles evenly on the region's perimeter with the shortest longest transit;
    each then runs the whole loop from its point."""
    names, where, pace = _fleet(positions, speeds)
    n = len(names)
    perimeter = region.exterior.length

    def costs(offset: float) -> np.ndarray:
        return _transit_costs(perimeter_points(region, evenly_spaced_arcs(perimeter, n, offset)), where, pace)

    offset, columns = _best_rotation(perimeter / n, rotations, costs)
    arcs = evenly_spaced_arcs(perimeter, n, offset)
    points = perimeter_points(region, arcs)
    cost = _transit_costs(points, where, pace)
    return Plan(
        region=region,
        offset=offset % (perimeter / n),
        starts={name: (float(points[col, 0]), float(points[col, 1])) for name, col in zip(names, columns)},
        start_arcs={name: float(arcs[col]) for name, col in zip(names, columns)},
        transit={name: float(cost[row, col]) for row, (name, col) in enumerate(zip(names, columns))},
    )


def plan_arcs(
    region: Polygon,
    positions: Mapping[str, Sequence[float]],
    speeds: Mapping[str, float] | None = None,
    rotations: int = 16,
    samples: int = 32,
) -> Plan:
    """Cut the perimeter into one arc per vehicle and deal them out with the shortest longest transit.

    The arcs are equally long: the fleet patrols at one speed, so equal arcs give every part of
    the perimeter the same revisit period.  A vehicle's transit is to the nearest point of its
    arc (`samples` points per arc are tried), where it joins it; the rotation of the cut and the
    assignment minimise the longest transit time (with `speeds`) as in `plan_containment`.  Fewer
    rotations than there: the entry slides along the arc, so the cut matters less, and pPathAssign
    plans every horizon of a forecast on the warped clock (16 x 32 is within a metre of 64 x 64 on
    the demo's 33 km loop, in a sixth of the time).
    """
    names, where, pace = _fleet(positions, speeds)
    n = len(names)
    perimeter = region.exterior.length
    spacing = perimeter / n
    along = np.linspace(0.0, spacing, samples)

    def entries(offset: float) -> tuple[np.ndarray, np.ndarray]:
        """Per vehicle x arc: the transit cost to the arc's nearest sample and that sample's arc distance."""
        sample_arcs = offset + spacing * np.arange(n)[:, np.newaxis] + along           # (arc, sample)
        cost = _transit_costs(perimeter_points(region, sample_arcs), where, pace)     # (arc, vehicle, sample)
        nearest = np.argmin(cost, axis=2)                                             # (arc, vehicle)
        best = np.take_along_axis(cost, nearest[..., np.newaxis], axis=2)[..., 0]
        return best.T, sample_arcs[np.arange(n)[:, np.newaxis], nearest].T

    offset, columns = _best_rotation(spacing, rotations, lambda o: entries(o)[0])
    cost, entry_arcs = entries(offset)
    rows = np.arange(n)
    entry = entry_arcs[rows, columns] % perimeter
    points = perimeter_points(region, entry)
    return Plan(
        region=region,
        offset=offset % spacing,
        starts={name: (float(points[row, 0]), float(points[row, 1])) for row, name in enumerate(names)},
        start_arcs={name: float(entry[row]) for row, name in enumerate(names)},
        transit={name: float(cost[row, columns[row]]) for row, name in enumerate(names)},
        arcs={name: (float((offset + spacing * columns[row]) % perimeter), float(spacing))
              for row, name in enumerate(names)},
    )


PLANNERS = {"arcs": plan_arcs, "loop": plan_containment}  # pPathAssign's `patrol` parameter


def reshare(plan: Plan, positions: Mapping[str, Sequence[float]], speeds: Mapping[str, float] | None = None) -> Plan:
    """Share the perimeter of `plan` again, the same way (arcs or loop), among whoever reports now
    (survivors and rejoiners), from where they are."""
    if not positions:
        raise PlanError("every vehicle has dropped out; nothing to re-share")
    return (plan_arcs if plan.arcs else plan_containment)(plan.region, positions, speeds)


@dataclass(frozen=True)
class ForecastChoice:
    horizon_h: float
    arrival_h: float
    plan: Plan


def choose_forecast(
    forecasts: Mapping[float, object],
    positions: Mapping[str, Sequence[float]],
    speeds: Mapping[str, float],
    standoff: float,
    age_h: float = 0.0,
    planner=plan_containment,
) -> ForecastChoice:
    """Aim at the forecast whose horizon best matches when the fleet can be on its perimeter.

    A 15 h forecast is wasted on a fleet that is there in 2 h, and a 3 h one is
    stale for a fleet that needs 10 h; `age_h` is how old the forecasts already
    are.  Ties go to the shorter (more certain) horizon.  `planner` is `plan_containment` or
    `plan_arcs` (how the fleet shares the perimeter).
    """
    if not forecasts:
        raise PlanError("no forecast horizons on offer")
    choices = []
    for horizon in sorted(forecasts):
        plan = planner(containment_region(forecasts[horizon], standoff), positions, speeds)
        arrival = age_h + plan.bottleneck / 3600.0
        choices.append((abs(float(horizon) - arrival), ForecastChoice(float(horizon), arrival, plan)))
    return min(choices, key=lambda item: item[0])[1]


def transit_route(region: Polygon, position: Sequence[float], goal: Sequence[float],
                  tolerance: float = 1e-3) -> list[Point]:
    """Waypoints from `position` to `goal` (a point on the region's perimeter) that stay out of the region.

    The straight line when it does not enter the region; otherwise the way along the exterior
    ring, in whichever direction is shorter, pulled taut (each waypoint is the farthest ring
    point still in plain sight), so the vehicle goes round the spill rather than across it.  A
    vehicle already inside the region leaves it by the nearest point of the ring first.
    `tolerance` (metres) is how far a line may graze the region before it counts as entering.
    """
    ring = region.exterior
    here, there = np.asarray(position, dtype=float), np.asarray(goal, dtype=float)
    inner = region.buffer(-tolerance)
    shapely.prepare(inner)  # tested against many lines below
    if inner.is_empty or not shapely.LineString([here, there]).intersects(inner):
        return [(float(there[0]), float(there[1]))]
    inside = inner.contains(shapely.Point(here))
    entry = ring.project(shapely.Point(here)) if inside else _first_entry(ring, here, there)
    origin = shapely.get_coordinates(ring.interpolate(entry))[0]
    target, length = ring.project(shapely.Point(there)), ring.length
    coords = np.asarray(ring.coords)
    vertex_arcs = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(coords, axis=0).T))[:-1]])
    routes = []
    for direction in (1.0, -1.0):
        span = ((target - entry) * direction) % length
        ahead = ((vertex_arcs - entry) * direction) % length
        order = np.argsort(ahead)
        points = np.vstack([coords[:-1][order[ahead[order] < span]], there])
        route = _pulled_taut(origin if inside else here, points, inner)
        routes.append([(float(origin[0]), float(origin[1])), *route] if inside else route)
    return min(routes, key=lambda route: _route_length(here, route))


def _first_entry(ring, here: np.ndarray, there: np.ndarray) -> float:
    """Arc distance on `ring` where the straight line from `here` to `there` first meets it."""
    hits = shapely.get_coordinates(shapely.LineString([here, there]).intersection(ring))
    return ring.project(shapely.Point(hits[np.argmin(np.hypot(*(hits - here).T))]))


def _pulled_taut(origin: np.ndarray, points: np.ndarray, inner) -> list[Point]:
    """From `origin`, jump each time to the farthest of `points` that the straight line reaches clear of `inner`."""
    route, here, index = [], origin, -1
    while index < len(points) - 1:
        candidates = points[index + 1:]
        clear = ~shapely.intersects(shapely.linestrings(
            np.stack([np.broadcast_to(here, candidates.shape), candidates], axis=1)), inner)
        step = int(np.flatnonzero(clear)[-1]) if clear.any() else 0
        index += step + 1
        here = points[index]
        route.append((float(here[0]), float(here[1])))
    return route


def _route_length(position: np.ndarray, route: list[Point]) -> float:
    path = np.vstack([position, route])
    return float(np.hypot(*np.diff(path, axis=0).T).sum())
