"""From observations to forecasts, for every kind: baselines, the physics prior, and the prior with a
learned correction. Pure numpy/shapely on a plane in metres (``features.SpillPlane``); torch is only
touched through the learned model object a caller passes in.

Kinds (``KINDS``):

- ``persistence``: the latest footprint, unchanged;
- ``constant-velocity``: moved at the centroid velocity fitted over the last ``TREND_H`` hours;
- ``constant-velocity-growth``: also grown at the fitted rate of area change;
- ``physics``: the physics prior (``physics.py``): particles moved by current + windage x wind and
  spread by diffusion, with the published default parameters;
- ``physics-corrected``: the prior with the forcing error estimated from the observed history
  (``forcing_error``): the observed centroids' motion against the forcing-predicted motion gives a
  drift correction, carried on over the horizon, blended with the observed constant velocity as far as
  a straight line explains the history better than the forcing does (``constant_velocity_weight``);
  a lobed outline's history is read from one lobe's track (``lobe_track``); its footprint is grown,
  part by part, to the observed area trend (``trend_area``, as constant-velocity-growth grows);
- ``ltc-rk4``, ``ltc-euler``, ``ltc-fused``, ``lstm``: the corrected prior moved on by a learned
  residual drift, and the ensemble widened by the learned spread of its error. The residual is scaled
  by a gain fitted on the validation split (``Settings.gain``): it is trusted less where the history
  is a straight line that constant velocity explains, and on held-out data an ungated residual made
  steady-forcing forecasts worse than the prior. The learned area ratio shapes the particle cloud,
  but the footprint is scaled to the observed area trend as physics-corrected's is: out of
  distribution (another footprint method) the learned area was biased low (docs/forecaster.md).

Every kind forecasts at any horizon: the physics moves particles to any time; the learned correction,
trained at ``features.HORIZONS_H``, is interpolated linearly in the horizon between them (from zero at
0 h) and carried on in proportion to the horizon past the last (``Correction.at``).

Uncertainty: an ensemble of ``MEMBERS`` members (``envelope`` draws the 50 % and 90 % contours). For the physics and learned kinds a member's forcing
is the given forcing with errors of the sizes ``FORCING_ERRORS`` (speed factors, direction biases);
with uniform forcing this shifts the whole footprint, so a member is the central footprint displaced
by its difference in drift, plus the learned spread for learned kinds. Baselines have no forcing, so
their members are Gaussian shifts. Every kind's offsets are scaled per horizon by a calibration factor
fitted on validation data (``calibration.json``) so that the nominal 95 % radius
(``RADIUS_95 x uncertainty_m``) holds the true centroid 95 % of the time.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from shapely import affinity
from shapely.geometry import MultiPolygon
from shapely.geometry.base import BaseGeometry

from . import features as F
from .kinds import BASELINE_KINDS, LEARNED_KINDS
from .physics import DriftParameters, ForcingTrack, Grid, ParticleFootprint, displacement, drift, drift_velocity, probability

TREND_H = 6.0                  # constant-velocity fits the observations of the last 6 h
# The forcing-error estimate (``forcing_error``): observations weigh exp(-age / DRIFT_MEMORY_H); the
# error is a weighted least-squares velocity with a Gaussian prior of DRIFT_PRIOR_MS (m/s, 1 sigma)
# around zero, against the scatter of the residual track about its fitted line (at least
# CENTROID_NOISE_M): the less the forcing-corrected track explains the observed motion, the more the
# estimate is pulled towards zero. Without forcing over the horizon the held forcing will miss the
# drift more, so the prior is wider and the observed motion trusted more. All chosen on the training
# split's centroid errors (docs/forecaster.md).
DRIFT_MEMORY_H = 1.0
CENTROID_NOISE_M = 30.0
DRIFT_PRIOR_MS = {True: 0.05, False: 0.1}          # forcing over the horizon given / held
LOBE_FRACTION = 0.9        # an outline whose largest part holds less of its area is lobed (``lobe_track``)
# The ridge (hours of lever arm) when the residual is as consistent as the centroid noise, forcing given ahead.
DRIFT_SHRINK_H = CENTROID_NOISE_M / DRIFT_PRIOR_MS[True] / 3600.0
MEMBERS = 32
RADIUS_95 = math.sqrt(-2 * math.log(0.05))     # 2.448: the 95 % radius of a circular 2-D Gaussian
# 1-sigma errors of given forcing (wind/ocean model vs truth), as in the training data generation.
FORCING_ERRORS = {"wind_speed_factor": 0.15, "wind_dir_deg": 15.0, "current_speed_factor": 0.3, "current_dir_deg": 25.0}




@dataclass
class Observations:
    """A spill's observations on its plane, times in seconds relative to the latest one."""

    plane: F.SpillPlane
    geometries: list[MultiPolygon]
    shapes: list[F.Shape]
    times_s: np.ndarray
    environments: np.ndarray          # [T, 4] wind u/v, current u/v at each observation
    track: ForcingTrack               # observation forcing, then the horizon forcing when given
    lobe_tracks: dict = field(default_factory=dict, init=False, repr=False, compare=False)  # ``lobe_track``'s, per params

    @property
    def forcing_ahead(self) -> bool:
        """Whether forcing over the horizon was given (else the latest observation's forcing is held)."""
        return len(self.track.times_s) > len(self.times_s)

    def drift_between(self, params: DriftParameters):
        """``drift_of(i0, i1)`` for ``features.window_features``: mean drift velocity between two
        observations (the forcing at i0 when i0 == i1)."""
        def drift_of(i0: int, i1: int) -> np.ndarray:
            t0, t1 = self.times_s[i0], self.times_s[i1]
            if t1 <= t0:
                return drift_velocity(self.track.at(t0), params.windage, params.deflection_deg)
            return displacement(self.track, t0, t1, params.windage, params.deflection_deg)[0] / (t1 - t0)
        return drift_of


