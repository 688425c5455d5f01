"""The physics prior: the observed footprint as particles, moved by current + windage x wind, spread by
horizontal diffusion, and rebuilt into a footprint. numpy only; a forecast takes milliseconds.

Everything here works on a plane in metres (the forecaster puts the latest observation's centroid at
the origin, ``features.spill_plane``). The forcing is uniform in space and piecewise constant in time
(``ForcingTrack``), so the motion has closed forms and needs no time stepping:

- drift velocity ``v = current + windage * R(-deflection) wind`` (deflection to the right of the wind,
  as in the northern hemisphere); the displacement to a horizon is the exact integral of ``v``;
- diffusion with constant diffusivity K is a Brownian walk: each particle's offset at time t is
  Gaussian with variance ``2 K t`` per axis, drawn as cumulative increments so trajectories hold
  together across horizons.

**The footprint method** (one for every kind that moves particles): the particles' 2-D histogram on a
grid of ``cell = sqrt(A0) / CELLS_PER_SIDE`` (A0 the observed area), Gaussian-smoothed by one cell,
and the highest-density region holding the mass fraction q of that density. q is set per forecast so
that the method reproduces the observed area from the undisturbed particles (t = 0); the same q is then
used at every horizon, so the footprint grows as diffusion spreads the particles and every part of a
multi-part slick is carried as its own part. (The kinds corrected from the observed history move the
particles without the walk and take the observed area trend instead: ``engine``.)

Uniform forcing moves every particle alike, so an ensemble member whose forcing differs is the central
footprint shifted by its difference in displacement: the probability of oil per cell is the central
footprint's mask convolved with the members' offsets (``probability``), exactly and in one FFT.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import contourpy
import numpy as np
import shapely
from scipy.ndimage import gaussian_filter
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.base import BaseGeometry

# ASCE Task Committee (1996) and OpenOil's default wind_drift_factor: 3 % of the 10 m wind.
WINDAGE = 0.03
# OpenOil applies none; observations give 0-25 degrees to the right of the wind.
DEFLECTION_DEG = 0.0
# Horizontal diffusivity of the upper ocean at spill scales (1-100 m^2/s; OpenDrift's default is 0).
DIFFUSIVITY = 10.0
CELLS_PER_SIDE = 24
MAX_CELLS = 200
MIN_PART_FRACTION = 0.01      # footprint parts under 1 % of the total area are dropped


@dataclass(frozen=True)
class DriftParameters:
    """The prior's parameters: published defaults, or fitted (``train.fit_drift``)."""

    windage: float = WINDAGE
    deflection_deg: float = DEFLECTION_DEG
    diffusivity: float = DIFFUSIVITY
    particles: int = 1500
    seed: int = 0

    def to_dict(self) -> dict:
        return {"windage": self.windage, "deflection_deg": self.deflection_deg, "diffusivity": self.diffusivity,
                "particles": self.particles, "seed": self.seed}

    @classmethod
    def from_dict(cls, data: dict) -> "DriftParameters":
        return cls(**{k: data[k] for k in ("windage", "deflection_deg", "diffusivity", "particles", "seed") if k in data})


@dataclass(frozen=True)
class ForcingTrack:
    """Wind and current (u, v m/s towards east/north) from ``times_s`` on, each value held until the next.

    Before the first time the first value holds; after the last, the last (no forecast: hold)."""

    times_s: np.ndarray      # [T] increasing, seconds (any epoch)
    values: np.ndarray       # [T, 4] wind_u, wind_v, current_u, current_v

    def __post_init__(self):
        times, values = np.asarray(self.times_s, float), np.asarray(self.values, float).reshape(-1, 4)
        if len(times) == 0 or len(times) != len(values):
            raise ValueError(f"forcing needs matching times and values ({len(times)} times, {len(values)} rows)")
        if np.any(np.diff(times) < 0) or not np.isfinite(values).all():
            raise ValueError("forcing times must increase and values be finite")
        object.__setattr__(self, "times_s", times)
        object.__setattr__(self, "values", values)

    def at(self, t_s) -> np.ndarray:
        i = np.clip(np.searchsorted(self.times_s, np.asarray(t_s, float), side="right") - 1, 0, len(self.times_s) - 1)
        return self.values[i]

    def rotated(self, angle: float) -> "ForcingTrack":
        """The same forcing turned counter-clockwise by ``angle`` radians (both vectors)."""
        c, s = math.cos(angle), math.sin(angle)
        v = self.values.copy()
        for i in (0, 2):
            v[:, i], v[:, i + 1] = c * self.values[:, i] - s * self.values[:, i + 1], s * self.values[:, i] + c * self.values[:, i + 1]
        return ForcingTrack(self.times_s, v)


def drift_velocity(values: np.ndarray, windage: float = WINDAGE, deflection_deg: float = DEFLECTION_DEG) -> np.ndarray:
    """[..., 2] surface drift of forcing rows [..., 4]: current + windage x wind turned right by deflection."""
    values = np.asarray(values, float)
    a = math.radians(deflection_deg)
    c, s = math.cos(a), math.sin(a)
    wu, wv = values[..., 0], values[..., 1]
    return np.stack([values[..., 2] + windage * (c * wu + s * wv), values[..., 3] + windage * (-s * wu + c * wv)], -1)


