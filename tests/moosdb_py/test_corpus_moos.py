"""Every .moos of the shared corpus parses, and the facts its README lists come out of the reader."""
import pytest

from helpers import CORPUS, requires_shared
from moosdb_py.mission import read_mission

pytestmark = requires_shared("missions-corpus")

# The macro values the missions' launch scripts give nsplug (README table).
SHORE = dict(WARP="1", IP_ADDR="localhost", MOOS_PORT="9000", PSHARE_PORT="9200")
LAUNCH = {
    ("ufld_alpha", "meta_shoreside.moos"): SHORE,
    ("ufld_alpha", "meta_vehicle.moos"): dict(WARP="1", VNAME="abe", MOOS_PORT="9001", PSHARE_PORT="9201",
                                              START_POS="0,0", SHORE_IP="localhost", SHORE_PSHARE="9200",
                                              IP_ADDR="localhost"),
    ("m2_berta", "meta_shoreside.moos"): dict(SHORE, LAUNCH_GUI=None, MMOD=None, VNAMES="abe:ben"),
    ("m2_berta", "meta_vehicle.moos"): dict(WARP="1", IP_ADDR="localhost", MOOS_PORT="9001", PSHARE_PORT="9201",
                                            SHORE_IP="localhost", SHORE_PSHARE="9200", VNAME="abe", COLOR="yellow",
                                            XMODE="SIM", START_POS="x=0,y=0,heading=0", MAX_SPD="2"),
    ("minicourse_lab_henry_gilda_baseline", "meta_vehicle.moos"): dict(
        WARP="1", VNAME="gilda", START_POS="0,0", VPORT="9001", PSHARE_PORT="9201", VTYPE="kayak",
        SHORE_IP="localhost", SHORE_PSHARE="9200", IP_ADDR="localhost"),
    ("minicourse_lab_henry_gilda_baseline", "meta_shoreside.moos"): dict(
        WARP="1", VNAME="shoreside", PSHARE_PORT="9200", VPORT="9000", IP_ADDR="localhost"),
}
ALL_MOOS = sorted(str(p.relative_to(CORPUS)) for p in CORPUS.glob("*/*.moos"))


def read(folder, name, monkeypatch, **extra):
    monkeypatch.chdir(CORPUS / folder)
    return read_mission(name, {**LAUNCH.get((folder, name), {}), **extra})


def runs(m):
    return [r.moos_name for r in m.antler.runs]


@pytest.mark.parametrize("relative", ALL_MOOS)
def test_every_corpus_file_parses_with_and_without_launch_macros(relative, monkeypatch):
    folder, name = relative.split("/")
    m = read(folder, name, monkeypatch)
    if (folder, name) in LAUNCH or not name.startswith(("meta_", "plug")):
        m.check()   # fully expanded: every global converts
    assert m.warnings == []
    monkeypatch.chdir(CORPUS / folder)
    # moos-lint's case, no -D: still parses; only #ifdef-guarded blocks (XMODE) may be missing
    assert {b.name for b in read_mission(name).blocks} <= {b.name for b in m.blocks}


def test_s1_alpha(monkeypatch):
    m = read("s1_alpha", "alpha.moos", monkeypatch)
    assert (m.server_host, m.server_port, m.community, m.time_warp) == ("localhost", 9000, "alpha", 1.0)
    assert (m.lat_origin, m.long_origin) == (43.8253, -70.3304)
    assert m.antler.ms_between_launches == 200
    assert runs(m) == ["MOOSDB", "pLogger", "uSimMarineV22", "pMarinePIDV22", "pHelmIvP", "pMarineViewer",
                       "uProcessWatch", "pNodeReporter", "pRealm"]
    assert not any(r.new_console for r in m.antler.runs)
    helm = m.process_config("pHelmIvP")
    assert helm.get("behaviors") == "alpha.bhv" and helm.get_all("domain") == ["course:0:359:360", "speed:0:4:41"]
    sim = m.process_config("uSimMarineV22")
    assert sim.get("start_pos") == "x=0, y=-20, heading=180, speed=0"
    assert (sim.get("prefix"), sim.get("turn_rate"), sim.get("turn_spd_loss")) == ("NAV", "95", "0.4")
    assert sim.entry("thrust_map").moos_value == "0:0,20:1,40:2,60:3,80:4,100:5"
    pid = m.process_config("pMarinePIDV22")
    assert [pid.get(k) for k in ("yaw_pid_kp", "yaw_pid_kd", "yaw_pid_ki", "speed_factor", "depth_control")] == \
        ["0.9", "0.3", "0.3", "20", "false"]


def test_minicourse_s2_alpha_uses_the_older_app_names(monkeypatch):
    m = read("minicourse_s2_alpha", "alpha.moos", monkeypatch)
    assert runs(m)[:4] == ["MOOSDB", "pLogger", "uSimMarine", "pMarinePID"]
    assert m.process_config("uSimMarine") is not None and m.process_config("pMarinePID") is not None


def test_station_keep_uuv(monkeypatch):
    m = read("station-keep-uuv", "davis.moos", monkeypatch)
    assert m.community == "davis" and m.antler is not None and runs(m)[0] == "MOOSDB"
    helm = m.process_config("pHelmIvP")
    assert helm.get("behaviors") == "davis.bhv"
    assert helm.get_all("domain") == ["course:0:359:360", "speed:0:5:26", "depth:0:100:101:optional"]
    viewer = " ".join(e.value for e in m.process_config("pMarineViewer").entries)
    assert "$(XPOS)" in viewer   # viewer macros are not nsplug's


