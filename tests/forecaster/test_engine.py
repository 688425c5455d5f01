"""Forecast kinds on the plane: baselines on known tracks, and the invariance property — translate and
rotate the whole input (polygons with their forcing) and the forecast moves with it."""
import math

import numpy as np
import pytest
import shapely
import torch
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from shapely import affinity
from shapely.geometry import MultiPolygon, Point, box

from oilspill_moos.forecaster import engine as E
from oilspill_moos.forecaster import features as F
from oilspill_moos.forecaster.models import Corrector, build_model
from oilspill_moos.forecaster.physics import ForcingTrack, drift_velocity


def planar_observations(geometries, times_h, forcing, ahead=()):
    """Observations straight on the plane: geometries (metres), hours, [T, 4] forcing, and forcing rows
    for each hour after the latest observation."""
    times_s = 3600.0 * (np.asarray(times_h, float) - times_h[-1])
    rows = np.asarray(forcing, float)
    ahead = np.asarray(ahead, float).reshape(-1, 4)
    track = ForcingTrack(np.concatenate([times_s, 3600.0 * np.arange(1, len(ahead) + 1)]), np.vstack([rows, ahead]))
    geoms = [MultiPolygon(F.polygon_parts(g)) for g in geometries]
    return E.Observations(None, geoms, [F.Shape.of(g) for g in geoms], times_s, rows, track)


def iou(a, b):
    return shapely.intersection(a, b).area / shapely.union(a, b).area


def test_persistence_and_constant_velocity_on_a_linear_track():
    slick = Point(0, 0).buffer(2_000, quad_segs=32)
    geoms = [affinity.scale(affinity.translate(slick, 400.0 * h, -300.0 * h), 1 + 0.05 * h, 1 + 0.05 * h) for h in range(5)]
    obs = planar_observations(geoms, np.arange(5.0), np.zeros((5, 4)))
    last = F.Shape.of(geoms[-1])
    assert E.baseline_geometry("persistence", obs, 3 * 3600.0).equals(obs.geometries[-1])
    moved = F.Shape.of(E.baseline_geometry("constant-velocity", obs, 10 * 3600.0))
    assert np.allclose(moved.centroid - last.centroid, [4_000.0, -3_000.0], atol=1.0)
    assert moved.area == pytest.approx(last.area)
    grown = F.Shape.of(E.baseline_geometry("constant-velocity-growth", obs, 10 * 3600.0))
    velocity, rate = E.trend(obs)
    assert grown.area == pytest.approx(last.area + rate * 36_000.0, rel=1e-6) and rate > 0
    assert np.allclose(grown.centroid, moved.centroid, atol=1.0)


def random_corrector(seed: int = 0) -> Corrector:
    """A real (untrained, randomly initialised) LTC with unit scalers: its outputs are arbitrary, so the
    invariance cannot come from the model saying nothing."""
    torch.manual_seed(seed)
    model = build_model("ltc-fused", n_features=len(F.FEATURE_NAMES))
    scaler = F.FeatureScaler(np.zeros(len(F.FEATURE_NAMES)), np.ones(len(F.FEATURE_NAMES)))
    extra = {"feature_scaler": scaler.to_dict(), "horizons_h": list(F.HORIZONS_H),
             "target_scaler": {"mean": np.zeros((4, 3)).tolist(), "std": np.full((4, 3), 2.0).tolist()}}
    return Corrector(model, extra)


