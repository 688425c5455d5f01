"""The physics prior: exact advection, windage and deflection, diffusion, the footprint method, multi-part
footprints and the ensemble probability."""
import math

import numpy as np
import pytest
import shapely
from shapely import affinity
from shapely.geometry import MultiPolygon, Point, box

from oilspill_moos.forecaster import engine as E
from oilspill_moos.forecaster.physics import (DriftParameters, ForcingTrack, Grid, ParticleFootprint, displacement, drift,
                                              drift_velocity, probability, sample_particles)


def iou(a, b):
    return shapely.intersection(a, b).area / shapely.union(a, b).area


def test_uniform_flow_advects_exactly():
    """A uniform current of (0.3, -0.1) m/s and no wind, no diffusion: every particle moves by exactly
    velocity x time, and the footprint is the observed one translated."""
    track = ForcingTrack([0.0], [[0.0, 0.0, 0.3, -0.1]])
    slick = Point(0, 0).buffer(2_000, quad_segs=32)
    params = DriftParameters(diffusivity=0.0, particles=2000)
    horizons = 3600.0 * np.array([3, 7, 11, 15])
    moved, start = drift(slick, 0.0, horizons, track, params)
    for h, p in zip(horizons, moved):
        assert np.allclose(p - start, [0.3 * h, -0.1 * h], atol=1e-9)
    method = ParticleFootprint(slick, start)
    grid, mask, footprint = method.draw(moved[-1])
    assert iou(footprint, affinity.translate(slick, 0.3 * horizons[-1], -0.1 * horizons[-1])) > 0.92


def test_piecewise_forcing_integrates_exactly_and_holds_the_last_value():
    track = ForcingTrack([0.0, 3600.0], [[0, 0, 1.0, 0.0], [0, 0, 0.0, 2.0]])
    got = displacement(track, 1800.0, [3600.0, 7200.0, 10800.0])
    assert np.allclose(got, [[1800.0, 0.0], [1800.0, 7200.0], [1800.0, 14400.0]])
    assert np.allclose(track.at([-5.0, 0.0, 3599.0, 1e9]), [[0, 0, 1, 0], [0, 0, 1, 0], [0, 0, 1, 0], [0, 0, 0, 2]])


def test_windage_and_deflection_to_the_right():
    wind_north = [[0.0, 10.0, 0.0, 0.0]]
    assert np.allclose(drift_velocity(wind_north, windage=0.03, deflection_deg=0.0), [[0.0, 0.3]])
    turned = drift_velocity(wind_north, windage=0.03, deflection_deg=90.0)
    assert np.allclose(turned, [[0.3, 0.0]], atol=1e-12)      # a wind towards north drifts oil towards east


def test_diffusion_spreads_as_two_k_t():
    params = DriftParameters(diffusivity=20.0, particles=20000)
    tiny = Point(0, 0).buffer(1.0)
    moved, _ = drift(tiny, 0.0, [36000.0], ForcingTrack([0.0], [[0, 0, 0, 0]]), params)
    assert moved[0].var(axis=0) == pytest.approx([2 * 20.0 * 36000.0] * 2, rel=0.05)


def test_footprint_method_reproduces_the_observed_area_at_the_start():
    for slick in (box(0, 0, 8_000, 2_000), Point(0, 0).buffer(3_000)):
        start = sample_particles(slick, 1500, np.random.default_rng(0))
        method = ParticleFootprint(slick, start)
        _, _, footprint = method.draw(start)
        assert footprint.area == pytest.approx(slick.area, rel=0.1)
        assert iou(footprint, slick) > 0.85


def test_multi_part_in_multi_part_out():
    lobes = MultiPolygon([Point(0, 0).buffer(3_000), Point(20_000, 5_000).buffer(1_500)])
    track = ForcingTrack([0.0], [[5.0, 0.0, 0.1, 0.0]])
    obs = E.Observations(plane=None, geometries=[lobes], shapes=[E.F.Shape.of(lobes)], times_s=np.array([0.0]),
                         environments=np.array([[5.0, 0.0, 0.1, 0.0]]), track=track)
    for kind in ("physics", "persistence", "constant-velocity-growth"):
        out = E.forecast_plane(kind, obs, (3, 15), E.Settings())
        for f in out:
            assert isinstance(f.geometry, MultiPolygon) and len(f.geometry.geoms) == 2, kind
            assert f.geometry.is_valid
            assert f.contour_90.area >= f.contour_50.area > 0


