"""The evaluation pipeline end to end on a tiny set of drifting, growing elliptical slicks."""
import math
from datetime import datetime, timezone

import numpy as np
import pytest
from shapely import affinity
from shapely.geometry import Point

from oilspill_moos.forecaster import evaluate as E
from oilspill_moos.forecaster import features as F
from oilspill_moos.forecaster.dataset import REGIMES, Scenario, save_dataset
from oilspill_moos.forecaster.train import train_models


def drifting_slick(k: int, regime: str, hours: int = 30) -> Scenario:
    """An ellipse moving at constant velocity and growing steadily: persistence must lose to a trend."""
    rng = np.random.default_rng(k)
    velocity = rng.uniform(-1.5, 1.5, 2)                  # km/h
    angle = rng.uniform(0, 180)
    times = np.arange(hours, dtype=float)
    geometries = []
    for t in times:
        radius = 1500.0 + 150.0 * t
        shape = affinity.rotate(affinity.scale(Point(0, 0).buffer(radius, 32), 1.8, 1.0), angle)
        geometries.append(F.to_lonlat(affinity.translate(shape, *(velocity * t * 1e3))))
    forcing = np.tile([5.0, 1.0, 0.1, 0.05, 26.0], (hours, 1))
    return Scenario(scenario_id=f"{regime}-{k}", regime=regime, seed=k,
                    release_time=datetime(2010, 4, 24, 6, tzinfo=timezone.utc), params={"velocity": velocity.tolist()},
                    times_h=times, geometries=geometries, forcing=forcing)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("eval")
    scenarios = [drifting_slick(3 * i + j, regime) for i, regime in enumerate(REGIMES) for j in range(3)]
    stem = root / "tiny"
    save_dataset(scenarios, stem, generation={"note": "test"})
    train_models(["ltc-fused", "lstm"], dataset_stem=stem, out_dir=root / "weights", progress=False,
                 epochs=2, hidden=16, unfolds=1, lr=1e-2)
    return root, scenarios


def test_polygon_metrics_on_known_shapes():
    a = Point(0, 0).buffer(1000.0, 64)
    b = affinity.translate(a, 1000.0, 0)
    m = E.polygon_metrics(a, b)
    assert m["centroid_err_km"] == pytest.approx(1.0, rel=1e-6)
    assert m["hausdorff_km"] == pytest.approx(1.0, rel=1e-3)
    assert m["area_abs_err_km2"] == pytest.approx(0.0, abs=1e-9)
    lens = 2 * (1000.0 ** 2) * (math.acos(0.5) - 0.5 * math.sqrt(1 - 0.25))   # two circles, d = r
    assert m["iou"] == pytest.approx(lens / (2 * math.pi * 1e6 - lens), rel=1e-2)
    assert E.polygon_metrics(a, a)["iou"] == pytest.approx(1.0)


def test_constant_velocity_extrapolates_a_linear_track_exactly():
    inputs = np.zeros((1, 16, len(F.FEATURE_NAMES)))
    cols = [F.FEATURE_INDEX[n] for n in F.TARGET_NAMES]
    inputs[0, :, F.FEATURE_INDEX["centroid_x_km"]] = 2.0 * np.arange(16)
    inputs[0, :, F.FEATURE_INDEX["aspect_ratio"]] = 1.5
    inputs[0, :, F.FEATURE_INDEX["orientation_cos2"]] = 1.0
    out = E.constant_velocity_targets(inputs, np.ones((1, 16)), (3, 7), cols)
    assert out[0, :, 0] == pytest.approx([30 + 6, 30 + 14])
    assert E.persistence_targets(inputs, None, (3, 7), cols)[0, :, 0] == pytest.approx([30, 30])