def case(shift_x, shift_y, angle_deg):
    """A two-lobed spill drifting under wind and current, then moved by (shift) and turned by angle."""
    lobes = MultiPolygon([Point(0, 0).buffer(2_500, quad_segs=16), Point(9_000, 2_000).buffer(1_200, quad_segs=16)])
    geoms = [affinity.translate(affinity.scale(lobes, 1 + 0.03 * h, 1 + 0.02 * h, origin=(0, 0)), 700.0 * h, 250.0 * h)
             for h in range(6)]
    forcing = np.array([[6.0 + 0.2 * h, 2.0, 0.15, 0.05 * h] for h in range(6)])
    ahead = [[3.0, -4.0, 0.1, 0.2]] * 5
    a = math.radians(angle_deg)
    turn = F.rotation(a)

    def move(g):
        return affinity.translate(affinity.rotate(g, angle_deg, origin=(0, 0)), shift_x, shift_y)

    def turned(rows):
        rows = np.atleast_2d(np.asarray(rows, float)).copy()
        rows[:, :2], rows[:, 2:4] = rows[:, :2] @ turn.T, rows[:, 2:4] @ turn.T
        return rows

    original = planar_observations(geoms, np.array([0, 1, 2, 4, 5, 6.0]), forcing, ahead)
    transformed = planar_observations([move(g) for g in geoms], np.array([0, 1, 2, 4, 5, 6.0]), turned(forcing),
                                      turned(ahead))
    return original, transformed, move


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(shift_x=st.floats(-2e5, 2e5), shift_y=st.floats(-2e5, 2e5), angle=st.floats(0, 360))
def test_forecast_moves_with_a_translated_and_rotated_input(shift_x, shift_y, angle):
    original, transformed, move = case(shift_x, shift_y, angle)
    corrector = random_corrector()
    params = E.DriftParameters()
    x0, x1 = (E.window_inputs(o, params)[0] for o in (original, transformed))
    assert np.allclose(x0, x1, atol=1e-6)                       # nothing in the features says where
    assert np.abs(x0[:, F.FEATURE_INDEX["error_u"]]).max() > 1e-3   # the forcing-error estimate is among them
    for kind in ("physics", "physics-corrected", "constant-velocity-growth", "ltc-fused"):
        corrections = [corrector.correction(o, params) if kind == "ltc-fused" else None for o in (original, transformed)]
        a = E.forecast_plane(kind, original, (3, 15), E.Settings(), corrections[0], contours=False)
        b = E.forecast_plane(kind, transformed, (3, 15), E.Settings(), corrections[1], contours=False)
        for fa, fb in zip(a, b):
            expected = move(fa.geometry)
            size = math.sqrt(fa.geometry.area)
            assert iou(expected, fb.geometry) > 0.85, kind
            assert np.linalg.norm(np.asarray(expected.centroid.coords[0]) - fb.centroid) < 0.05 * size, kind
            assert fb.uncertainty_m == pytest.approx(fa.uncertainty_m, rel=0.02), kind


def drifting_history(offset, forcing_row, hours, size=2_000.0):
    """A round slick observed at ``hours`` moving exactly at the forcing's drift plus ``offset`` (m/s)."""
    params = E.DriftParameters()
    velocity = drift_velocity(np.asarray(forcing_row, float), params.windage, params.deflection_deg) + offset
    hours = np.asarray(hours, float)
    geoms = [Point(*(velocity * 3600.0 * h)).buffer(size, quad_segs=32) for h in hours]
    return planar_observations(geoms, hours, np.tile(forcing_row, (len(hours), 1)), ahead=[forcing_row] * 15)


def lobes_history(radii_a, radii_b, drift_b: bool):
    """Two lobes observed hourly under constant forcing: lobe a drifting exactly with the forcing's
    drift, lobe b 12 km to its side, drifting too (``drift_b``) or staying where it is (a continuing
    release feeding it); their radii per hour given. (obs, lobe a's centroids, the drift velocity)."""
    forcing = [6.0, 1.0, 0.1, -0.05]
    params = E.DriftParameters()
    velocity = drift_velocity(np.asarray(forcing), params.windage, params.deflection_deg)
    side = np.array([-velocity[1], velocity[0]]) / np.linalg.norm(velocity) * 12_000.0
    hours = np.arange(float(len(radii_a)))
    a = [velocity * 3600.0 * h for h in hours]
    b = [side + (a[i] if drift_b else 0.0) for i in range(len(hours))]
    geoms = [MultiPolygon([Point(*pa).buffer(ra, quad_segs=32), Point(*pb).buffer(rb, quad_segs=32)])
             for pa, pb, ra, rb in zip(a, b, radii_a, radii_b)]
    return planar_observations(geoms, hours, np.tile(forcing, (len(hours), 1)), ahead=[forcing] * 15), np.array(a)


