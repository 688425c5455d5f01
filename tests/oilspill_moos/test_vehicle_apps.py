"""uSimMarine, pMarinePID and pNodeReporter as MOOS apps against a real moosdb, driven by a scripted client."""
from __future__ import annotations

import asyncio
import contextlib
import os
import statistics

import pytest

from helpers import CORPUS, async_wait_until, requires_shared
from moosdb_py.client import MOOSClient
from moosdb_py.message import MOOSMsg
from moosdb_py.mission import read_mission
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.marine.marine_pid import MarinePID, PIDParams
from oilspill_moos.marine.node_reporter import NodeReporter, ReporterParams
from oilspill_moos.marine.sim_marine import SimMarine, SimParams

WARP = 10
BLOCKS = {
    "uSimMarineV22": """
  AppTick = 4
  start_pos = x=0, y=-20, heading=180, speed=0
  prefix = NAV
  turn_rate = 95
  thrust_map = 0:0, 20:1, 40:2, 60:3, 80:4, 100:5
  turn_spd_loss = 0.4""",
    "pMarinePIDV22": """
  AppTick = 10
  depth_control = false
  yaw_pid_kp = 0.9
  yaw_pid_kd = 0.3
  yaw_pid_ki = 0.3
  yaw_pid_integral_limit = 0.07
  speed_factor = 20""",
    "pNodeReporter": """
  AppTick = 2
  platform_type = kayak
  platform_length = 4""",
}


def write_mission(tmp_path, port, blocks=BLOCKS):
    path = tmp_path / "vehicle.moos"
    text = (f"ServerHost = localhost\nServerPort = {port}\nCommunity = alpha\nMOOSTimeWarp = {WARP}\n"
            "LatOrigin = 43.825300\nLongOrigin = -70.330400\n")
    text += "".join(f"\nProcessConfig = {name}\n{{{body}\n}}\n" for name, body in blocks.items())
    path.write_text(text)
    return path


@contextlib.asynccontextmanager
async def running(apps, port, keys):
    """Run the apps and a watcher client (registered for `keys`) in this event loop."""
    watcher = MOOSClient("uScript", port=port, time_warp=WARP)
    for key in keys:
        watcher.register(key)
    tasks = [asyncio.create_task(app.run_async()) for app in apps] + [asyncio.create_task(watcher.run())]
    try:
        assert await watcher.wait_connected(5)
        yield watcher
    finally:
        for app in apps:
            app.stop()
        watcher.close()
        await asyncio.wait_for(asyncio.gather(*tasks), 5)


def latest(watcher, key):
    values = [m for m in watcher.inbox if m.key == key]
    return values[-1] if values else None


def value(watcher, key, default=None):
    msg = latest(watcher, key)
    return default if msg is None else msg.value


def test_sim_posts_nav_every_second_iteration_and_follows_thrust(moosdb_server, tmp_path, caplog):
    async def scenario():
        sim = SimMarine(write_mission(tmp_path, moosdb_server.port), "uSimMarineV22")
        keys = ["NAV_X", "NAV_Y", "NAV_LAT", "NAV_LONG", "NAV_SPEED", "NAV_HEADING", "NAV_DEPTH",
                "NAV_SPEED_OVER_GROUND", "USM_DRIFT_SUMMARY", "USM_RESET_COUNT"]
        async with running([sim], moosdb_server.port, keys) as w:
            await async_wait_until(lambda: latest(w, "NAV_X") is not None, 5)
            assert latest(w, "NAV_Y").double == pytest.approx(-20) and latest(w, "NAV_HEADING").double == 180
            # AppTick 4: one iteration per 0.25 s of MOOS time, nav on every second one
            await async_wait_until(lambda: sum(m.key == "NAV_X" for m in w.inbox) >= 8, 5)
            stamps = [m.time for m in w.inbox if m.key == "NAV_X"]
            assert 0.4 < statistics.median(b - a for a, b in zip(stamps, stamps[1:])) < 0.75
            w.notify("ROTATE_SPEED", "fast")  # bad mail: named in a warning, nothing else changes
            await async_wait_until(lambda: "ROTATE_SPEED from uScript ignored" in caplog.text, 5)
            w.notify("DESIRED_THRUST", 40.0)
            await async_wait_until(lambda: latest(w, "NAV_SPEED").double >= 1.98, 10)
            assert latest(w, "NAV_SPEED").source == "uSimMarineV22"
            await async_wait_until(lambda: latest(w, "NAV_Y").double < -25, 10)
            x, y = latest(w, "NAV_X").double, latest(w, "NAV_Y").double
            lat, lon = latest(w, "NAV_LAT").double, latest(w, "NAV_LONG").double
            assert LocalGrid(43.8253, -70.3304).to_local(lat, lon) == pytest.approx((x, y), abs=2.0)
            w.notify("DRIFT_VECTOR", "90,0.5")
            await async_wait_until(lambda: value(w, "USM_DRIFT_SUMMARY", "").startswith("ang=90,mag=0.5"), 5)
            w.notify("USM_RESET", "x=5, y=6, heading=45")
            await async_wait_until(lambda: latest(w, "USM_RESET_COUNT") is not None, 5)
            assert sim.model.state.heading == 45
    asyncio.run(scenario())


