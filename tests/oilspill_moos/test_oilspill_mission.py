"""End to end: missions/oilspill with 3 vehicles under time warp, real processes on loopback ports
(two of the vessels hosted in one process).

One mission run is shared by the two tests (module fixture) to stay inside the time budget: the
first follows a boundary through every phase and checks the vehicles' alogs, the second kills a
vehicle during OIL-PATH, checks that the loop is re-shared between the other two, then brings it
back and checks that the loop is shared among three again.
"""
import asyncio
import math
import threading

import pytest

from helpers import wait_until
from moosdb_py.alog import read_alog
from moosdb_py.app import MOOSApp
from moosdb_py.message import MOOSMsg
from oilspill_moos.oilspill_mission import Community, OilspillMission, Observer, TickWatch
from oilspill_moos.forecaster.push import push_lines
from oilspill_moos.messages import parse_polygon_spec
from oilspill_moos.response.path_assign import OIL_PATH, STARTING_POSITION

WARP = 10.0
SPILL = "pts={-30,60:30,60:30,120:-30,120},label=test-spill\n"  # local metres, north of the start line
CAPTURE_RADIUS = 5.0  # the starting-position waypoint's, in meta_vehicle.bhv
TIMEOUT = 40.0        # wall seconds for any one step


@pytest.fixture(scope="module")
def running(tmp_path_factory):
    # The whole-loop mode (patrol = loop): these tests check the loop itself is re-shared; the arcs of the
    # default mode re-balance by the planner's own tests (test_planner.py, test_path_assign.py).
    # abe and ben hosted in one pAntler (--with), as the response demo hosts its vessels; cal alone, so
    # that killing it (below) takes no other vessel with it
    mission = OilspillMission(tmp_path_factory.mktemp("oilspill"), vehicles=3, warp=WARP, standoff=10.0,
                              node_timeout=40.0,  # 4 s of wall time: a loaded CI machine must not drop anyone
                              extra={"PATROL": "loop"}, vessels_per_process=2)
    assert [[c.name for c in group] for group in mission.processes()] == [["shoreside"], ["abe", "ben"], ["cal"]]
    mission.start()
    assert mission.fleet["abe"].process is mission.fleet["ben"].process is not mission.fleet["cal"].process
    loop = asyncio.new_event_loop()
    observer = Observer("127.0.0.1", mission.shoreside.moos_port, WARP)
    thread = threading.Thread(target=loop.run_until_complete, args=(observer.client.run(),), daemon=True)
    thread.start()
    try:
        wait_until(lambda: mission.dead() or observer.vehicles_seen() >= set(mission.fleet), timeout=TIMEOUT)
        assert not mission.dead(), f"communities stopped: {mission.dead()}"
        asyncio.run_coroutine_threadsafe(observer.deploy(mission.fleet, TIMEOUT, mission), loop).result(TIMEOUT + 5)
        yield mission, observer, loop  # loop: where the observer's client runs, for coroutines from the tests
    finally:
        loop.call_soon_threadsafe(observer.client.close)
        thread.join(timeout=5)
        mission.stop()


def mode_changes(alog_path):
    modes = []
    for entry in read_alog(alog_path).entries:
        if entry.key == "MODE" and (not modes or modes[-1] != entry.value):
            modes.append(entry.value)
    return modes


def test_three_vehicles_go_through_every_phase_and_keep_looping(running):
    mission, observer, _ = running
    assert push_lines([SPILL.encode()], port=mission.boundary_port) == [1]
    wait_until(lambda: observer.phase_count.get(OIL_PATH, 0) >= 1, timeout=TIMEOUT)
    looping_since = observer.moos_now
    wait_until(lambda: observer.moos_now - looping_since > 40, timeout=TIMEOUT)  # 40 mission seconds of loop
    assert observer.phase_count.get(STARTING_POSITION) == 1 and not observer.dropped
    for name in mission.fleet:
        wait_until(lambda: "ACTIVE:OIL-PATH" in mode_changes(mission.alog(name)), timeout=TIMEOUT)
        alog = read_alog(mission.alog(name))
        modes = mode_changes(mission.alog(name))
        order = [modes.index(m) for m in ("ACTIVE:STATION-KEEPING", "ACTIVE:STARTING-POSITION", "ACTIVE:OIL-PATH")]
        assert order == sorted(order), f"{name}: modes in the wrong order: {modes}"
        start = parse_polygon_spec("pts={" + str(alog.values("STARTING_POSITION_UPDATES")[-1]).split("=", 1)[1] + "}")[-1]
        xs, ys = alog.values("NAV_X"), alog.values("NAV_Y")
        closest = min(math.hypot(x - start[0], y - start[1]) for x, y in zip(xs, ys))
        assert closest <= CAPTURE_RADIUS + 1.0, f"{name} came no closer than {closest:.1f} m to its start"
        loop = observer.loops[name]
        assert len(loop) >= 4 and loop[0] == pytest.approx(start, abs=0.1)
        assert alog.values("MODE")[-1] == "ACTIVE:OIL-PATH"
        hits = [v for v in alog.values("WPT_INDEX") if isinstance(v, float)]
        assert hits and max(hits) >= 1, f"{name} has not advanced along its loop"