def displacement(track: ForcingTrack, start_s: float, end_s, windage: float = WINDAGE,
                 deflection_deg: float = DEFLECTION_DEG) -> np.ndarray:
    """[len(end_s), 2] metres drifted from ``start_s`` to each ``end_s``: the exact integral of the
    piecewise-constant drift velocity."""
    ends = np.atleast_1d(np.asarray(end_s, float))
    knots = np.unique(np.concatenate([[start_s], track.times_s[(track.times_s > start_s) & (track.times_s < ends.max())], ends]))
    velocity = drift_velocity(track.at(knots[:-1]), windage, deflection_deg)
    travelled = np.vstack([[0.0, 0.0], np.cumsum(velocity * np.diff(knots)[:, None], axis=0)])
    return travelled[np.searchsorted(knots, ends)]


# ---------------------------------------------------------------------------------------------------
# Particles and footprints

def sample_particles(geometry: BaseGeometry, count: int, rng: np.random.Generator) -> np.ndarray:
    """[count, 2] points uniform over every part of a planar (Multi)Polygon, by rejection."""
    area = geometry.area
    if not area > 0:
        raise ValueError("footprint has no area")
    x0, y0, x1, y1 = geometry.bounds
    shapely.prepare(geometry)
    chunks, have = [], 0
    ratio = area / max((x1 - x0) * (y1 - y0), 1e-12)
    while have < count:
        n = int((count - have) / max(ratio, 0.05) * 1.3) + 16
        pts = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)])
        inside = pts[shapely.contains_xy(geometry, pts[:, 0], pts[:, 1])]
        chunks.append(inside)
        have += len(inside)
    return np.vstack(chunks)[:count]


@dataclass(frozen=True)
class Grid:
    """A raster: lower-left corner, cell size and shape (nx, ny)."""

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int

    @classmethod
    def covering(cls, xy: np.ndarray, cell: float, pad_m: float) -> "Grid":
        lo, hi = xy.min(axis=0) - pad_m, xy.max(axis=0) + pad_m
        cell = max(cell, float(max(hi - lo)) / MAX_CELLS)
        n = np.maximum(np.ceil((hi - lo) / cell).astype(int), 1)
        return cls(float(lo[0]), float(lo[1]), cell, int(n[0]), int(n[1]))

    def histogram(self, xy: np.ndarray) -> np.ndarray:
        counts, _, _ = np.histogram2d(xy[:, 0], xy[:, 1], bins=[self.nx, self.ny],
                                      range=[[self.x0, self.x0 + self.nx * self.cell], [self.y0, self.y0 + self.ny * self.cell]])
        return counts

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x0 + (np.arange(self.nx) + 0.5) * self.cell, self.y0 + (np.arange(self.ny) + 0.5) * self.cell

    def contour(self, field: np.ndarray, level: float) -> MultiPolygon:
        """The region where ``field`` [nx, ny] >= ``level``, as polygons (parts under 1 % dropped)."""
        if field.max() < level:
            return MultiPolygon()
        padded = np.pad(field, 1)        # closed contours even where the field touches the edge
        cx, cy = self.centres()
        cx = np.concatenate([[cx[0] - self.cell], cx, [cx[-1] + self.cell]])
        cy = np.concatenate([[cy[0] - self.cell], cy, [cy[-1] + self.cell]])
        gen = contourpy.contour_generator(cx, cy, padded.T, fill_type=contourpy.FillType.OuterOffset)
        points, offsets = gen.filled(level, np.inf)
        polys = [shapely.make_valid(Polygon(p[o[0]:o[1]], [p[o[i]:o[i + 1]] for i in range(1, len(o) - 1)]))
                 for p, o in zip(points, offsets)]
        return clean_parts(shapely.union_all(polys) if polys else MultiPolygon(), self.cell / 4)

    def rasterise(self, geometry: BaseGeometry) -> np.ndarray:
        """[nx, ny] 1 where a cell centre lies inside ``geometry``."""
        cx, cy = self.centres()
        gx, gy = np.meshgrid(cx, cy, indexing="ij")
        return shapely.contains_xy(geometry, gx.ravel(), gy.ravel()).reshape(self.nx, self.ny).astype(float)


def clean_parts(geometry: BaseGeometry, simplify_m: float = 0.0) -> MultiPolygon:
    """The polygon parts of ``geometry`` holding at least 1 % of its area, as a MultiPolygon."""
    parts = [p for p in shapely.get_parts(geometry) if isinstance(p, Polygon) and not p.is_empty]
    parts += [q for p in shapely.get_parts(geometry) if isinstance(p, MultiPolygon) for q in p.geoms]
    total = sum(p.area for p in parts)
    kept = [p.simplify(simplify_m) if simplify_m > 0 else p for p in parts if p.area >= MIN_PART_FRACTION * total]
    return MultiPolygon([p for p in kept if isinstance(p, Polygon) and not p.is_empty])


