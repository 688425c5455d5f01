"""Issue 15's four-vehicle MOOS-IvP loiter mission (corpus m2_berta with the deprecated uSimMarine and
pMarinePID and BHV_AvoidCollision live; tests/corpus_loiter.py): nsplug and pAntler launch every
community; every app of the Run lists runs except the two MOOS-IvP utilities this project does not
have; the helm takes BHV_AvoidCollision and asks pContactMgrV20 for its alerts; the vessels deploy and
move. Distances against C++ are benchmarks/loiter_mission_bench.py's."""
from __future__ import annotations

import asyncio
import re

from helpers import requires_shared

pytestmark = requires_shared("missions-corpus")

from corpus_loiter import LoiterMission, distances, fly  # noqa: E402  (imports ../shared paths)
from moosdb_py.alog import read_alog  # noqa: E402
from moosdb_py.mission import read_mission  # noqa: E402

FLIGHT_S = 40.0


def test_the_loiter_mission_launches_every_app_and_the_vessels_move(tmp_path):
    mission = LoiterMission(tmp_path, warp=10, deprecated=True, avoid=True)
    with mission:
        flown = asyncio.run(fly(mission, FLIGHT_S))
    for c in mission.communities:
        runs = {r.moos_name for r in read_mission(tmp_path / f"targ_{c.name}.moos").antler.runs} - {"MOOSDB"}
        unlaunched = set(re.findall(r"cannot launch (\S+):", mission.antler_log(c.name)))
        assert not unlaunched, (c.name, unlaunched)
        assert runs <= flown["clients"][c.name], (c.name, sorted(runs - flown["clients"][c.name]))
    assert {"uFldNodeComms", "pRealm"} <= flown["clients"]["shoreside"]
    spawned = 0
    for v in mission.fleet.values():
        assert {"pContactMgrV20", "pRealm", "uSimMarine", "pMarinePID"} <= flown["clients"][v.name]
        alog = read_alog(mission.alog(v.name))
        assert any(str(r).startswith("id=ac_,") for r in alog.values("BCM_ALERT_REQUEST")), v.name
        assert not alog.values("BHV_ERROR"), alog.values("BHV_ERROR")
        assert alog.values("PHELMIVP_MEM"), v.name     # uMemWatch measured the helm (watch_only = pHelmIvP)
        spawned += sum("event=spawn" in str(e) for e in alog.values("IVPHELM_LIFE_EVENT"))
        # the contacts' reports carry only LAT/LON (coord_policy_global): the helm must place them
        assert not [w for w in alog.values("BHV_WARNING") if "info not found" in str(w)], v.name
        assert "ACTIVE:LOITERING" in alog.values("MODE"), v.name
    assert spawned, "no BHV_AvoidCollision was spawned"
    moved = distances(mission, FLIGHT_S)
    assert all(d > 20.0 for d in moved.values()), moved      # 1.4 m/s less the start: about 40 m