def test_vehicle_killed_in_oil_path_is_dropped_reshared_and_rejoins(running):
    mission, observer, loop = running
    if observer.phase_count.get(OIL_PATH, 0) == 0:
        assert push_lines([SPILL.encode()], port=mission.boundary_port)
        wait_until(lambda: observer.phase_count.get(OIL_PATH, 0) >= 1, timeout=TIMEOUT)
    loops_before = observer.phase_count[OIL_PATH]
    mission.stop(names=["cal"])
    wait_until(lambda: "cal" in observer.dropped, timeout=TIMEOUT)
    wait_until(lambda: observer.phase_count.get(OIL_PATH, 0) > loops_before, timeout=TIMEOUT)
    wait_until(lambda: "planned=2" in observer.status, timeout=TIMEOUT)
    starts = [observer.loops[name][0] for name in ("abe", "ben")]
    region = observer.regions[-1]
    perimeter = sum(math.dist(region[i], region[(i + 1) % len(region)]) for i in range(len(region)))
    # two vehicles on one loop: their starts are half a perimeter apart along it, so far apart in the plane
    assert math.dist(*starts) > perimeter / 6

    # cal comes back (a fresh community from its base): pPathAssign re-shares the loop among three
    loops_before = observer.phase_count[OIL_PATH]
    mission.launch(mission.fleet["cal"])
    wait_until(lambda: any(e["event"] == "rejoined" and e["what"] == "cal" for e in observer.events), timeout=TIMEOUT)
    observer.modes.pop("cal", None)  # its old report still says OIL-PATH; the operator deploys it again
    asyncio.run_coroutine_threadsafe(observer.deploy(["cal"], TIMEOUT, mission), loop).result(TIMEOUT)
    wait_until(lambda: observer.phase_count.get(OIL_PATH, 0) > loops_before and "planned=3" in observer.status,
               timeout=TIMEOUT)


def test_the_tick_watch_reads_the_app_statuses_of_every_community(running):
    """TickWatch on the running mission (what the response demo's summary uses): every hosted app of a
    vessel and of the shoreside, its ticks counted from the first status the watch saw."""
    mission, _, loop = running
    watch = TickWatch([mission.shoreside, mission.fleet["abe"]], WARP)
    loop.call_soon_threadsafe(watch.start)
    wanted = {("abe", "pHelmIvP"), ("abe", "pLogger"), ("abe", "pNodeReporter"), ("shoreside", "pPathAssign"),
              ("shoreside", "pShare")}
    try:
        # two statuses of each (they come every 2 s): ticks counted between them
        wait_until(lambda: all(dict(watch.last).get(app, (0, 0))[0] > dict(watch.first).get(app, (1e9, 0))[0]
                               for app in wanted), timeout=TIMEOUT)
        assert {c for c, _ in dict(watch.last)} == {"abe", "shoreside"}

        async def behind():     # in the loop that feeds the watch
            return watch.behind()
        late = asyncio.run_coroutine_threadsafe(behind(), loop).result(5)
        assert all(b["community"] in ("abe", "shoreside") and b["due"] > 0 for b in late)
    finally:
        asyncio.run_coroutine_threadsafe(watch.close(), loop).result(10)


# ---- the vehicle behaviour file on the helm engine alone (no processes) ----------------------