def prepare(geometries, times, environments=None, horizon_forcing=None, plane: F.SpillPlane | None = None) -> Observations:
    """Observations in time order -> ``Observations``. ``environments``: one ``Environment`` (or
    4-5 numbers) per observation, or None for no forcing known; ``horizon_forcing``: (time, Environment)
    pairs after the latest observation (a wind and current forecast), held between and after."""
    if len(geometries) == 0:
        raise ValueError("no observations to forecast from")
    if len(geometries) != len(times):
        raise ValueError(f"{len(geometries)} geometries but {len(times)} times")
    times = [F.as_utc(t) for t in times]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise ValueError("observation times must strictly increase")
    cleaned = [F.repaired(g) for g in geometries]
    if any(g.is_empty for g in cleaned):
        raise ValueError("an observation holds no polygon")
    plane = plane or F.SpillPlane.about(cleaned[-1])
    planar = [plane.to_plane(g) for g in cleaned]
    shapes = [F.Shape.of(g) for g in planar]
    latest = times[-1]
    times_s = np.array([(t - latest).total_seconds() for t in times])
    envs = np.zeros((len(times), 4)) if environments is None else np.array([_forcing_row(e) for e in environments])
    if len(envs) != len(times):
        raise ValueError(f"{len(times)} observations but {len(envs)} forcing rows")
    track_t, track_v = list(times_s), list(envs)
    for when, env in sorted(horizon_forcing or (), key=lambda p: F.as_utc(p[0])):
        t = (F.as_utc(when) - latest).total_seconds()
        if t > track_t[-1]:
            track_t.append(t)
            track_v.append(_forcing_row(env))
    return Observations(plane, planar, shapes, times_s, envs, ForcingTrack(np.array(track_t), np.array(track_v)))


def _forcing_row(env) -> np.ndarray:
    row = env.as_array()[:4] if hasattr(env, "as_array") else np.asarray(env, float)[:4]
    if not np.isfinite(row).all():
        raise ValueError(f"forcing holds a non-finite value: {row}")
    return row


