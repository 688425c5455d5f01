"""The project's oil-spill vehicle .bhv (missions/oilspill) through the helm engine, no MOOS.

Checks the phase protocol of the architecture page from the vehicle's side: station keeping,
starting position with its endflags, the looping oil path, and the comms-loss watchdog.
"""
import math
from pathlib import Path

import pytest

from behaviors.bhv_file import parse_bhv
from behaviors.helm import Helm
from moosdb_py.nsplug import preprocess

from helm_sim import Boat, run

MISSION = Path(__file__).resolve().parents[2] / "missions" / "oilspill" / "meta_vehicle.bhv"


@pytest.fixture
def vehicle(domain):
    if not MISSION.is_file():
        pytest.skip("oil-spill mission not present")
    helm = Helm([parse_bhv(preprocess(MISSION, {"START_POS": "0,0", "COMMS_TIMEOUT": "60"}), MISSION)],
                domain, "abe", active_start=True)
    helm.startup(0.0)
    return helm


def values(log, var, since=0.0):
    return [val for t, v, val in log if v == var and t >= since]


def test_phases_from_the_vehicle_side(vehicle):
    boat, log = Boat(30, -40, 0), []
    beat = {float(t): {"SHORE_HEARTBEAT": "true"} for t in range(2, 1000, 20)}
    t = run(vehicle, boat, 30, dt=0.5, pokes={**beat, 1.0: {"DEPLOY": "true"}}, log=log)
    assert values(log, "MODE") == ["ACTIVE:STATION-KEEPING"]
    assert math.hypot(boat.x - 30, boat.y + 40) < 5          # held where it was (center_activate)
    pokes = {**beat, t: {"STATION_KEEP": "false", "OILSPILL_PHASE": "STARTING-POSITION",
                         "STARTING_POSITION_UPDATES": "points=80,20"}}
    t = run(vehicle, boat, 90, dt=0.5, start=t, pokes=pokes, log=log)
    assert values(log, "REACHED_STARTING_POSITION") == ["true"]
    assert values(log, "MODE")[-2:] == ["ACTIVE:STARTING-POSITION", "ACTIVE:STATION-KEEPING"]
    assert math.hypot(boat.x - 80, boat.y - 20) < 10
    loop = "points=80,20:80,-60:0,-60:0,20 # repeat=forever"
    start_loop = t
    pokes = {**beat, t: {"STATION_KEEP": "false", "OILSPILL_PHASE": "OIL-PATH", "OIL_PATH_UPDATES": loop}}
    t = run(vehicle, boat, 300, dt=0.5, start=t, pokes=pokes, log=log)
    assert values(log, "MODE", since=start_loop) == ["ACTIVE:OIL-PATH"]
    cycles = [v for v in values(log, "WPT_STAT", since=start_loop) if str(v).endswith(",cycled")]
    assert len(cycles) >= 2                                    # loops, never completes
    assert values(log, "COMMS_LOST") == []
    run(vehicle, boat, 200, dt=0.5, start=t, log=log)                  # the shore goes silent
    assert values(log, "COMMS_LOST") == ["true"]
    assert values(log, "MODE")[-2:] == ["ACTIVE:RETURNING", "INACTIVE"]   # home: endflag DEPLOY=false
    assert math.hypot(boat.x, boat.y) < 6