def test_a_fed_lobe_does_not_read_as_a_forcing_error():
    """Known answer: a lobe drifting exactly with the forcing beside a smaller lobe that stays put and
    grows (a continuing release). The whole outline's centroid lags the forcing (a spurious error);
    the lobe track follows the drifting lobe: no forcing error, and its centroids are that lobe's."""
    params = E.DriftParameters()
    obs, drifting = lobes_history([2_000.0] * 9, np.linspace(300.0, 1_500.0, 9), drift_b=False)
    assert obs.shapes[-1].largest_fraction < E.LOBE_FRACTION
    track = E.lobe_track(obs, params)
    assert np.allclose([s.centroid for s in track.shapes], drifting, atol=1.0)
    lag = np.array([s.centroid for s in obs.shapes]) - drifting      # where the outline's centroid reads
    assert np.linalg.norm(lag[-1] - lag[0]) > 1_000.0
    assert np.linalg.norm(E.forcing_error(obs, params)) < 1e-4


def test_lobes_trading_first_place_keep_one_track():
    """Two lobes drifting together with the forcing, trading area so that the larger one alternates:
    the whole outline's centroid swings between them (a spurious error and a jagged track), the lobe
    track stays on one lobe, so the forcing error is zero and constant velocity and forcing explain it
    equally (weight 0.5)."""
    params = E.DriftParameters()
    swing = 1_500.0 + 400.0 * np.array([1, -1, 1, -1, 1, -1, 1, -1, 1.0])
    obs, drifting = lobes_history(swing, 3_000.0 - swing, drift_b=True)
    assert obs.shapes[-1].largest_fraction < E.LOBE_FRACTION
    lag = np.array([s.centroid for s in obs.shapes]) - drifting
    assert np.linalg.norm(lag[1] - lag[0]) > 1_000.0                  # the outline's centroid swings
    track = E.lobe_track(obs, params)
    assert np.allclose([s.centroid for s in track.shapes], drifting, atol=1.0)
    assert np.linalg.norm(E.forcing_error(obs, params)) < 1e-4
    assert E.constant_velocity_weight(obs, params) == pytest.approx(0.5)
    one = drifting_history(np.zeros(2), [6.0, 1.0, 0.1, -0.05], np.arange(9.0))
    assert E.lobe_track(one, params) is one         # a single body is its own track


def test_forcing_error_recovers_a_known_drift_error():
    """Known answer: the slick moves at the forcing's drift plus (0.12, -0.05) m/s. Weighted least squares
    recovers that velocity, pulled towards zero by exactly the documented ridge factor."""
    hours = np.array([0, 1, 2, 3, 5, 6, 8, 9, 10, 12.0])
    offset = np.array([0.12, -0.05])
    obs = drifting_history(offset, [7.0, -2.0, 0.2, 0.1], hours)
    t = 3600.0 * (hours - hours[-1])
    w = np.exp(t / (3600.0 * E.DRIFT_MEMORY_H))
    spread = (w * (t - (w * t).sum() / w.sum()) ** 2).sum()
    shrink = spread / (spread + (3600.0 * E.DRIFT_SHRINK_H) ** 2)
    error = E.forcing_error(obs, E.DriftParameters())
    assert np.allclose(error, shrink * offset, atol=1e-4) and 0.5 < shrink < 1
    # exact forcing: nothing to correct; one observation: nothing known
    assert np.allclose(E.forcing_error(drifting_history(np.zeros(2), [7.0, -2.0, 0.2, 0.1], hours), E.DriftParameters()),
                       0.0, atol=1e-5)
    assert np.allclose(E.forcing_error(drifting_history(offset, [7.0, -2.0, 0.2, 0.1], [0.0]), E.DriftParameters()), 0.0)
    # and the corrected prior carries it on over any horizon; this straight track under constant forcing
    # is explained equally well by constant velocity, so it is blended half and half with that (within
    # 100 m: the physics kind's particles take a random walk, the corrected kind's do not)
    weight = E.constant_velocity_weight(obs, E.DriftParameters())
    assert weight == pytest.approx(0.5)
    for horizon in (2.5, 9.0, 20.0):
        physics, corrected = (E.forecast_plane(k, obs, (horizon,), E.Settings(), contours=False)[0]
                              for k in ("physics", "physics-corrected"))
        assert np.allclose(corrected.centroid - physics.centroid, 3600.0 * horizon * ((1 - weight) * error + weight * offset),
                           atol=100.0)