def hdr_level(density: np.ndarray, mass_fraction: float) -> float:
    """The density level whose superlevel set holds ``mass_fraction`` of the total."""
    ordered = np.sort(density.ravel())[::-1]
    cumulative = np.cumsum(ordered)
    k = min(int(np.searchsorted(cumulative, mass_fraction * cumulative[-1])), len(ordered) - 1)
    return float(ordered[k])


class ParticleFootprint:
    """The footprint method: HDR of the smoothed particle density at the mass fraction that reproduces
    the observed area from the undisturbed particles."""

    def __init__(self, observed: BaseGeometry, particles: np.ndarray):
        self.cell = max(math.sqrt(observed.area) / CELLS_PER_SIDE, 1.0)
        self.smooth_m = self.cell
        grid = Grid.covering(particles, self.cell, 4 * self.cell)
        density = gaussian_filter(grid.histogram(particles), self.smooth_m / grid.cell)
        ordered = np.sort(density.ravel())[::-1]
        k = int(min(max(round(observed.area / grid.cell ** 2), 1), len(ordered)))
        self.mass_fraction = float(min(ordered[:k].sum() / ordered.sum(), 0.999))

    def area(self, particles: np.ndarray) -> float:
        """Area (m^2) of the footprint of moved particles, from its mask (no polygons drawn)."""
        grid = Grid.covering(particles, self.cell, 4 * self.smooth_m)
        density = gaussian_filter(grid.histogram(particles), self.smooth_m / grid.cell)
        return float((density >= hdr_level(density, self.mass_fraction)).sum() * grid.cell ** 2)

    def draw(self, particles: np.ndarray) -> tuple[Grid, np.ndarray, MultiPolygon]:
        """(grid, 0/1 footprint mask, footprint polygons) of moved particles."""
        grid = Grid.covering(particles, self.cell, 4 * self.smooth_m)
        density = gaussian_filter(grid.histogram(particles), self.smooth_m / grid.cell)
        level = hdr_level(density, self.mass_fraction)
        return grid, (density >= level).astype(float), grid.contour(density, level)


def drift(observed: BaseGeometry, start_s: float, horizons_s, track: ForcingTrack,
          params: DriftParameters = DriftParameters(), diffuse: bool = True) -> tuple[list[np.ndarray], np.ndarray]:
    """(particles [N, 2] at ``start_s`` + each horizon (seconds), particles at the start) of ``observed``
    (planar metres): advected by the drift velocity and, with ``diffuse``, spread by diffusion (the
    corrected kinds take their spreading from the observed area trend instead, see engine)."""
    rng = np.random.default_rng(params.seed)
    start = sample_particles(observed, params.particles, rng)
    horizons = np.asarray(horizons_s, float)
    moved = displacement(track, start_s, start_s + horizons, params.windage, params.deflection_deg)
    if not diffuse:
        return [start + moved[j] for j in range(len(horizons))], start
    gaps = np.diff(np.concatenate([[0.0], horizons]))
    steps = rng.standard_normal((len(horizons), params.particles, 2)) * np.sqrt(2 * params.diffusivity * gaps)[:, None, None]
    walk = np.cumsum(steps, axis=0)
    return [start + moved[j] + walk[j] for j in range(len(horizons))], start


MAX_REACH_CELLS = 24


def probability(mask: np.ndarray, grid: Grid, offsets_m: np.ndarray) -> tuple[Grid, np.ndarray]:
    """P(oil) per cell when the footprint ``mask`` on ``grid`` is shifted by each row of ``offsets_m``
    (an ensemble of equally likely members): the mask convolved with the offsets' histogram, on the
    grid grown to hold every shifted copy. Where the offsets span more than ``MAX_REACH_CELLS`` cells
    the mask is first averaged over blocks of cells (so the cost stays bounded)."""
    k = max(1, math.ceil(float(np.abs(offsets_m).max(initial=0.0)) / grid.cell / MAX_REACH_CELLS))
    if k > 1:
        nx, ny = -(-grid.nx // k) * k, -(-grid.ny // k) * k
        padded = np.zeros((nx, ny))
        padded[:grid.nx, :grid.ny] = mask
        mask = padded.reshape(nx // k, k, ny // k, k).mean(axis=(1, 3))
        grid = replace(grid, cell=grid.cell * k, nx=nx // k, ny=ny // k)
    shift = np.round(np.asarray(offsets_m, float) / grid.cell).astype(int)
    reach = int(np.abs(shift).max(initial=0))
    kernel = np.zeros((2 * reach + 1, 2 * reach + 1))
    np.add.at(kernel, (shift[:, 0] + reach, shift[:, 1] + reach), 1.0 / len(shift))
    big = replace(grid, x0=grid.x0 - reach * grid.cell, y0=grid.y0 - reach * grid.cell, nx=grid.nx + 2 * reach,
                  ny=grid.ny + 2 * reach)
    shape = (mask.shape[0] + kernel.shape[0] - 1, mask.shape[1] + kernel.shape[1] - 1)
    full = np.fft.irfft2(np.fft.rfft2(mask, shape) * np.fft.rfft2(kernel, shape), shape)
    return big, np.clip(full, 0.0, 1.0)


