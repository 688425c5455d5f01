"""Closed loop end to end: missions/oilspill with FEEDBACK, 3 vehicles against a truth spill.

The forecaster forecasts a held-out scenario 3 h ahead from its first 17 hourly polygons (hours
1-17, so valid at hour 20); the forecast goes to pPathAssign; uFldOilSensor holds the scenario's
truth at hour 21, an hour after that forecast's valid time (the fleet is late, as fleets are); the vehicles' pOilSampler observations
cross the bridges to uFldOilFusion, which scores the forecast and writes them for the
forecaster; the forecaster re-anchors on them, and the corrected outline must fit the truth
better than the forecast the fleet was sent around. Fixed scenario and sensor seed.
"""
import asyncio
import threading

import pytest
from helpers import wait_until
from moosdb_py.client import MOOSClient
from oilspill_moos.demo import Observer, OilspillMission
from shapely.geometry import Polygon

from oilspill_moos.forecaster.assimilate import ingest, read_feedback
from oilspill_moos.forecaster.boundary import outline
from oilspill_moos.forecaster.dataset import load_dataset
from oilspill_moos.forecaster.features import to_plane
from oilspill_moos.forecaster.operational import Forecaster
from oilspill_moos.geodesy import LocalGrid
from oilspill_moos.oil_fusion import ScenarioMap, parse_observation
from oilspill_moos.path_assign import OIL_PATH, format_points, parse_report
from oilspill_moos.forecaster.push import push_lines

WARP = 12.0
TIMEOUT = 40.0
SCENARIO = "strong_forcing-2214"   # a held-out scenario of the shipped weights
MAP_SCALE = 0.015                  # its ~8 km slick becomes ~120 m: a kayak loop of a minute or two
ORIGIN = LocalGrid(28.736667, -88.387222)


def iou(a, b):
    a, b = to_plane(a), to_plane(b)
    return a.intersection(b).area / a.union(b).area


@pytest.fixture(scope="module")
def forecast_case():
    forecaster = Forecaster()
    scenario = next(s for s in load_dataset() if s.scenario_id == SCENARIO)
    assert SCENARIO in forecaster.split["test"]
    history = scenario.geometries[:17], scenario.times()[:17], scenario.environments()[:17]
    (first, *_) = forecaster.forecast(*history, scenario.release_time)
    assert first.horizon_h == 3
    return forecaster, scenario, history, first.geometry


def test_observations_reach_the_shore_and_correct_the_forecast(tmp_path, forecast_case):
    forecaster, scenario, history, forecast = forecast_case
    world = ScenarioMap(ORIGIN, MAP_SCALE)
    feedback = tmp_path / "feedback.jsonl"
    mission = OilspillMission(tmp_path / "run", vehicles=3, warp=WARP, standoff=10.0, node_timeout=30.0, extra={
        "FEEDBACK": "true", "OIL_SCENARIO": SCENARIO, "OIL_START_HOUR": "21", "OIL_MAP_SCALE": f"{MAP_SCALE:g}",
        "SENSOR_RANGE": "15", "FALSE_POS": "0.02", "FALSE_NEG": "0.05", "SAMPLE_INTERVAL": "3",
        "FEEDBACK_FILE": str(feedback)})
    skills, warnings = [], []

    def on_mail(mail):
        for msg in mail:
            (skills if msg.key == "OIL_FUSION_SKILL" else warnings).append(str(msg.value))

    mission.start()
    loop = asyncio.new_event_loop()
    observer = Observer("127.0.0.1", mission.shoreside.moos_port, WARP)
    watch = MOOSClient("uFeedbackWatch", "127.0.0.1", mission.shoreside.moos_port, on_mail=on_mail, time_warp=WARP,
                       on_connect=lambda: [watch.register(k) for k in ("OIL_FUSION_SKILL", "OIL_FUSION_WARNING")])

    async def clients():
        await asyncio.gather(observer.client.run(), watch.run())

    thread = threading.Thread(target=loop.run_until_complete, args=(clients(),), daemon=True)
    thread.start()
    try:
        wait_until(lambda: mission.dead() or observer.vehicles_seen() >= set(mission.fleet), timeout=TIMEOUT)
        assert not mission.dead(), f"communities stopped: {mission.dead()}"
        asyncio.run_coroutine_threadsafe(observer.deploy(mission.fleet, TIMEOUT, mission), loop).result(TIMEOUT + 5)
        spill = world.to_local(Polygon(outline(forecast)))   # the one ring the forecaster pushes
        line = f"pts={{{format_points(spill.exterior.coords[:-1])}}}\n"
        assert push_lines([line.encode()], port=mission.boundary_port) == [1]
        wait_until(lambda: observer.phase_count.get(OIL_PATH, 0) >= 1, timeout=TIMEOUT)
        looping_since = observer.moos_now
        perimeter = spill.buffer(10.0).exterior.length
        # each vehicle covers a third of the loop at 2 m/s, and a little more
        wait_until(lambda: observer.moos_now - looping_since > perimeter / 3 / 2.0 + 10, timeout=TIMEOUT)
        wait_until(lambda: skills, timeout=TIMEOUT)
    finally:
        loop.call_soon_threadsafe(observer.client.close)
        loop.call_soon_threadsafe(watch.close)
        thread.join(timeout=5)
        mission.stop()

    lines = feedback.read_text().splitlines()
    assert {parse_report(s)["cycle"] for s in skills} == {"oilspill_1"}
    assert len(lines) >= 30 and not [w for w in warnings if "unknown" in w or "order" in w], warnings[:3]
    obs = read_feedback(feedback)
    assert obs.oil.any() and not obs.oil.all(), "the loop should see both oil and open water"
    fields = parse_report(skills[-1])
    assert float(fields["agreement"]) < 1.0 and int(fields["flips"]) >= 2

    # the forecaster consumes them: re-anchored outline appended to its history
    geometries, times, _ = ingest(forecaster, *history, obs, release_time=scenario.release_time)
    assert len(geometries) == 18 and times[-1] > times[-2]
    truth = scenario.geometries[20]
    assert scenario.times_h[20] == 21
    before, after = iou(forecast, truth), iou(geometries[-1], truth)
    print(f"IoU with the truth: forecast {before:.3f}, corrected {after:.3f}; {len(obs)} observations; {skills[-1]}")
    assert after > before + 0.05
