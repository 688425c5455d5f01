"""Fleet safety in missions/oilspill (issue 15): every vessel avoids the others and watches its
operating area, the shoreside relays reports with limited range and judges collisions.

The mission files pass moos-lint; the behaviour file on the helm engine alone spawns an avoidance
behaviour per contact and all-stops on leaving the operating area; a running three-vessel mission
with a short comms range shows the vessels hearing each other only through uFldNodeComms, an
out-of-range vessel retired like a silent one, and the brokers and pPathAssign carrying on.
"""
import pytest

from behaviors.lint import main as moos_lint
from helpers import wait_until
from moosdb_py.alog import read_alog
from moosdb_py.client import MOOSClient
from moosdb_py.mission import read_mission
from oilspill_moos.forecaster.push import push_lines
from oilspill_moos.oilspill_mission import MISSION_DIR, OilspillMission
from oilspill_moos.response.path_assign import OIL_PATH
from mission_run import VehicleHelm, deployed

VEHICLE_DEFINES = ["VNAME=abe", "START_POS=0,0", "MOOS_PORT=9001", "PSHARE_PORT=9201"]


@pytest.mark.parametrize("extra", [[], ["FEEDBACK=true", "COMMS_SEED=3", "AVOID=false", "COMMS_LOSS=hold"]])
def test_mission_files_pass_moos_lint(extra, monkeypatch, capsys):
    monkeypatch.chdir(MISSION_DIR)
    defines = [arg for d in VEHICLE_DEFINES + extra for arg in ("-D", d)]
    assert moos_lint(["meta_vehicle.moos", "meta_vehicle.bhv", "meta_shoreside.moos", *defines]) == 0
    assert capsys.readouterr().out == ""


def test_vessels_run_the_contact_manager_and_the_shore_the_relay_and_the_judge(tmp_path):
    mission = OilspillMission(tmp_path, vehicles=2)
    shore_file, *vehicle_files = mission.generate()
    shore = read_mission(shore_file)
    assert {"uFldNodeComms", "uFldCollisionDetect"} <= {r.exe for r in shore.antler.runs}
    assert any("NODE_REPORT" in [v.strip() for v in q.split(",")]
               for q in shore.process_config("uFldShoreBroker").get_all("qbridge"))
    for path in vehicle_files:
        vehicle = read_mission(path)
        assert "pContactMgrV20" in {r.exe for r in vehicle.antler.runs}
        bhv = (tmp_path / f"targ_{vehicle.community}.bhv").read_text()
        assert "BHV_AvoidCollision" in bhv and "templating = spawn" in bhv and "BHV_OpRegion" in bhv


def test_contact_info_spawns_an_avoidance_behaviour_per_vessel(tmp_path):
    v = VehicleHelm(tmp_path)
    request = v.last("BCM_ALERT_REQUEST")
    assert request and "id=avd_" in request and "alert_range=50" in request and "cpa_range=60" in request
    v.mail(DEPLOY="true", SHORE_HEARTBEAT="true")
    v.run(1)
    v.mail(NODE_REPORT="NAME=ben,X=0,Y=30,SPD=2,HDG=180,TIME=1", CONTACT_INFO="name=ben # contact=ben")
    v.run(1)
    spawned = [value for key, value, _ in v.posts if key == "IVPHELM_LIFE_EVENT" and "event=spawn" in value]
    assert len(spawned) == 1 and "bname=avd_ben" in spawned[0]
    assert v.last("RANGE_AVD_BEN") == pytest.approx(30, abs=10)


def test_leaving_the_operating_area_all_stops_with_the_reason(tmp_path):
    v = VehicleHelm(tmp_path, OP_REGION_RADIUS="500")
    v.mail(DEPLOY="true", SHORE_HEARTBEAT="true", STATION_KEEP="false", OILSPILL_PHASE="OIL-PATH",
           OIL_PATH_UPDATES="points=100,0:100,100:0,100:0,0#repeat=forever")
    v.run(3)
    assert v.last("BHV_ERROR") is None and v.last("DESIRED_SPEED") > 0
    v.at(700, 0)   # beyond the octagon of radius 500 about the origin
    v.run(3)
    assert "BHV_OpRegion Polygon containment failure" in v.last("BHV_ERROR")
    assert v.last("IVPHELM_ALLSTOP") == "BehaviorError" and v.last("DESIRED_SPEED") == 0


# ---- a running mission with a short comms range ---------------------------------------------

WARP = 10.0
TIMEOUT = 40.0
COMMS_RANGE = 45.0   # the start line is 30 m apart: abe hears ben, not cal (60 m)
SPILL = "pts={-30,60:30,60:30,120:-30,120},label=test-spill\n"   # loop starts ~107 m apart


class VesselWatch:
    """A MOOS client on one vessel's MOOSDB keeping what its contact manager and helm post."""

    KEYS = ("NODE_REPORT", "CONTACTS_LIST", "CONTACTS_RETIRED", "IVPHELM_LIFE_EVENT", "BHV_ERROR")

    def __init__(self, port: int):
        self.mail = []
        self.client = MOOSClient("uSafetyWatch", "127.0.0.1", port, on_mail=self.mail.extend,
                                 on_connect=self.on_connect, time_warp=WARP)

    def on_connect(self):
        for key in self.KEYS:
            self.client.register(key)

    def values(self, key):
        return [str(m.value) for m in list(self.mail) if m.key == key]


def test_vessels_hear_each_other_only_in_range_and_the_fleet_carries_on(tmp_path):
    mission = OilspillMission(tmp_path, vehicles=3, warp=WARP, standoff=10.0, node_timeout=40.0,
                              extra={"COMMS_RANGE": f"{COMMS_RANGE:g}", "CRITICAL_RANGE": "20", "COMMS_DROP": "20",
                                     "COMMS_SEED": "1", "CONTACT_MAX_AGE": "20"})
    abe = VesselWatch(mission.fleet["abe"].moos_port)
    with deployed(mission, (abe.client,), TIMEOUT) as (observer, _):
        # on the start line abe hears ben (30 m) through uFldNodeComms, never cal (60 m)
        wait_until(lambda: "ben" in abe.values("CONTACTS_LIST"), timeout=TIMEOUT)
        wait_until(lambda: any("bname=avd_ben" in e and "event=spawn" in e for e in abe.values("IVPHELM_LIFE_EVENT")),
                   timeout=TIMEOUT)
        senders = {r.split("NAME=", 1)[1].split(",", 1)[0].lower() for r in abe.values("NODE_REPORT") if "NAME=" in r}
        assert senders == {"ben"}, senders
        # the brokers and pPathAssign carry on: every vessel to its start and round the loop, nobody dropped
        assert push_lines([SPILL.encode()], port=mission.boundary_port) == [1]
        wait_until(lambda: observer.phase_count.get(OIL_PATH, 0) >= 1, timeout=TIMEOUT)
        # out of range on the loop, ben falls silent for abe: retired, and its avoidance behaviour ends
        wait_until(lambda: any("ben" in v.split(",") for v in abe.values("CONTACTS_RETIRED")), timeout=TIMEOUT)
        wait_until(lambda: any("bname=avd_ben" in e and "event=death" in e for e in abe.values("IVPHELM_LIFE_EVENT")),
                   timeout=TIMEOUT)
        assert not observer.dropped and "planned=3" in observer.status
        assert abe.values("BHV_ERROR") == []
    shore = read_alog(mission.alog("shoreside"))
    assert not any(total > 0 for total in shore.values("COLLISION_TOTAL"))   # posted at the first event
    assert min(v for v in shore.values("UCD_CLOSEST_RANGE") if isinstance(v, float)) > 3.0