def test_adaptive_forcing_error_trusts_a_consistent_miss_and_doubts_an_erratic_one():
    """Known answer: uniform flow the forcing misses by (0.12, -0.05) m/s. With forcing over the horizon
    the estimate is the documented posterior mean (residual as consistent as the centroid noise); held,
    the prior is wider and it recovers the bias more closely. A residual that zigzags about its trend
    (forcing that explains the motion only on average) is pulled further towards zero; a track the
    forcing explains gives zero in both modes."""
    hours = np.array([0, 1, 2, 3, 5, 6, 8, 9, 10, 12.0])
    offset = np.array([0.12, -0.05])
    ahead = drifting_history(offset, [7.0, -2.0, 0.2, 0.1], hours)
    held = E.Observations(ahead.plane, ahead.geometries, ahead.shapes, ahead.times_s, ahead.environments,
                          ForcingTrack(ahead.track.times_s[:len(hours)], ahead.track.values[:len(hours)]))
    assert ahead.forcing_ahead and not held.forcing_ahead
    params = E.DriftParameters()
    t = 3600.0 * (hours - hours[-1])
    w = np.exp(t / (3600.0 * E.DRIFT_MEMORY_H))
    lever = (w * (t - (w * t).sum() / w.sum()) ** 2).sum()
    for obs, prior in ((ahead, E.DRIFT_PRIOR_MS[True]), (held, E.DRIFT_PRIOR_MS[False])):
        shrink = lever / (lever + (E.CENTROID_NOISE_M / prior) ** 2)
        assert np.allclose(E.forcing_error(obs, params), shrink * offset, atol=1e-4)
    assert np.linalg.norm(E.forcing_error(held, params) - offset) < np.linalg.norm(E.forcing_error(ahead, params) - offset) < 0.05
    assert np.linalg.norm(E.forcing_error(held, params) - offset) < 0.01
    # the same mean miss, but each observation 600 m off the line in turn: less trust
    zigzag = [affinity.translate(g, 600.0 * (-1) ** k, 0.0) for k, g in enumerate(ahead.geometries)]
    erratic = planar_observations(zigzag, hours, ahead.environments, ahead=[[7.0, -2.0, 0.2, 0.1]] * 15)
    assert np.linalg.norm(E.forcing_error(erratic, params)) < 0.5 * np.linalg.norm(E.forcing_error(ahead, params))
    exact = drifting_history(np.zeros(2), [7.0, -2.0, 0.2, 0.1], hours)
    exact_held = E.Observations(exact.plane, exact.geometries, exact.shapes, exact.times_s, exact.environments,
                                ForcingTrack(exact.track.times_s[:len(hours)], exact.track.values[:len(hours)]))
    for obs in (exact, exact_held):
        assert np.allclose(E.forcing_error(obs, params), 0.0, atol=1e-5)