from mission_run import VehicleHelm  # noqa: E402


def test_vehicle_modes_follow_the_shore_and_the_arrival_flag(tmp_path):
    v = VehicleHelm(tmp_path).run(2)
    assert v.last("MODE") == "INACTIVE"
    v.mail(DEPLOY="true", SHORE_HEARTBEAT="true")
    assert v.run(2).last("MODE") == "ACTIVE:STATION-KEEPING"
    v.mail(STARTING_POSITION_UPDATES="points=100,0", STATION_KEEP="false", OILSPILL_PHASE="STARTING-POSITION")
    assert v.run(1).last("MODE") == "ACTIVE:STARTING-POSITION"
    assert v.last("DESIRED_SPEED") == pytest.approx(2.5)
    v.at(98, 0)
    v.run(1)
    assert v.last("REACHED_STARTING_POSITION") == "true"
    assert v.last("MODE") == "ACTIVE:STATION-KEEPING"  # holds its point until everyone has arrived
    v.mail(OIL_PATH_UPDATES="points=100,0:100,100:0,100:0,0#repeat=forever", STATION_KEEP="false",
           OILSPILL_PHASE="OIL-PATH", SHORE_HEARTBEAT="true")
    assert v.run(1).last("MODE") == "ACTIVE:OIL-PATH"
    assert v.last("DESIRED_SPEED") == pytest.approx(2.0)
    v.mail(RETURN="true")
    assert v.run(1).last("MODE") == "ACTIVE:RETURNING"


def test_comms_watchdog_returns_or_holds_when_the_heartbeat_stops(tmp_path):
    for action, mode in (("return", "ACTIVE:RETURNING"), ("hold", "ACTIVE:STATION-KEEPING")):
        v = VehicleHelm(tmp_path, COMMS_TIMEOUT="20", COMMS_LOSS=action)
        v.mail(DEPLOY="true", STATION_KEEP="false", OILSPILL_PHASE="OIL-PATH",
               OIL_PATH_UPDATES="points=100,0:100,100:0,100:0,0#repeat=forever")
        for _ in range(5):  # heartbeats keep the watchdog quiet
            v.mail(SHORE_HEARTBEAT="true")
            v.run(10)
        assert v.last("MODE") == "ACTIVE:OIL-PATH" and v.last("COMMS_LOST") == "false"
        v.at(100, 50)  # out on the loop, away from base
        v.run(25)  # silence for longer than COMMS_TIMEOUT
        assert v.last("COMMS_LOST") == "true"
        assert v.last("MODE") == mode, action


def _status(name: str, iterations: int, missed: int, community: str = "") -> MOOSMsg:
    """The <NAME>_STATUS an app with these counts posts (MOOSApp.status itself)."""
    app = MOOSApp(name=name)
    app.iterations, app.ticks_missed = iterations, missed
    msg = MOOSMsg.notification(f"{name.upper()}_STATUS", app.status(), time=0.0, source=name)
    msg.community = community
    return msg


def test_the_tick_watch_names_apps_that_missed_over_2_percent_of_their_appticks_since_it_started():
    watch = TickWatch([Community("abe", 1, {}), Community("shoreside", 2, {})], 10.0)
    watch.on_mail("abe", [_status("pLogger", 50, 40), _status("pHelmIvP", 50, 0), _status("uSimMarine", 50, 0)])
    watch.on_mail("shoreside", [_status("pShare", 10, 0), _status("pHelmIvP", 60, 9, community="abe")])
    assert watch.behind() == []     # 40 ticks missed before the first status seen: the launch, not counted
    watch.on_mail("abe", [_status("pLogger", 142, 48), _status("pHelmIvP", 148, 2), _status("uSimMarine", 150, 3)])
    watch.on_mail("shoreside", [_status("pShare", 110, 2), _status("pHelmIvP", 60, 90, community="abe")])
    # pLogger: 8 of 100 due; pHelmIvP 2 of 100 and pShare 2 of 102 (not over 2 %); uSimMarine 3 of 103; the
    # shoreside's copy of abe's helm status (pShare) is abe's, not the shoreside's
    assert watch.behind() == [{"community": "abe", "app": "pLogger", "missed": 8, "due": 100},
                              {"community": "abe", "app": "uSimMarine", "missed": 3, "due": 103}]