@pytest.mark.parametrize("xmode,app", [("SIM", "uSimMarineV22"), ("M300", "iM300")])
def test_m2_berta_vehicle(xmode, app, monkeypatch):
    m = read("m2_berta", "meta_vehicle.moos", monkeypatch, XMODE=xmode)
    assert runs(m) == ["MOOSDB", "uProcessWatch", "pShare", "pLogger", "pNodeReporter", "pMarinePIDV22", "pHelmIvP",
                       "pHostInfo", "uFldNodeBroker", "uLoadWatch", "uMemWatch", "pContactMgrV20", "pRealm", app]
    assert (m.community, m.server_port, m.antler.ms_between_launches) == ("abe", 9001, 50)
    broker = m.process_config("uFldNodeBroker")
    assert broker.get("try_shore_host") == "pshare_route=localhost:9200"
    assert [e.moos_value for e in broker.entries if e.key == "bridge"] == [
        "src=VIEW_POLYGON", "src=VIEW_CIRCLE", "src=VIEW_POINT", "src=VIEW_SEGLIST",
        "src=NODE_REPORT_LOCAL,alias=NODE_REPORT", "src=NODE_MESSAGE_LOCAL,alias=NODE_MESSAGE"]
    assert (m.process_config("uSimMarineV22") is not None) == (xmode == "SIM")
    assert m.process_config("pLogger").get("File") == "LOG_ABE"
    assert m.process_config("pHelmIvP").get_all("domain") == ["course:0:359:360", "speed:0:2:21"]


def test_m2_berta_shoreside(monkeypatch):
    m = read("m2_berta", "meta_shoreside.moos", monkeypatch)
    broker = m.process_config("uFldShoreBroker")
    qbridges = [v.strip() for q in broker.get_all("qbridge") for v in q.split(",")]
    assert qbridges == ["DEPLOY", "RETURN", "STATION_KEEP", "NODE_REPORT", "NODE_MESSAGE", "MOOS_MANUAL_OVERRIDE",
                        "AVOID", "UP_LOITER", "RETURN_UPDATES", "BCM_DISPLAY_RADII", "CONTACT_INFO",
                        "NODE_GROUP_UPDATE", "BHV_ABLE_FILTER"]
    assert broker.entry("bridge").moos_value == "src=MISSION_HASH,alias=MISSION_HASH"
    assert len(broker.get_all("bridge")) == 4


def test_ufld_alpha_vehicle(monkeypatch):
    m = read("ufld_alpha", "meta_vehicle.moos", monkeypatch)
    assert runs(m) == ["MOOSDB", "pRealm", "uSimMarineV22", "pMarinePIDV22", "pLogger", "pNodeReporter", "pHelmIvP",
                       "uProcessWatch", "pShare", "pHostInfo", "uFldNodeBroker"]
    broker = m.process_config("uFldNodeBroker")
    assert broker.get("try_shore_host") == "pshare_route=localhost:9200"
    assert [e.moos_value for e in broker.entries if e.key == "bridge"] == [
        "src=VIEW_POLYGON", "src=VIEW_POINT", "src=VIEW_SEGLIST", "src=APPCAST", "src=NODE_PSHARE_VARS",
        "src=NODE_REPORT_LOCAL,alias=NODE_REPORT", "src=NODE_MESSAGE_LOCAL,alias=NODE_MESSAGE"]
    assert m.process_config("pHelmIvP").get("behaviors") == "targ_abe.bhv"
    assert m.process_config("pLogger").get("File") == "LOG_ABE"
    # spec 3.6: the tagged include brings both origins; MOOS's first-match lookup picks the pavlab one
    assert (m.lat_origin, m.long_origin) == (42.358436, -71.087448)


def test_ufld_alpha_without_macros_keeps_them_unexpanded(monkeypatch):
    monkeypatch.chdir(CORPUS / "ufld_alpha")
    broker = read_mission("meta_vehicle.moos").process_config("uFldNodeBroker")
    assert broker.get("try_shore_host") == "pshare_route=$(SHORE_IP):$(SHORE_PSHARE)"


def test_ufld_alpha_shoreside(monkeypatch):
    broker = read("ufld_alpha", "meta_shoreside.moos", monkeypatch).process_config("uFldShoreBroker")
    qbridges = [v.strip() for q in broker.get_all("qbridge") for v in q.split(",")]
    assert qbridges == ["DEPLOY", "NODE_REPORT", "NODE_MESSAGE", "STATION_KEEP", "APPCAST_REQ", "MOOS_MANUAL_OVERRIDE"]
    assert [e.moos_value for e in broker.entries if e.key == "bridge"] == [
        "src=RETURN_ALL,alias=RETURN", "src=RETURN_$V,alias=RETURN", "src=REGION_INFO,alias=REGION_INFO",
        "src=MISSION_HASH"]


@pytest.mark.parametrize("vname,meta", [("gilda", "meta_vehicle.moos"), ("shoreside", "meta_shoreside.moos")])
def test_baseline_meta_reads_like_its_real_nsplug_output(vname, meta, monkeypatch):
    folder = "minicourse_lab_henry_gilda_baseline"
    m = read(folder, meta, monkeypatch, WARP="10")
    target = read_mission(f"targ_{vname}.moos")

    def view(mission):
        return mission.globals, [(b.name, [(e.key, e.value) for e in b.entries]) for b in mission.blocks]

    assert view(m) == view(target)
    assert m.community == vname and m.time_warp == 10