def test_constant_velocity_weight_follows_the_straighter_explanation():
    """Known answers: a slick moving in a straight line while the given wind swings from side to side
    (steady real forcing, noisy forecast forcing) is explained by constant velocity, weight near 1, and
    the corrected prior then moves at the observed velocity; a slick carried round by a rotating current
    exactly as the forcing says is explained by the forcing, weight near 0; two observations give 0."""
    params = E.DriftParameters()
    hours = np.arange(0.0, 12.0)
    velocity = np.array([0.3, -0.1])
    geoms = [Point(*(velocity * 3600.0 * h)).buffer(1_500.0, quad_segs=16) for h in hours]
    swinging = np.array([[5.0, 6.0 * (-1) ** k, 0.1, 0.0] for k in range(len(hours))])
    straight = planar_observations(geoms, hours, swinging)
    assert E.constant_velocity_weight(straight, params) > 0.9
    corrected = E.forecast_plane("physics-corrected", straight, (6.0,), E.Settings(), contours=False)[0]
    expected = F.Shape.of(straight.geometries[-1]).centroid + 6 * 3600.0 * velocity
    assert np.linalg.norm(corrected.centroid - expected) < 0.1 * np.linalg.norm(6 * 3600.0 * velocity)
    turning = np.array([[0.0, 0.0, 0.3 * math.cos(0.4 * h), 0.3 * math.sin(0.4 * h)] for h in hours])
    track = ForcingTrack(3600.0 * hours, turning)
    from oilspill_moos.forecaster.physics import displacement
    loop = displacement(track, 0.0, 3600.0 * hours, params.windage, params.deflection_deg)
    bent = planar_observations([Point(*xy).buffer(1_500.0, quad_segs=16) for xy in loop], hours, turning)
    assert E.constant_velocity_weight(bent, params) < 0.1
    two = planar_observations(geoms[:2], hours[:2], swinging[:2])
    assert E.constant_velocity_weight(two, params) == 0.0


def test_physics_corrected_spreads_at_the_observed_area_trend():
    """Known answer: a round slick drifting exactly with the forcing, its area growing by 4 km^2 an hour.
    physics-corrected keeps the prior's drift and grows to the trend's area at every horizon."""
    forcing = [6.0, 1.0, 0.1, -0.05]
    params = E.DriftParameters()
    velocity = drift_velocity(np.asarray(forcing), params.windage, params.deflection_deg)
    hours = np.arange(8.0)
    geoms = [Point(*(velocity * 3600.0 * h)).buffer(math.sqrt((20e6 + 4e6 * h) / math.pi), quad_segs=64) for h in hours]
    obs = planar_observations(geoms, hours, np.tile(forcing, (len(hours), 1)), ahead=[forcing] * 15)
    for horizon in (3.0, 15.0):
        physics, corrected = (E.forecast_plane(k, obs, (horizon,), E.Settings(), contours=False)[0]
                              for k in ("physics", "physics-corrected"))
        assert corrected.geometry.area == pytest.approx(E.trend_area(obs, 3600.0 * horizon), rel=0.08)
        assert E.trend_area(obs, 3600.0 * horizon) == pytest.approx(48e6 + 4e6 * horizon, rel=1e-3)
        assert np.linalg.norm(corrected.centroid - physics.centroid) < 100.0