def lobed(shape: F.Shape) -> bool:
    """Whether an outline is lobed: its largest part holds under ``LOBE_FRACTION`` of its area."""
    return shape.largest_fraction < LOBE_FRACTION


def lobe_track(obs: Observations, params: DriftParameters) -> Observations:
    """``obs`` described by one lobe's track when its latest outline is lobed (largest part under
    ``LOBE_FRACTION`` of the area), else ``obs`` itself. The centroid of separate lobes is not a
    material point: a lobe fed by a continuing release, or lobes trading area as the outline is drawn,
    move it in ways no drift does, and the forcing error and constant velocity read from it are wrong
    (founding OpenOil set, multi-lobe slicks: the corrected prior 0.38 against 0.45 IoU at 15 h). The
    track follows the latest observation's largest part back through the history, each step to the
    part nearest where the forcing says it was, so near-equal lobes trading the first place do not
    make it jump."""
    if not lobed(obs.shapes[-1]):
        return obs
    if params in obs.lobe_tracks:       # a forecast reads it for its features, weight and correction
        return obs.lobe_tracks[params]
    drift_of = obs.drift_between(params)
    parts = [F.polygon_parts(g) for g in obs.geometries]
    chosen = [parts[-1][0]]
    for i in range(len(parts) - 2, -1, -1):
        before = np.asarray(chosen[-1].centroid.coords[0]) - drift_of(i, i + 1) * (obs.times_s[i + 1] - obs.times_s[i])
        chosen.append(min(parts[i], key=lambda p: np.hypot(*(np.asarray(p.centroid.coords[0]) - before))))
    obs.lobe_tracks[params] = replace(obs, shapes=[F.Shape.of(p) for p in reversed(chosen)])
    return obs.lobe_tracks[params]


def forcing_error(obs: Observations, params: DriftParameters) -> np.ndarray:
    """Drift error of the given forcing (m/s, plane axes) estimated from the observed history.

    The observed centroids minus the forcing-predicted track (``displacement`` from the first
    observation) should stand still if the forcing were right; their weighted least-squares velocity
    (weights exp(-age / DRIFT_MEMORY_H)) is what the forcing misses. It is shrunk towards zero as a
    posterior mean: ridge = (residual scatter about the fitted line, at least CENTROID_NOISE_M)^2 /
    DRIFT_PRIOR_MS^2, the prior wider when no forcing over the horizon was given. One observation, or
    no time between them, gives zero."""
    t = np.asarray(obs.times_s, float)
    if len(t) < 2:
        return np.zeros(2)
    obs = lobe_track(obs, params)
    track = displacement(obs.track, float(t[0]), t, params.windage, params.deflection_deg)
    residual = np.array([s.centroid for s in obs.shapes]) - track
    w = np.exp((t - t[-1]) / (3600.0 * DRIFT_MEMORY_H))
    tc = t - (w * t).sum() / w.sum()
    rc = residual - (w[:, None] * residual).sum(axis=0) / w.sum()
    lever = (w * tc ** 2).sum()
    moment = (w[:, None] * tc[:, None] * rc).sum(axis=0)
    scatter = rc - tc[:, None] * (moment / lever)
    variance = (w[:, None] * scatter ** 2).sum() / (2 * w.sum()) * len(t) / max(len(t) - 2, 1)
    ridge = max(variance, CENTROID_NOISE_M ** 2) / DRIFT_PRIOR_MS[obs.forcing_ahead] ** 2
    return moment / (lever + ridge)


def line_misfit(t: np.ndarray, track: np.ndarray) -> float:
    """RMS distance (m) of the points ``track`` [T, 2] at times ``t`` from their least-squares straight
    line in time."""
    design = np.column_stack([np.ones_like(t), t - t.mean()])
    coef, *_ = np.linalg.lstsq(design, track, rcond=None)
    return float(np.sqrt(((track - design @ coef) ** 2).sum(axis=1).mean()))


