"""`uSimMarine` (deprecated in MOOS-IvP) and `uSimMarineV22` are two variants of one model (issue 15's
loiter finding): the deprecated simulator turns at the full rate at any speed, loses a fixed 0.85 of
its speed at full rudder and posts NAV_* every iteration; V22 scales the turn rate by speed (full at
5 m/s) and posts every second iteration.

The closed loop is the helm's BHV_Loiter (1.4 m/s, radius 20 m), pMarinePID's control law and the
model, ticked as a mission ticks them (sim and PID 10 Hz, helm 4 Hz), for 900 s: the deprecated
model covers 1,168 m in the other engineer's measurement (the V22 model about 840 m here); with no
rudder speed loss the two are the same boat.
"""
import asyncio
import math
import statistics
from dataclasses import replace

import pytest

from behaviors.bhv_file import parse_bhv
from behaviors.domain import IvPDomain, parse_domain_line
from behaviors.helm import Helm
from helpers import async_wait_until
from moosdb_py.client import MOOSClient
from moosdb_py.nsplug import preprocess
from oilspill_moos.marine.marine_pid import PIDEngine, PIDParams
from oilspill_moos.marine.sim_marine import MarineModel, SimMarine, SimMarineDeprecated, SimParams

LOITER = """initialize DEPLOY = true
Behavior = BHV_Loiter
{
  name      = loiter
  condition = DEPLOY = true
      speed = 1.4
  clockwise = false
     radius = 8.0
  nm_radius = 15.0
    polygon = radial:: x=0, y=-50, radius=20, pts=8, snap=1
}
"""
PID = {"depth_control": "false", "yaw_pid_kp": "1.2", "yaw_pid_kd": "0.1", "yaw_pid_ki": "0.3",
       "yaw_pid_integral_limit": "0.07", "speed_pid_kp": "1.0", "speed_factor": "20"}
SIM = {"start_pos": "0,0,0,0", "prefix": "NAV"}
DEPRECATED_LOITER_M = 1168.0   # 900 s closed loop of the deprecated model, as measured for issue 15


def loiter_distance(params: SimParams, tmp_path, seconds: float = 900.0) -> float:
    """Metres the model covers in `seconds` of the closed loop; the helm and PID see NAV_* as posted."""
    bhv = tmp_path / "loiter.bhv"
    bhv.write_text(LOITER)
    domain = IvPDomain(vars=[parse_domain_line("course:0:359:360"), parse_domain_line("speed:0:4:41")])
    helm = Helm([parse_bhv(preprocess(bhv), bhv)], domain, "abe", active_start=True)
    helm.startup(0.0)
    model, pid = MarineModel(params), PIDEngine(PIDParams.from_config(PID))
    nav = {"NAV_X": 0.0, "NAV_Y": 0.0, "NAV_HEADING": 0.0, "NAV_SPEED": 0.0}
    desired = {"DESIRED_HEADING": 0.0, "DESIRED_SPEED": 0.0}
    covered = 0.0
    for tick in range(1, int(seconds * 10) + 1):    # 10 Hz: sim and PID; helm every 2.5 ticks (4 Hz)
        now = tick / 10
        x, y = model.state.x, model.state.y
        model.step(0.1)
        covered += math.hypot(model.state.x - x, model.state.y - y)
        if tick % params.nav_interval == 0:
            nav = {"NAV_X": model.state.x, "NAV_Y": model.state.y, "NAV_HEADING": model.state.heading,
                   "NAV_SPEED": model.state.speed}
        if tick % 5 in (0, 3):   # 0.0, 0.3, 0.5, 0.8 s: four helm iterations a second
            for key, value in nav.items():
                helm.on_mail(key, value, now)
            desired.update((k, v) for k, v, _ in helm.iterate(now) if k in desired)
        rudder, thrust = pid.control(desired["DESIRED_HEADING"], desired["DESIRED_SPEED"], nav["NAV_HEADING"],
                                     nav["NAV_SPEED"], now)
        model.set_rudder(rudder, now)
        model.set_thrust(thrust)
    return covered


def test_the_deprecated_model_loiters_as_far_as_measured(tmp_path):
    deprecated = replace(SimParams.from_config(SIM), **SimMarineDeprecated.variant)
    assert loiter_distance(deprecated, tmp_path) == pytest.approx(DEPRECATED_LOITER_M, rel=0.03)


def test_without_rudder_speed_loss_the_variants_are_the_same_boat(tmp_path):
    """At 1.4 m/s V22's turn rate is 28 % of the full one, yet with turn_spd_loss 0 the loop is as
    long (300 s of it): the loiter runs at the helm's speed either way; the loss is what differs."""
    no_loss = SimParams.from_config({**SIM, "turn_spd_loss": "0"})
    v22 = loiter_distance(replace(no_loss, **SimMarine.variant), tmp_path, 300.0)
    deprecated = loiter_distance(replace(no_loss, **{**SimMarineDeprecated.variant, "turn_spd_loss": 0.0}), tmp_path,
                                 300.0)
    assert deprecated == pytest.approx(v22, rel=0.01)


def test_the_deprecated_model_turns_at_the_full_rate_at_low_speed():
    for variant, rate in ((SimMarineDeprecated.variant, 70.0), (SimMarine.variant, 70.0 * 1.0 / 5.0)):
        params = replace(SimParams.from_config({**SIM, "thrust_map": "0:0, 100:5"}), **variant)
        model = MarineModel(replace(params, turn_spd_loss=0.0))
        model.state.speed = 1.0
        model.set_thrust(20.0)   # 1 m/s: no change of speed
        model.set_rudder(100.0, 0.0)
        model.step(0.1)
        # full rudder: rate x dt x (1 + (thrust - 50) / 50) degrees
        assert model.state.heading == pytest.approx(rate * 0.1 * (1 + (20.0 - 50.0) / 50.0))


@pytest.mark.parametrize("app, name, interval", [(SimMarineDeprecated, "uSimMarine", 0.25),
                                                 (SimMarine, "uSimMarineV22", 0.5)])
def test_nav_cadence(app, name, interval, moosdb_server, tmp_path):
    """AppTick 4: an iteration every 0.25 s of MOOS time; uSimMarine posts NAV_* on each one,
    uSimMarineV22 on every second one."""
    mission = tmp_path / "sim.moos"
    mission.write_text(f"ServerHost = 127.0.0.1\nServerPort = {moosdb_server.port}\nCommunity = abe\n"
                       f"MOOSTimeWarp = 10\n\nProcessConfig = {name}\n{{\n  AppTick = 4\n  prefix = NAV\n}}\n")

    async def scenario():
        sim = app(mission, name)
        watcher = MOOSClient("uWatch", "127.0.0.1", moosdb_server.port, time_warp=10)
        watcher.register("NAV_X")
        tasks = [asyncio.create_task(sim.run_async()), asyncio.create_task(watcher.run())]
        try:
            await async_wait_until(lambda: sum(m.key == "NAV_X" for m in watcher.inbox) >= 12, 10)
        finally:
            sim.stop()
            watcher.close()
            await asyncio.wait_for(asyncio.gather(*tasks), 5)
        stamps = [m.time for m in watcher.inbox if m.key == "NAV_X"]
        assert statistics.median(b - a for a, b in zip(stamps, stamps[1:])) == pytest.approx(interval, rel=0.3)
        assert {m.source for m in watcher.inbox if m.key == "NAV_X"} == {name}

    asyncio.run(scenario())