def test_pid_takes_control_only_when_unoverridden_and_goes_stale(moosdb_server, tmp_path, caplog):
    async def scenario():
        pid = MarinePID(write_mission(tmp_path, moosdb_server.port), "pMarinePIDV22")
        keys = ["DESIRED_RUDDER", "DESIRED_THRUST", "PID_HAS_CONTROL", "PID_STALE"]
        async with running([pid], moosdb_server.port, keys) as w:
            def feed():
                for key, value in (("NAV_HEADING", 350.0), ("NAV_SPEED", 1.0), ("DESIRED_HEADING", 10.0),
                                   ("DESIRED_SPEED", 2.0)):
                    w.notify(key, value)
            feed()
            await async_wait_until(lambda: pid.iterations > 10, 5)
            assert latest(w, "DESIRED_THRUST") is None  # overridden from the start
            w.notify("MOOS_MANUAL_OVERRIDE", "false")
            await async_wait_until(lambda: latest(w, "PID_HAS_CONTROL"), 5)
            assert latest(w, "PID_HAS_CONTROL").string == "true"
            w.notify("DESIRED_DEPTH", "deep")
            await async_wait_until(lambda: "DESIRED_DEPTH from uScript is not a number" in caplog.text, 5)
            # control resets the inputs: they must arrive again (and keep coming, or they go stale)
            await async_wait_until(lambda: feed() or value(w, "DESIRED_THRUST") == 40.0, 5, interval=0.05)
            assert latest(w, "DESIRED_RUDDER").double > 0  # 350 -> 10: turn right
            # stop feeding: after 2 warped seconds the inputs are stale and the outputs drop to zero
            await async_wait_until(lambda: latest(w, "PID_STALE"), 5)
            assert latest(w, "PID_STALE").string.startswith("Stale DesHdg:")
            await async_wait_until(lambda: latest(w, "DESIRED_THRUST").double == 0.0, 5)
            w.notify("MOOS_MANUAL_OVERRIDE", "true")
            await async_wait_until(lambda: latest(w, "PID_HAS_CONTROL").string == "false", 5)
    asyncio.run(scenario())


def test_sim_and_pid_close_the_loop_on_a_scripted_heading(moosdb_server, tmp_path):
    """A client stands in for the helm: DESIRED_HEADING=90 at 2 m/s turns the boat east and holds it."""
    async def scenario():
        mission = write_mission(tmp_path, moosdb_server.port)
        sim, pid = SimMarine(mission, "uSimMarineV22"), MarinePID(mission, "pMarinePIDV22")
        async with running([sim, pid], moosdb_server.port, ["NAV_X", "NAV_HEADING", "NAV_SPEED"]) as w:
            w.notify("MOOS_MANUAL_OVERRIDE", "false")
            await async_wait_until(lambda: not pid.overridden, 5)

            def settled():
                w.notify("DESIRED_HEADING", 90.0)
                w.notify("DESIRED_SPEED", 2.0)
                hdg, x = latest(w, "NAV_HEADING"), latest(w, "NAV_X")
                return hdg and x and abs(hdg.double - 90) < 5 and x.double > 20
            await async_wait_until(settled, 20, interval=0.05)
            assert latest(w, "NAV_SPEED").double == pytest.approx(2.0, abs=0.2)
    asyncio.run(scenario())


def test_node_reporter_reports_community_nav_and_helm_mode(moosdb_server, tmp_path):
    async def scenario():
        # Warp 10: a half-second stall of a loaded machine ages IVPHELM_STATE past the default 5 s and
        # the report would say NOHELM-5; the threshold is not what this test is about.
        blocks = {**BLOCKS, "pNodeReporter": BLOCKS["pNodeReporter"] + "\n  nohelm_threshold = 600"}
        reporter = NodeReporter(write_mission(tmp_path, moosdb_server.port, blocks), "pNodeReporter")
        keys = ["NODE_REPORT_LOCAL", "NODE_REPORT_LOCAL_FIRST", "PNODEREPORTER_PID"]
        async with running([reporter], moosdb_server.port, keys) as w:
            await async_wait_until(lambda: reporter.iterations > 2, 5)
            await async_wait_until(lambda: latest(w, "PNODEREPORTER_PID") is not None, 5)
            assert latest(w, "PNODEREPORTER_PID").double == os.getpid()     # what uMemWatch measures
            assert latest(w, "NODE_REPORT_LOCAL") is None  # no nav yet
            for key, value in (("NAV_X", 12.5), ("NAV_Y", -40.25), ("NAV_SPEED", 2.0), ("NAV_HEADING", 181.3),
                               ("NAV_LAT", 43.82494), ("NAV_LONG", -70.3302), ("IVPHELM_STATE", "DRIVE"),
                               ("IVPHELM_SUMMARY", "iter=2,modes=MODE@ACTIVE:SURVEYING")):
                w.notify(key, value)
            await async_wait_until(lambda: sum(m.key == "NODE_REPORT_LOCAL" for m in w.inbox) >= 2, 5)
            first = latest(w, "NODE_REPORT_LOCAL_FIRST").string
            assert first.startswith("NAME=alpha,X=12.5,Y=-40.25,SPD=2,HDG=181.3,DEP=0,LAT=43.82494,LON=-70.3302,"
                                    "TYPE=kayak,MODE=")
            assert "INDEX=" not in first and first.endswith(",LENGTH=4")
            second = [m.string for m in w.inbox if m.key == "NODE_REPORT_LOCAL"][1]
            assert ",MODE=MODE@ACTIVE:SURVEYING,ALLSTOP=unknown,INDEX=1,TIME=" in second
    asyncio.run(scenario())