def constant_velocity_weight(obs: Observations, params: DriftParameters) -> float:
    """How far the corrected prior is moved towards the observed constant velocity, 0-1.

    Two explanations of the observed centroids, each a straight line in time with the same number of
    parameters: constant velocity, and the forcing-predicted track plus a constant drift error. Each is
    weighed by the inverse of its misfit's variance (misfits at least ``CENTROID_NOISE_M``). Under
    steady real forcing with erroneous given forcing the observed track is straighter than what the
    forcing explains, so the weight goes towards 1; where the forcing bends the track as observed
    (inertial current, a wind shift), towards 0; equal misfits give 0.5. Zero with fewer than three
    observations (no misfit to judge by)."""
    t = np.asarray(obs.times_s, float)
    if len(t) < 3:
        return 0.0
    obs = lobe_track(obs, params)
    centroids = np.array([s.centroid for s in obs.shapes])
    forced = displacement(obs.track, float(t[0]), t, params.windage, params.deflection_deg)
    cv, forcing = (max(line_misfit(t, y), CENTROID_NOISE_M) ** 2 for y in (centroids, centroids - forced))
    return forcing / (cv + forcing)


def window_inputs(obs: Observations, params: DriftParameters) -> tuple[np.ndarray, np.ndarray, float]:
    """(features, elapsed hours, frame angle) of ``obs`` for a learned correction: the one place training
    examples and forecasts build their inputs."""
    return F.window_features(obs.shapes, obs.times_s, obs.environments, obs.drift_between(params),
                             drift_error=forcing_error(obs, params), forcing_ahead=obs.forcing_ahead,
                             cv_weight=constant_velocity_weight(obs, params))


def history_correction(obs: Observations, params: DriftParameters, horizons_h, weight: float | None = None) -> "Correction":
    """The prior's correction from the observed history, per horizon: its drift error (``forcing_error``)
    carried on, blended with the observed constant velocity by ``weight`` (default:
    ``constant_velocity_weight``)."""
    horizons = tuple(horizons_h)
    horizons_s = 3600.0 * np.asarray(horizons, float)
    obs = lobe_track(obs, params)
    drift_m = horizons_s[:, None] * forcing_error(obs, params)[None, :]
    weight = constant_velocity_weight(obs, params) if weight is None else weight
    if weight > 0:
        velocity, _ = trend(obs)
        forced = displacement(obs.track, 0.0, horizons_s, params.windage, params.deflection_deg)
        drift_m = (1 - weight) * drift_m + weight * (horizons_s[:, None] * velocity[None, :] - forced)
    return Correction(drift_m, np.zeros((len(horizons), 2)), horizons)


# ---------------------------------------------------------------------------------------------------
# Baselines

def trend(obs: Observations, window_h: float = TREND_H) -> tuple[np.ndarray, float]:
    """(centroid velocity m/s, area rate m^2/s) by least squares over the last ``window_h`` hours
    (zero with a single observation)."""
    keep = obs.times_s >= -3600 * window_h
    if keep.sum() < 2:
        keep[-2:] = True
    t = obs.times_s[keep]
    if len(t) < 2:
        return np.zeros(2), 0.0
    c = np.array([s.centroid for s in obs.shapes])[keep]
    a = np.array([s.area for s in obs.shapes])[keep]
    tc = t - t.mean()
    denom = float((tc ** 2).sum())
    return (tc[:, None] * (c - c.mean(axis=0))).sum(axis=0) / denom, float((tc * (a - a.mean())).sum() / denom)


def trend_area(obs: Observations, horizon_s: float) -> float:
    """The latest area grown on at the ``trend`` rate for ``horizon_s``, never below a quarter of it."""
    area = obs.shapes[-1].area
    return max(area + trend(obs)[1] * horizon_s, 0.25 * area)