def test_probability_of_symmetric_shifts_is_known():
    """A square shifted by +d and -d (two equally likely members): P = 1 on the overlap, 1/2 on the rest."""
    grid = Grid(0.0, 0.0, 100.0, 40, 40)
    mask = grid.rasterise(box(1_000, 1_000, 3_000, 3_000))
    big, p = probability(mask, grid, np.array([[500.0, 0.0], [-500.0, 0.0]]))
    assert np.isclose(p, 1.0).sum() * 100.0 ** 2 == pytest.approx(1_000 * 2_000)
    assert np.isclose(p, 0.5).sum() * 100.0 ** 2 == pytest.approx(2 * 1_000 * 2_000)
    assert p.sum() * 100.0 ** 2 == pytest.approx(2_000 * 2_000, rel=1e-6)
    # contours interpolate between cell centres: within a cell of the known edges
    assert big.contour(p, 0.9).area == pytest.approx(1_000 * 2_000, rel=0.15)
    assert big.contour(p, 0.4).area == pytest.approx(3_000 * 2_000, rel=0.1)


def perturbed(track: ForcingTrack, member) -> ForcingTrack:
    """The track with the member's wind and current each scaled and turned counter-clockwise: the
    errors spelled out on the forcing itself, independently of ``forcing_offsets``' linear form."""
    values = track.values.copy()
    for k, (i, j) in enumerate(((0, 1), (2, 3))):
        scale, turn = member[2 * k], member[2 * k + 1]
        c, s = math.cos(turn), math.sin(turn)
        u, w = track.values[:, i], track.values[:, j]
        values[:, i], values[:, j] = scale * (c * u - s * w), scale * (s * u + c * w)
    return ForcingTrack(track.times_s, values)


def test_member_offsets_are_the_displacements_under_the_perturbed_forcing():
    track = ForcingTrack([-7200.0, 0.0, 3600.0 * 5], [[8.0, 3.0, 0.25, -0.1], [2.0, -6.0, 0.1, 0.3], [-4.0, 1.0, 0.0, 0.2]])
    params = DriftParameters(deflection_deg=12.0)
    horizons = np.array([3 * 3600.0, 11 * 3600.0])
    obs = E.Observations(None, [], [], np.array([0.0]), track.values[:1], track)
    members = E.forcing_members(16)
    offsets = E.forcing_offsets(obs, horizons, params, members)
    central = displacement(track, 0.0, horizons, params.windage, params.deflection_deg)
    for m, member in enumerate(members):
        moved = displacement(perturbed(track, member), 0.0, horizons, params.windage, params.deflection_deg)
        assert np.allclose(offsets[:, m], moved - central, atol=1e-6)


def test_ensemble_covers_a_truth_drawn_from_the_same_forcing_errors():
    """Synthetic case with a known answer: the truth drifts under a forcing drawn from the very error
    distribution the ensemble samples, so the nominal 95 % radius (uncalibrated) must hold the true
    centroid about 95 % of the time."""
    track = ForcingTrack([0.0], [[8.0, 3.0, 0.25, -0.1]])
    params = DriftParameters()
    horizon = np.array([15 * 3600.0])
    obs = E.Observations(None, [], [], np.array([0.0]), np.array([[8.0, 3.0, 0.25, -0.1]]), track)
    offsets = E.forcing_offsets(obs, horizon, params, E.forcing_members(200))[0]
    sigma = math.sqrt((offsets ** 2).sum(axis=1).mean() / 2)
    central = displacement(track, 0.0, horizon)[0]
    truths = E.forcing_members(400, seed=99)[1:]
    inside = [np.linalg.norm(displacement(perturbed(track, m), 0.0, horizon)[0] - central) <= E.RADIUS_95 * sigma
              for m in truths]
    assert 0.90 <= np.mean(inside) <= 0.99