@settings(max_examples=40, deadline=None)
@given(st.floats(0.3, 4.0), st.floats(500.0, 9_000.0), st.floats(0.2, 0.9))
def test_growing_two_lobes_keeps_each_lobe_in_place(factor, gap_m, second_share):
    """Two lobes grown or shrunk to a target area: each part is scaled about its own centroid, so the
    lobes keep their centroids (not pushed apart as the whole outline grows) and the area is the
    target's while they stay apart."""
    big = Point(0, 0).buffer(1_000.0, quad_segs=64)
    small = Point(4_000.0 + gap_m, 0).buffer(1_000.0 * math.sqrt(second_share), quad_segs=64)   # apart even at 4x
    lobes = MultiPolygon([big, small])
    grown = E.scaled_to(lobes, factor * lobes.area)
    assert grown.area == pytest.approx(factor * lobes.area, rel=1e-6)
    parts = F.polygon_parts(grown)
    assert len(parts) == 2
    for before, after in zip(F.polygon_parts(lobes), parts):
        assert after.centroid.distance(before.centroid) < 1e-6 * gap_m
        assert after.area == pytest.approx(factor * before.area, rel=1e-6)


def test_learned_correction_at_any_horizon():
    """Rows at the trained horizons are kept; between them the correction is linear in the horizon (from
    zero at 0 h), past the last one in proportion to the horizon."""
    drift = np.array([[300.0, -30.0], [700.0, -70.0], [1_100.0, -110.0], [1_500.0, -150.0]])
    c = E.Correction(drift, np.array([[50.0, 50.0], [90, 90], [120, 120], [150, 150]]))
    at = c.at((3, 5, 1.5, 15, 30))
    assert np.allclose(at.drift_m, [[300, -30], [500, -50], [150, -15], [1_500, -150], [3_000, -300]])
    assert np.allclose(at.sigma_m[:, 0], [50, 70, 25, 150, 300])
    with pytest.raises(ValueError, match="positive"):
        c.at((0, 3))
    obs = drifting_history(np.array([0.05, 0.02]), [7.0, -2.0, 0.2, 0.1], np.arange(8.0))
    corrector = random_corrector()
    out = E.forecast_plane("ltc-fused", obs, (1, 5.5, 15, 24), E.Settings(), corrector.correction(obs, E.DriftParameters()))
    assert [f.horizon_h for f in out] == [1, 5.5, 15, 24]
    assert all(f.geometry.area > 0 and f.geometry.is_valid and f.uncertainty_m > 0 for f in out)


def test_learned_growth_never_outruns_a_shrinking_slick():
    """DWH-like input: two sparse, unforced observations a day apart of a slick shrinking from 26 to
    20 km across (the learned kinds once forecast it doubling): a real random LTC's forecast has at
    most the observed trend's area, never more than the latest."""
    geoms = [Point(0, 0).buffer(radius, quad_segs=64) for radius in (13_000.0, 10_000.0)]
    obs = planar_observations(geoms, np.array([0.0, 48.0]), np.zeros((2, 4)))
    latest = obs.shapes[-1].area
    correction = random_corrector(3).correction(obs, E.DriftParameters())
    for f in E.forecast_plane("ltc-fused", obs, F.HORIZONS_H, E.Settings(), correction, contours=False):
        assert f.geometry.area <= E.trend_area(obs, 3600.0 * f.horizon_h) * (1 + 1e-6)
        assert f.geometry.area < latest


def test_learned_residual_is_added_by_its_fitted_gain():
    """Known answer: a residual of 3 km east at every horizon moves the corrected prior's forecast by the
    whole residual with no gain fitted, and by clip(factor x (1 - constant_velocity_weight), 0, 1) of
    it with one; a factor of 0 gives the corrected prior itself."""
    params = E.DriftParameters()
    hours = np.arange(0.0, 10.0)
    geoms = [Point(300.0 * 3.6 * h, 0.0).buffer(1_500.0, quad_segs=16) for h in hours]
    forcing = np.array([[5.0, 2.0 * (-1) ** k, 0.05, 0.02] for k in range(len(hours))])
    obs = planar_observations(geoms, hours, forcing)
    weight = E.constant_velocity_weight(obs, params)
    assert 0.0 < weight < 1.0
    residual = E.Correction(np.tile([3_000.0, 0.0], (4, 1)), np.full((4, 2), 50.0))
    prior = E.forecast_plane("physics-corrected", obs, (7.0,), E.Settings(), contours=False)[0]
    for gains, share in ((None, 1.0), ([1.5] * 4, min(1.5 * (1 - weight), 1.0)), ([0.0] * 4, 0.0)):
        settings = E.Settings(residual_gain={} if gains is None else {"ltc-fused held": gains})
        learned = E.forecast_plane("ltc-fused", obs, (7.0,), settings, residual, contours=False)[0]
        assert np.allclose(learned.centroid - prior.centroid, [3_000.0 * share, 0.0], atol=60.0)
        assert learned.geometry.area == pytest.approx(prior.geometry.area, rel=0.02)