def baseline_geometry(kind: str, obs: Observations, horizon_s: float) -> BaseGeometry:
    last, shape = obs.geometries[-1], obs.shapes[-1]
    if kind == "persistence":
        return last
    velocity, _ = trend(obs)
    moved = affinity.translate(last, *(velocity * horizon_s))
    if kind == "constant-velocity":
        return moved
    return scaled_to(moved, trend_area(obs, horizon_s))


def scaled_to(geometry: BaseGeometry, area: float) -> BaseGeometry:
    """``geometry`` grown (or shrunk) to ``area``: every part scaled about its own centroid by the one
    factor that takes the whole to ``area``, parts that grow into each other merged. Scaled about the
    whole outline's centroid instead, two lobes would be pushed apart as they grow (founding OpenOil
    set, multi-lobe slicks: physics-corrected 0.35 -> 0.38 IoU at 15 h with per-part scaling)."""
    if geometry.is_empty or geometry.area <= 0:
        return geometry
    factor = math.sqrt(area / geometry.area)
    return F.repaired(MultiPolygon([affinity.scale(p, factor, factor, origin="centroid")
                                    for p in F.polygon_parts(geometry)]))


# ---------------------------------------------------------------------------------------------------
# Ensemble offsets

def forcing_members(count: int = MEMBERS, seed: int = 1) -> np.ndarray:
    """[count, 4] (wind speed factor, wind turn rad, current speed factor, current turn rad); member 0
    is the given forcing."""
    rng = np.random.default_rng(seed)
    e = FORCING_ERRORS
    out = np.column_stack([np.exp(rng.normal(0, e["wind_speed_factor"], count)), np.radians(rng.normal(0, e["wind_dir_deg"], count)),
                           np.exp(rng.normal(0, e["current_speed_factor"], count)), np.radians(rng.normal(0, e["current_dir_deg"], count))])
    out[0] = (1.0, 0.0, 1.0, 0.0)
    return out


def forcing_offsets(obs: Observations, horizons_s: np.ndarray, params: DriftParameters,
                    members: np.ndarray) -> np.ndarray:
    """[H, M, 2] each member's displacement minus the given forcing's, at each horizon. The drift is
    linear in the forcing, so a member's displacement is its current displacement and its wind drift,
    each scaled and turned by the member's errors (counter-clockwise by the turn)."""
    central = displacement(obs.track, 0.0, horizons_s, params.windage, params.deflection_deg)
    current = displacement(obs.track, 0.0, horizons_s, 0.0, 0.0)

    def turned(d: np.ndarray, scale: np.ndarray, angle: np.ndarray) -> np.ndarray:
        c, s = np.cos(angle)[None, :], np.sin(angle)[None, :]
        x, y = d[:, None, 0], d[:, None, 1]
        return scale[None, :, None] * np.stack([c * x - s * y, s * x + c * y], axis=-1)

    members = np.asarray(members, float)
    return (turned(central - current, members[:, 0], members[:, 1]) + turned(current, members[:, 2], members[:, 3])
            - central[:, None, :])


def gaussian_members(count: int = MEMBERS, seed: int = 2) -> np.ndarray:
    """[count, 2] standard normal draws (member 0 at zero), the same for every forecast."""
    z = np.random.default_rng(seed).standard_normal((count, 2))
    z[0] = 0.0
    return z


# ---------------------------------------------------------------------------------------------------
# One forecast

@dataclass
class PlanarForecast:
    horizon_h: float
    geometry: MultiPolygon
    contour_50: MultiPolygon
    contour_90: MultiPolygon
    uncertainty_m: float
    centroid: np.ndarray
    raw_spread_m: float = 0.0       # before calibration, for calibrating