def test_temporal_consistency_is_zero_at_constant_velocity():
    track = np.array([[[3.0, 0.0], [7.0, 0.0], [11.0, 0.0], [15.0, 0.0]]])
    assert E.centroid_velocity_variance(np.zeros((1, 2)), track, (3, 7, 11, 15)) == pytest.approx([0.0])
    assert E.centroid_velocity_variance(np.zeros((1, 2)), track[:, ::-1], (3, 7, 11, 15))[0] > 0


def test_bootstrap_and_paired_tests():
    rng = np.random.default_rng(0)
    a = rng.normal(1.0, 0.1, 12)
    mean, low, high = E.bootstrap_ci(a)
    assert low < mean < high and mean == pytest.approx(a.mean())
    b = a + 0.5 + rng.normal(0.0, 0.05, 12)
    result = E.paired_tests(b, a)
    assert result["mean_diff"] == pytest.approx((b - a).mean()) and result["n"] == 12
    assert result["wilcoxon_p"] < 0.01 and result["t_p"] < 0.01


def test_pipeline_scores_every_method_and_writes_the_report(trained, tmp_path):
    root, scenarios = trained
    ev = E.run_evaluation(root / "weights", scenarios=[s for s in scenarios if s.scenario_id.endswith(("0", "5"))],
                          progress=False)
    assert set(ev.methods) == {"ltc-fused", "lstm", "persistence", "constant-velocity"}
    for name, result in ev.methods.items():
        assert result.values["iou"].shape == (len(ev.windows), 4)
        assert np.nanmin(result.values["iou"]) >= 0 and np.nanmax(result.values["iou"]) <= 1
    # a steadily drifting, growing ellipse: the trend baseline must beat persistence at 15 h
    assert ev.summary("iou", "constant-velocity", horizon=3)[0] > ev.summary("iou", "persistence", horizon=3)[0]
    assert 0 <= ev.summary("coverage", "lstm")[0] <= 1
    assert ev.methods["lstm"].cost["latency_ms"] > 0
    report = tmp_path / "report.md"
    E.write_report(ev, report, tmp_path / "img", {}, ["(no real data in this test)"], "test")
    text = report.read_text()
    assert "| ltc-fused |" in text and "persistence" in text and "Wilcoxon" in text
    assert (tmp_path / "img" / "forecaster-horizons.png").stat().st_size > 1000


def test_operational_once_pushes_every_horizon_to_a_listener(trained, tmp_path):
    import json
    import socket
    import threading

    from oilspill_moos.forecaster import operational

    root, scenarios = trained
    for k in (10, 11, 12):
        name = f"slick_{scenarios[0].times()[k]:%Y%m%dT%H%M}.geojson"
        geometry = scenarios[0].geometries[k]
        (tmp_path / name).write_text(json.dumps({"type": "FeatureCollection", "features": [
            {"type": "Feature", "properties": {}, "geometry": geometry.__geo_interface__}]}))
    received = []
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(20)

    def listen():
        conn, _ = server.accept()
        with conn, conn.makefile("rwb") as stream:
            for n, line in enumerate(stream, 1):
                received.append(json.loads(line))
                stream.write(f"OK {n}\n".encode())
                stream.flush()

    thread = threading.Thread(target=listen, daemon=True)
    thread.start()
    rc = operational.main(["--once", "--observations", str(tmp_path), "--weights", str(root / "weights"),
                           "--model", "lstm", "--port", str(server.getsockname()[1])])
    server.close()
    assert rc == 0
    assert [m["horizon_h"] for m in received] == [3, 7, 11, 15]
    assert all(m["crs"] == "EPSG:4326" and len(m["polygon"]) >= 3 and m["uncertainty_m"] > 0 for m in received)


def test_forecaster_refuses_a_single_observation(trained):
    from oilspill_moos.forecaster.operational import Forecaster

    root, scenarios = trained
    with pytest.raises(ValueError, match="at least 2"):
        Forecaster(root / "weights", "ltc-fused").forecast(scenarios[0].geometries[:1], scenarios[0].times()[:1])