@pytest.mark.parametrize("app, block, line, word", [
    (SimMarine, "uSimMarineV22", "turn_rate = 150", "turn_rate"),
    (MarinePID, "pMarinePIDV22", "depth_control = sometimes", "depth_control"),
    (NodeReporter, "pNodeReporter", "crossfill_policy = newest", "crossfill_policy"),
])
def test_bad_parameter_is_reported_at_its_line(tmp_path, capsys, free_port, app, block, line, word):
    mission = write_mission(tmp_path, free_port(), {block: f"\n  AppTick = 4\n  {line}"})
    assert app.main([str(mission), block]) == 1
    err = capsys.readouterr().err
    assert f"vehicle.moos:11: {word}:" in err


def test_command_line_pages(capsys):
    for app in (SimMarine, MarinePID, NodeReporter):
        assert app.main(["--example"]) == 0
        example = capsys.readouterr().out
        assert example.startswith("ProcessConfig = ") and "AppTick" in example
        assert app.main(["--interface"]) == 0
        assert "SUBSCRIPTIONS" in capsys.readouterr().out
        assert app.main(["--help"]) == 0
        assert app.default_name in capsys.readouterr().out


CORPUS_MISSIONS = ["s1_alpha/alpha.moos", "minicourse_s2_alpha/alpha.moos", "station-keep-uuv/davis.moos",
                   "minicourse_lab_henry_gilda_baseline/targ_henry.moos",
                   "minicourse_lab_henry_gilda_baseline/targ_gilda.moos"]


@pytest.mark.parametrize("name", CORPUS_MISSIONS)
@requires_shared("missions-corpus")
def test_real_mission_blocks_are_accepted(name):
    """Every uSimMarine/pMarinePID/pNodeReporter block of the real MOOS-IvP missions reads cleanly."""
    mission = read_mission(CORPUS / name)
    readers = {"usimmarine": SimParams.from_config, "usimmarinev22": SimParams.from_config,
               "pmarinepid": PIDParams.from_config, "pmarinepidv22": PIDParams.from_config,
               "pnodereporter": ReporterParams.from_config}
    blocks = [b for b in mission.blocks if b.name.lower() in readers]
    assert len(blocks) == 3
    for block in blocks:
        readers[block.name.lower()](block)
    sim = next(b for b in blocks if b.name.lower().startswith("usimmarine"))
    start = SimParams.from_config(sim).start
    assert (start.heading, start.speed) == (180, 0) and SimParams.from_config(sim).prefix == "NAV"


def test_unhandled_parameters_are_warned_with_their_line(tmp_path, free_port, caplog):
    blocks = {"uSimMarine": "\n  AppTick = 10\n  FORCE_X = 0.3\n  prefix = NAV",
              "pMarinePID": "\n  sim_instability = 20\n  depth_control = false",
              "pNodeReporter": "\n  rider = BATTERY\n  vessel_type = UUV"}
    mission = write_mission(tmp_path, free_port(), blocks)
    for app in (SimMarine(mission), MarinePID(mission), NodeReporter(mission)):
        app.on_startup()
    assert "vehicle.moos:11: unhandled parameter 'FORCE_X'" in caplog.text
    assert "vehicle.moos:17: unhandled parameter 'sim_instability'" in caplog.text
    assert "vehicle.moos:23: unhandled parameter 'rider'" in caplog.text
    assert "prefix" not in caplog.text and "AppTick" not in caplog.text and "vessel_type" not in caplog.text


def test_manual_override_mail_is_a_moos_boolean(tmp_path, free_port):
    """MOOS_MANUAL_OVERRIDE by the one boolean rule: FALSE, off or 0 hand control over; TRUE, on or 1 take it
    back; any other word changes nothing."""
    pid = MarinePID(write_mission(tmp_path, free_port()), "pMarinePIDV22")
    pid.on_startup()
    now = pid.moos_time()
    states = []
    for word in ("FALSE", "garbage", "on", "0", "maybe", "1"):
        pid.on_new_mail([MOOSMsg.notification("MOOS_MANUAL_OVERRIDE", word, time=now)])
        states.append(pid.overridden)
    assert states == [False, False, True, False, False, True]