@dataclass
class Correction:
    """What a learned model adds to the prior per horizon: residual drift (m, plane axes) and its
    1-sigma drift error (m, per plane axis)."""

    drift_m: np.ndarray          # [H, 2]
    sigma_m: np.ndarray          # [H, 2]
    horizons_h: tuple = F.HORIZONS_H

    def at(self, horizons_h) -> "Correction":
        """The correction at any ``horizons_h``: linear in the horizon between the rows it holds (and
        from zero at 0 h), in proportion to the horizon past the last row."""
        known = np.concatenate([[0.0], np.asarray(self.horizons_h, float)])
        wanted = np.asarray(horizons_h, float)
        if np.any(wanted <= 0) or not np.isfinite(wanted).all():
            raise ValueError(f"horizons must be positive hours, not {list(horizons_h)}")

        def along(values: np.ndarray) -> np.ndarray:
            table = np.concatenate([np.zeros((1, *values.shape[1:])), values])
            flat = table.reshape(len(known), -1)
            inside = np.column_stack([np.interp(wanted, known, flat[:, k]) for k in range(flat.shape[1])])
            beyond = flat[-1] * (wanted[:, None] / known[-1])
            return np.where((wanted > known[-1])[:, None], beyond, inside).reshape(len(wanted), *values.shape[1:])

        return Correction(along(self.drift_m), along(self.sigma_m), tuple(horizons_h))

    def gained(self, gain: np.ndarray) -> "Correction":
        """The drift scaled by ``gain`` [H] (the spread kept)."""
        return Correction(self.drift_m * np.asarray(gain, float)[:, None], self.sigma_m, self.horizons_h)

    def plus(self, other: "Correction") -> "Correction":
        """Both corrections at this one's horizons: drifts add, spreads add in quadrature."""
        other = other.at(self.horizons_h)
        return Correction(self.drift_m + other.drift_m, np.hypot(self.sigma_m, other.sigma_m), self.horizons_h)


def correction_from(mean: np.ndarray, sigma: np.ndarray, angle: float) -> Correction:
    """A ``Correction`` from a model's raw outputs [H, 3] (frame km, km, log area ratio) in the frame
    turned by ``angle``: the residual drift turned back onto the plane; the drift spread made
    isotropic (the rms of its two axes), so that it turns with the input too. The log area ratio is
    the networks' third training target only: a forecast's area is the observed trend
    (``trend_area``), and scaling the particles by the ratio before drawing them changed only the
    drawn shape and the lobes' spacing (IoU -0.004 to -0.009 out of distribution, 2026-12-03)."""
    turn = F.rotation(angle)
    drift_m = 1e3 * mean[:, :2] @ turn.T
    sigma_iso = 1e3 * np.sqrt((sigma[:, 0] ** 2 + sigma[:, 1] ** 2) / 2)
    return Correction(drift_m=drift_m, sigma_m=np.column_stack([sigma_iso, sigma_iso]))


def envelope(mask: np.ndarray, grid, offsets: np.ndarray, level: float) -> MultiPolygon:
    """The footprint swept over the ``level`` share of ensemble members nearest the ensemble's centre:
    the region holding the oil with that confidence (cells any of those members covers)."""
    order = np.argsort(np.linalg.norm(offsets - offsets.mean(axis=0), axis=1))
    kept = offsets[order[:max(1, math.ceil(level * len(offsets)))]]
    big, p = probability(mask, grid, kept)
    return big.contour(p, 0.5 / len(kept))