def test_a_lobed_outline_takes_the_gains_fitted_for_lobed_outlines():
    """Known answer: the same 3 km residual is kept whole (factor 3) on a single outline and dropped
    (factor 0) on a lobed one when the calibration holds lobed factors; without them a lobed outline
    takes the others (calibrations written before the classes)."""
    residual = E.Correction(np.tile([3_000.0, 0.0], (4, 1)), np.full((4, 2), 50.0))
    lobed, _ = lobes_history([2_000.0] * 8, [1_500.0] * 8, drift_b=True)
    single = drifting_history(np.zeros(2), [6.0, 1.0, 0.1, -0.05], np.arange(8.0))
    assert E.lobed(lobed.shapes[-1]) and not E.lobed(single.shapes[-1])
    by_class = {"ltc-fused": [3.0] * 4, "ltc-fused lobed": [0.0] * 4}
    for obs, calibration, moved in ((single, by_class, True), (lobed, by_class, False),
                                    (lobed, {"ltc-fused": [3.0] * 4}, True)):
        share = min(3.0 * (1 - E.constant_velocity_weight(obs, E.DriftParameters())), 1.0) if moved else 0.0
        prior = E.forecast_plane("physics-corrected", obs, (7.0,), E.Settings(), contours=False)[0]
        learned = E.forecast_plane("ltc-fused", obs, (7.0,), E.Settings(residual_gain=calibration), residual,
                                   contours=False)[0]
        assert np.allclose(learned.centroid - prior.centroid, [3_000.0 * share, 0.0], atol=60.0)


def test_gains_are_fitted_per_outline_class(monkeypatch):
    """Known answer: the truth lies 2 km north of the corrected prior for single outlines and 2 km south
    for lobed ones; a residual of 2 km north is kept for the single ones and dropped for the lobed."""
    from oilspill_moos.forecaster import train
    from oilspill_moos.forecaster.physics import DriftParameters
    from oilspill_moos.forecaster.windows import Case

    monkeypatch.setattr(train, "MIN_GAIN_CASES", 2)
    params = DriftParameters()
    histories = [drifting_history(np.zeros(2), [6.0, 1.0, 0.1, 0.0], np.arange(6.0)),
                 drifting_history(np.zeros(2), [-5.0, 2.0, -0.1, 0.05], np.arange(6.0)),
                 lobes_history([2_000.0] * 6, [1_500.0] * 6, drift_b=True)[0],
                 lobes_history([2_000.0] * 6, [1_200.0] * 6, drift_b=True)[0]]
    cases = []
    for k, obs in enumerate(histories):
        prior = E.forecast_plane("physics-corrected", obs, F.HORIZONS_H, E.Settings(params), contours=False)
        truth = [affinity.translate(f.geometry, 0.0, -2_000.0 if E.lobed(obs.shapes[-1]) else 2_000.0) for f in prior]
        cases.append(Case(f"s{k}", 0.0, obs, truth, [F.Shape.of(g) for g in truth]))
    gains = train.fit_gains(cases, FixedResidual([0.0, 2_000.0]), params)
    assert gains[True] == [0.0] * 4
    assert min(gains[False]) > 0.0


