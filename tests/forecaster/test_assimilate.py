"""Feedback re-anchoring on a case where the truth is known: readings sampled around a forecast that is
off by a known shift and scale bring the outline back onto the truth."""
import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Point

from oilspill_moos.forecaster.assimilate import SensorReadings, reanchor, reanchored_history
from oilspill_moos.forecaster.features import plane_to_lonlat, to_lonlat, to_plane


def iou(a, b):
    return a.intersection(b).area / a.union(b).area


@pytest.mark.parametrize("shift, scale", [((1_500.0, -800.0), 1.0), ((0.0, 0.0), 1.25), ((-1_000.0, 600.0), 0.85)])
def test_reanchoring_recovers_a_known_truth(shift, scale):
    truth = affinity.scale(Point(5_000, 2_000).buffer(4_000, quad_segs=32), 1.6, 1.0)
    forecast = affinity.translate(affinity.scale(truth, 1 / scale, 1 / scale), -shift[0], -shift[1])
    # the fleet sweeps rings 2 km inside to 2 km outside the forecast edge, sensing oil within 100 m:
    # enough readings on both sides of the true edge to pin it down
    xy = np.vstack([np.array([ring.interpolate(d).coords[0] for d in np.linspace(0, ring.length, 60, endpoint=False)])
                    for ring in (forecast.buffer(b).exterior for b in (-2_000, -1_000, 0, 1_000, 2_000))])
    oil = np.array([truth.distance(Point(x, y)) <= 100.0 for x, y in xy])
    lon, lat = plane_to_lonlat(xy[:, 0], xy[:, 1])
    readings = SensorReadings(np.asarray(lon), np.asarray(lat), oil, np.full(len(xy), 100.0), np.zeros(len(xy)))
    anchored = to_plane(reanchor(to_lonlat(forecast), readings))
    assert iou(anchored, truth) > max(0.9, iou(forecast, truth) + 0.05)
    assert np.hypot(anchored.centroid.x - truth.centroid.x, anchored.centroid.y - truth.centroid.y) < 300


def test_no_readings_change_nothing():
    forecast = to_lonlat(Point(0, 0).buffer(3_000))
    empty = SensorReadings(*(np.array([]) for _ in range(5)))
    assert reanchor(forecast, empty) is forecast


def test_the_history_moves_with_the_anchor():
    """A forecast 1.5 km off a known truth: the re-anchored outline is appended, and every earlier
    observation is moved by the same shift, so the observed motion between them is unchanged."""
    truth = Point(5_000, 2_000).buffer(4_000, quad_segs=32)
    forecast = affinity.translate(truth, -1_500.0, 0.0)
    history = [affinity.translate(truth, -1_500.0 - 2_000.0 * k, 0.0) for k in (3, 2, 1)]
    xy = np.vstack([np.array([ring.interpolate(d).coords[0] for d in np.linspace(0, ring.length, 60, endpoint=False)])
                    for ring in (forecast.buffer(b).exterior for b in (-2_000, -1_000, 0, 1_000, 2_000))])
    oil = np.array([truth.distance(Point(x, y)) <= 100.0 for x, y in xy])
    lon, lat = plane_to_lonlat(xy[:, 0], xy[:, 1])
    readings = SensorReadings(np.asarray(lon), np.asarray(lat), oil, np.full(len(xy), 100.0), np.zeros(len(xy)))
    out = [to_plane(g) for g in reanchored_history([to_lonlat(g) for g in history], to_lonlat(forecast), readings)]
    assert len(out) == 4 and abs(out[-1].centroid.x - truth.centroid.x) < 300
    shift = np.subtract(out[-1].centroid.coords[0], forecast.centroid.coords[0])
    assert shift[0] > 1_200 and abs(shift[1]) < 300
    for before, after in zip(history, out[:-1]):
        assert np.allclose(np.subtract(after.centroid.coords[0], before.centroid.coords[0]), shift, atol=1.0)