@dataclass
class Settings:
    params: DriftParameters = field(default_factory=DriftParameters)
    spread_scale: dict = field(default_factory=dict)   # kind -> [H] calibration factors at F.HORIZONS_H
    members: int = MEMBERS
    residual_gain: dict = field(default_factory=dict)  # ``gain_key`` -> [H] gain factors at F.HORIZONS_H

    @classmethod
    def from_calibration(cls, blob: dict) -> "Settings":
        """The settings a ``calibration.json`` holds (defaults for what it lacks)."""
        return cls(DriftParameters.from_dict(blob.get("drift", {})), blob.get("spread_scale", {}),
                   residual_gain=blob.get("residual_gain", {}))

    @staticmethod
    def scale_key(kind: str, forcing_ahead: bool = True) -> str:
        """``spread_scale`` key: the kind, calibrated with forcing over the horizon, or "<kind> held"
        without it (the latest forcing held: larger errors)."""
        return kind if forcing_ahead else f"{kind} held"

    def scale(self, kind: str, horizons_h, forcing_ahead: bool = True) -> np.ndarray:
        """Calibration factors at any horizons: linear between the calibrated ones, held beyond (the
        factors calibrated with forcing ahead when none were calibrated without)."""
        factors = self.spread_scale.get(self.scale_key(kind, forcing_ahead), self.spread_scale.get(kind))
        return np.ones(len(horizons_h)) if factors is None else at_horizons(factors, horizons_h)

    @staticmethod
    def gain_key(kind: str, forcing_ahead: bool = True, lobed: bool = False) -> str:
        """``residual_gain`` key: ``scale_key``, with " lobed" for the factors of lobed outlines."""
        return Settings.scale_key(kind, forcing_ahead) + (" lobed" if lobed else "")

    def gain(self, kind: str, horizons_h, forcing_ahead: bool, weight: float, lobed: bool = False) -> np.ndarray:
        """[H] share of a learned residual drift kept: clip(factor x (1 - ``weight``), 0, 1), ``weight`` the
        history's ``constant_velocity_weight`` and the factor fitted per horizon and outline class
        (``lobed`` or not) on the validation split (``train.fit_gains``); a calibration without
        lobed factors uses the others; the whole residual where none was fitted."""
        factors = self.residual_gain.get(self.gain_key(kind, forcing_ahead, lobed),
                                         self.residual_gain.get(self.gain_key(kind, forcing_ahead)))
        if factors is None:
            return np.ones(len(horizons_h))
        return np.clip(at_horizons(factors, horizons_h) * (1.0 - weight), 0.0, 1.0)


def at_horizons(factors, horizons_h) -> np.ndarray:
    """Factors fitted at ``features.HORIZONS_H``, at any horizons: linear between them, held beyond."""
    return np.interp(np.asarray(horizons_h, float), np.asarray(F.HORIZONS_H, float), np.asarray(factors, float))


def canonical(obs: Observations, params: DriftParameters) -> tuple[Observations, float, np.ndarray]:
    """(obs in the spill's own frame, its angle, its origin): origin at the latest centroid, +x along the
    forcing-predicted drift at the latest observation. Particles, grids and random draws are laid out
    in this frame, so a translated or rotated input gives the same forecast, translated and rotated."""
    origin = np.asarray(obs.shapes[-1].centroid, float)
    angle = F.frame_angle(obs.drift_between(params)(len(obs.shapes) - 1, len(obs.shapes) - 1))
    turn = F.rotation(-angle)
    degrees = -math.degrees(angle)

    def to_frame(g):
        return affinity.rotate(affinity.translate(g, -origin[0], -origin[1]), degrees, origin=(0, 0))

    shapes = [F.Shape(s.area, turn @ (s.centroid - origin), turn @ s.cov @ turn.T, s.perimeter, s.n_parts, s.largest_fraction)
              for s in obs.shapes]
    envs = obs.environments.copy()
    envs[:, :2], envs[:, 2:4] = envs[:, :2] @ turn.T, envs[:, 2:4] @ turn.T
    return (Observations(obs.plane, [to_frame(g) for g in obs.geometries], shapes, obs.times_s, envs,
                         obs.track.rotated(-angle)), angle, origin)