def test_an_unknown_kind_and_a_correction_for_a_baseline_are_refused():
    """A misspelt kind once ran the physics prior silently."""
    obs = drifting_history(np.zeros(2), [5.0, 0.0, 0.0, 0.0], np.arange(4.0))
    with pytest.raises(ValueError, match="unknown forecaster kind 'cv'"):
        E.forecast_plane("cv", obs, (3.0,), E.Settings())
    residual = E.Correction(np.zeros((4, 2)), np.full((4, 2), 50.0))
    with pytest.raises(ValueError, match="physics takes no learned correction"):
        E.forecast_plane("physics", obs, (3.0,), E.Settings(), residual)


class FixedResidual:
    """A corrector whose residual drift is the same for every case (the ``models.Corrector`` interface)."""

    def __init__(self, drift_m):
        self.drift_m = np.asarray(drift_m, float)

    def corrections(self, observations, params):
        return [E.Correction(np.tile(self.drift_m, (4, 1)), np.full((4, 2), 100.0)) for _ in observations]


def test_fitted_gain_keeps_a_residual_that_helps_and_drops_one_that_hurts():
    """Known answer: slicks drift with the forcing, but the truth lies 2 km north of where the corrected
    prior puts it. A residual of 2 km north is kept whole at every horizon; one of 2 km
    south gets 0 (the prior alone)."""
    from oilspill_moos.forecaster.physics import DriftParameters
    from oilspill_moos.forecaster.train import fit_gains
    from oilspill_moos.forecaster.windows import Case

    params = DriftParameters()
    cases = []
    for k, row in enumerate(([6.0, 1.0, 0.1, 0.0], [3.0, -4.0, 0.0, 0.1], [-5.0, 2.0, -0.1, 0.05])):
        obs = drifting_history(np.zeros(2), row, np.arange(6.0))
        prior = E.forecast_plane("physics-corrected", obs, (3, 7, 11, 15), E.Settings(params), contours=False)
        truth = [affinity.translate(f.geometry, 0.0, 2_000.0) for f in prior]
        cases.append(Case(f"s{k}", 0.0, obs, truth, [F.Shape.of(g) for g in truth]))
    weights = [E.constant_velocity_weight(c.obs, params) for c in cases]
    helping = fit_gains(cases, FixedResidual([0.0, 2_000.0]), params)
    assert helping[True] == helping[False]      # no lobed case: both classes take the factors of all
    assert all(min(g * (1 - w), 1.0) == 1.0 for g in helping[False] for w in weights)       # the whole residual
    assert fit_gains(cases, FixedResidual([0.0, -2_000.0]), params) == {False: [0.0] * 4, True: [0.0] * 4}


def test_corrected_kinds_keep_the_shape_the_walk_would_round():
    """A 8 x 2 km slick drifting exactly as a steady current says: physics-corrected moves its particles
    without the random walk (its spreading is the observed area trend, here none), so at 15 h its
    footprint is the observed one translated; the physics prior's walk (K = 10 m^2/s, about 1 km of
    spread by then) rounds it."""
    slick = box(-4_000, -1_000, 4_000, 1_000)
    hours = np.arange(6.0)
    current = [0.0, 0.0, 0.2, 0.1]
    geoms = [affinity.translate(slick, 720.0 * (h - hours[-1]), 360.0 * (h - hours[-1])) for h in hours]
    obs = planar_observations(geoms, hours, np.tile(current, (len(hours), 1)), ahead=[current] * 15)
    corrected, physics = (E.forecast_plane(k, obs, (15,), E.Settings(), contours=False)[0]
                          for k in ("physics-corrected", "physics"))
    truth = affinity.translate(slick, 0.2 * 54_000, 0.1 * 54_000)
    assert iou(corrected.geometry, truth) > 0.9
    assert F.shape_axes(F.Shape.of(corrected.geometry).cov)[0] == pytest.approx(4.0, rel=0.1)
    assert F.shape_axes(F.Shape.of(physics.geometry).cov)[0] < 3.2