def forecast_plane(kind: str, obs: Observations, horizons_h, settings: Settings,
                   correction: Correction | None = None, contours: bool = True) -> list[PlanarForecast]:
    """Forecasts on ``obs.plane`` for each horizon (computed in the spill's own frame, ``canonical``).
    ``correction``: a learned model's residual (``models.Corrector``), added to the history's correction
    of the prior by ``settings.gain``; physics-corrected takes the history's correction alone."""
    if kind not in BASELINE_KINDS + LEARNED_KINDS:
        raise ValueError(f"unknown forecaster kind {kind!r}: one of {BASELINE_KINDS + LEARNED_KINDS}")
    if correction is not None and kind not in LEARNED_KINDS:
        raise ValueError(f"{kind} takes no learned correction (only {LEARNED_KINDS} do)")
    if kind == "physics-corrected" or correction is not None:
        weight = constant_velocity_weight(obs, settings.params)
        base = history_correction(obs, settings.params, horizons_h, weight)
        if correction is not None:
            gain = settings.gain(kind, horizons_h, obs.forcing_ahead, weight, lobed(obs.shapes[-1]))
            base = base.plus(correction.at(tuple(horizons_h)).gained(gain))
        correction = base
    frame, angle, origin = canonical(obs, settings.params)
    if correction is not None:
        turn = F.rotation(-angle)
        correction = Correction(correction.drift_m @ turn.T, correction.sigma_m, correction.horizons_h)

    def back(g):
        return affinity.translate(affinity.rotate(g, math.degrees(angle), origin=(0, 0)), origin[0], origin[1])

    return [PlanarForecast(f.horizon_h, back(f.geometry), back(f.contour_50), back(f.contour_90), f.uncertainty_m,
                           F.rotation(angle) @ f.centroid + origin, f.raw_spread_m)
            for f in _forecast_frame(kind, frame, horizons_h, settings, correction, contours)]


def _forecast_frame(kind: str, obs: Observations, horizons_h, settings: Settings,
                    correction: Correction | None, contours: bool) -> list[PlanarForecast]:
    horizons_s = 3600.0 * np.asarray(horizons_h, float)
    scale = settings.scale(kind, horizons_h, obs.forcing_ahead)
    z = gaussian_members(settings.members)
    if kind in BASELINE_KINDS and not kind.startswith("physics"):
        geometries = [baseline_geometry(kind, obs, h) for h in horizons_s]
        masks = [None] * len(geometries)
        raw = np.broadcast_to(z, (len(horizons_s), *z.shape))
    else:
        # the corrected kinds spread by the observed area trend (below): a random walk on top would
        # only round the shape (founding OpenOil set, initial releases: IoU 0.55 with it, 0.62 without)
        moved, start = drift(obs.geometries[-1], 0.0, horizons_s, obs.track, settings.params, diffuse=correction is None)
        method = ParticleFootprint(obs.geometries[-1], start)
        raw = forcing_offsets(obs, horizons_s, settings.params, forcing_members(settings.members))
        if correction is not None:
            moved = [p + d for p, d in zip(moved, correction.drift_m)]
            raw = raw + z[None] * correction.sigma_m[:, None, :]
        drawn = [method.draw(p) for p in moved]
        geometries = [d[2] for d in drawn]
        masks = [(d[0], d[1]) for d in drawn]
        if correction is not None:          # spreading corrected too: scaled to the observed area trend
            geometries = [scaled_to(g, trend_area(obs, h)) for g, h in zip(geometries, horizons_s)]
            masks = [None] * len(geometries)
    out = []
    for j, h in enumerate(horizons_h):
        offsets = raw[j] * scale[j]
        spread = float(np.sqrt((raw[j] ** 2).sum(axis=1).mean() / 2))
        geometry = geometries[j]
        c50 = c90 = geometry
        if contours:
            if masks[j] is None:
                grid = Grid.covering(np.array(geometry.bounds).reshape(2, 2), math.sqrt(geometry.area) / 24, 0.0)
                mask = grid.rasterise(geometry)
            else:
                grid, mask = masks[j]
            c50, c90 = (envelope(mask, grid, offsets, level) for level in (0.5, 0.9))
        _, centroid, _ = F.second_moments(geometry)
        out.append(PlanarForecast(float(h), geometry, c50, c90, spread * scale[j], centroid, spread))
    return out

