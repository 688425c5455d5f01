"""pContactMgrV20: ranges, CPA and dead reckoning on hand-computed cases; alert triggering (once per
approach, off when leaving, again after retirement); the summary postings; the mission-file shell."""
from __future__ import annotations

import math

import pytest
from hypothesis import given, strategies as st

from moosdb_py.source import MissionFileError
from oilspill_moos.marine.contact_mgr import (
    Alert, AlertError, BasicContactMgr, ContactManager, ContactMgr, ContactMgrParams)
from behaviors.contacts import NodeRecord, cpa_range

AVOID_REQUEST = 'id=avd, var=CONTACT_INFO, val="name=avd_$[VNAME] # contact=$[VNAME]", alert_range=80, cpa_range=100'


def manager(**config) -> ContactManager:
    return ContactManager("abe", ContactMgrParams.from_config({k: str(v) for k, v in config.items()}))


def report(name="ben", x=0.0, y=0.0, hdg=0.0, spd=0.0, time=None, **extra) -> str:
    fields = [f"NAME={name}", f"X={x:g}", f"Y={y:g}", f"SPD={spd:g}", f"HDG={hdg:g}"]
    fields += [f"{k.upper()}={v}" for k, v in extra.items()]
    return ",".join(fields + ([f"TIME={time:g}"] if time is not None else []))


def values(posts, key):
    return [v for k, v in posts if k == key]


# ---- geometry -------------------------------------------------------------------------------

@pytest.mark.parametrize("contact, own, expected", [
    ((100, 0, 270, 2), (0, 0, 0, 0), 0.0),        # coming straight at a still ownship
    ((0, 100, 90, 2), (0, 0, 0, 0), 100.0),       # crossing, already at its closest
    ((30, 40, 270, 1), (0, 0, 0, 0), 40.0),       # passes 40 m north after 30 s
    ((100, 0, 0, 1), (0, 0, 0, 1), 100.0),        # same course and speed: the range never changes
    ((0, 100, 180, 1), (0, 0, 0, 1), 0.0),        # head-on, closing at 2 m/s
    ((0, 100, 90, 2), (0, 0, 90, 2), 100.0),      # abreast, parallel
])
def test_cpa_range_hand_computed(contact, own, expected):
    cnx, cny, cnh, cnv = contact
    osx, osy, osh, osv = own
    assert cpa_range(osx, osy, osh, osv, cnx, cny, cnh, cnv, 36000) == pytest.approx(expected, abs=1e-9)


def test_cpa_range_stops_at_the_horizon():
    # head-on from 100 m at 2 m/s closing: after 20 s the range is 60 m
    assert cpa_range(0, 0, 0, 1, 0, 100, 180, 1, 20) == pytest.approx(60.0)


coord = st.floats(-1e4, 1e4, allow_nan=False)
heading = st.floats(0, 360, allow_nan=False, exclude_max=True)
speed = st.floats(0, 20, allow_nan=False)


@given(coord, coord, heading, speed, coord, coord, heading, speed, coord, coord, heading)
def test_cpa_is_unchanged_by_moving_and_turning_the_scene_and_never_above_the_range(
        osx, osy, osh, osv, cnx, cny, cnh, cnv, dx, dy, turn):
    base = cpa_range(osx, osy, osh, osv, cnx, cny, cnh, cnv, 36000)
    assert base <= math.hypot(osx - cnx, osy - cny) + 1e-6
    shifted = cpa_range(osx + dx, osy + dy, osh, osv, cnx + dx, cny + dy, cnh, cnv, 36000)
    rad = math.radians(turn)   # turning the plane clockwise adds `turn` to both headings

    def rotate(x, y):
        return x * math.cos(rad) + y * math.sin(rad), -x * math.sin(rad) + y * math.cos(rad)

    rotated = cpa_range(*rotate(osx, osy), (osh + turn) % 360, osv, *rotate(cnx, cny), (cnh + turn) % 360, cnv, 36000)
    scale = 1e-6 * (1 + abs(osx) + abs(osy) + abs(cnx) + abs(cny) + abs(dx) + abs(dy) + 36000 * (osv + cnv))
    assert shifted == pytest.approx(base, abs=scale)
    assert rotated == pytest.approx(base, abs=scale)


@pytest.mark.parametrize("elapsed, travelled", [(0, 0), (10, 20), (15, 30), (30, 45), (100, 45), (20, 30 + 2 * (5 - 25 / 30))])
def test_dead_reckoning_slows_linearly_between_the_decay_times(elapsed, travelled):
    """2 m/s east, decay = 15,30: full speed for 15 s, then the speed falls to 0 at 30 s (15 s at 1 m/s average)."""
    record = NodeRecord.parse("NAME=ben,X=10,Y=5,SPD=2,HDG=90")
    x, y = record.dead_reckoned(elapsed, 15, 30)
    assert (x, y) == (pytest.approx(10 + travelled), pytest.approx(5))


def test_node_report_reading():
    record = NodeRecord.parse("name=ben,x=1.5,y=-2,spd=1,hdg=370,depth=3,group=blue,type=kayak,utc_time=12.5")
    assert (record.name, record.x, record.y, record.heading, record.depth, record.group, record.time) == (
        "ben", 1.5, -2.0, 10.0, 3.0, "blue", 12.5)
    with pytest.raises(ValueError, match="without X/Y"):
        NodeRecord.parse("NAME=ben,LAT=43.8,LON=-70.3")   # no grid to place it
    with pytest.raises(ValueError, match="X: expected a number, got .ten."):
        NodeRecord.parse("NAME=ben,X=ten,Y=0")


# ---- alert configuration and the range test -------------------------------------------------

@pytest.mark.parametrize("actual, cpa, applies", [
    (100.0, 0.0, True),     # at the cpa_range, heading for a collision
    (100.5, 0.0, False),    # beyond cpa_range: never
    (90.0, 90.0, False),    # inside cpa_range, but passing wide
    (90.0, 80.0, True),     # passing within alert_range
    (70.0, 70.0, True),     # inside alert_range
])
def test_alert_range_test(actual, cpa, applies):
    alert = Alert("avd")
    alert.configure(["alert_range=80", "cpa_range=100", "on_flag=X=1"])
    assert alert.applies(actual, cpa) is applies


def test_alert_ranges_keep_their_order_and_off_leaves_only_filters():
    alert = Alert("a")
    alert.configure(["cpa_range=50", "alert_range=80"])   # alert_range raises cpa_range
    assert (alert.range, alert.cpa_range) == (80, 80)
    alert.configure(["cpa_range=30"])                      # cpa_range lowers alert_range
    assert (alert.range, alert.cpa_range) == (30, 30)
    alert.configure(["alert_range=off", "on_flag=SEEN=$[VNAME]"])
    assert alert.valid() and alert.applies(1e6, 1e6)
    assert not Alert("b").valid()                           # no range, no flags


def test_alert_lines_with_the_same_id_add_up_and_var_val_make_an_on_flag():
    mgr = manager()
    mgr.configure_alert('id=avd, var=CONTACT_INFO, val="name=$[VNAME] # contact=$[VNAME]"', "")
    mgr.configure_alert("id=avd, alert_range=15, cpa_range=5, off_flag=GONE=$[VNAME] # LEFT=1", "")
    alert = mgr.alerts["avd"]
    assert (alert.range, alert.cpa_range) == (5, 5)
    assert [(f.var, f.value) for f in alert.on_flags] == [("CONTACT_INFO", "name=$[VNAME] # contact=$[VNAME]")]
    assert [(f.var, f.value) for f in alert.off_flags] == [("GONE", "$[VNAME]"), ("LEFT", 1.0)]
    with pytest.raises(AlertError, match="unknown alert component 'colour'"):
        mgr.configure_alert("id=avd, colour=red", "")


# ---- the spawning trigger -------------------------------------------------------------------

def approach(mgr, start_x, hdg, spd, seconds, name="ben", t0=0.0):
    """The contact runs along y=0 from start_x; ownship stays at the origin. Posts per second."""
    out = []
    for t in range(seconds):
        now = t0 + t
        x = start_x + spd * t * math.sin(math.radians(hdg))
        mgr.on_mail("NODE_REPORT", report(name, x, 0, hdg, spd, time=now), now)
        out.append((now, x, mgr.iterate(now)))
    return out


def test_helm_alert_request_posts_contact_info_once_when_the_contact_enters_range_then_off_and_again():
    mgr = manager()
    mgr.on_mail("BCM_ALERT_REQUEST", AVOID_REQUEST + ", off_flag=AVOID_DONE=$[VNAME]", 0.0, "pHelmIvP")
    assert mgr.alerts["avd"].source == "pHelmIvP"
    inbound = approach(mgr, 200, 270, 2, 60)          # 200 m east, coming west at 2 m/s
    spawned = [(x, values(posts, "CONTACT_INFO")) for _, x, posts in inbound if values(posts, "CONTACT_INFO")]
    # CPA is 0, so the alert applies as soon as the range is within cpa_range (100 m): at x = 100
    assert spawned == [(100.0, ["name=avd_ben # contact=ben"])]
    outbound = approach(mgr, 80, 90, 2, 20, t0=60)     # turns away east: its CPA is now its range,
    assert [x for _, x, posts in outbound if values(posts, "AVOID_DONE") == ["ben"]] == [82.0]   # > alert_range
    assert not any(values(posts, "CONTACT_INFO") for _, _, posts in outbound)
    back = approach(mgr, 150, 270, 2, 40, t0=80)      # and back again: a second spawn
    assert [x for _, x, posts in back if values(posts, "CONTACT_INFO")] == [100.0]


def test_a_retired_contact_forgets_its_alert_and_is_alerted_again_when_it_returns():
    mgr = manager(contact_max_age=10)
    mgr.configure_alert(AVOID_REQUEST, "")
    mgr.on_mail("NODE_REPORT", report("ben", 50, 0, time=0), 0)
    assert values(mgr.iterate(0), "CONTACT_INFO") == ["name=avd_ben # contact=ben"]
    assert values(mgr.iterate(5), "CONTACT_INFO") == []
    posts = mgr.iterate(10.5)                           # silent for more than contact_max_age
    assert values(posts, "CONTACTS_RETIRED") == ["ben"] and values(posts, "CONTACTS_LIST") == [""]
    assert "ben" not in mgr.contacts and not mgr.alerted
    mgr.on_mail("NODE_REPORT", report("ben", 50, 0, time=20), 20)
    posts = mgr.iterate(20)
    assert values(posts, "CONTACT_INFO") == ["name=avd_ben # contact=ben"]
    assert values(posts, "CONTACTS_RETIRED") == [""]    # back from retirement


def test_alerts_wait_for_the_helm_when_asked():
    mgr = manager(hold_alerts_for_helm="true")
    mgr.configure_alert(AVOID_REQUEST, "")
    mgr.on_mail("NODE_REPORT", report("ben", 50, 0, time=0), 0)
    assert values(mgr.iterate(0), "CONTACT_INFO") == []
    mgr.on_mail("IVPHELM_STATE", "PARK", 1)
    assert values(mgr.iterate(1), "CONTACT_INFO") == []
    mgr.on_mail("IVPHELM_STATE", "DRIVE", 2)
    assert values(mgr.iterate(2), "CONTACT_INFO") == ["name=avd_ben # contact=ben"]


def test_alert_filters_and_flag_macros():
    mgr = manager(ignore_name="cal")
    mgr.configure_alert("id=say, alert_range=off, match_group=blue, "
                        "on_flag=SAY=$[VNAME]/%[VNAME] $[VTYPE] $[GROUP] at $[X]:$[Y] hdg $[HDG] spd $[SPD]", "")
    for name, group in (("Ben", "blue"), ("cal", "blue"), ("dan", "red"), ("abe", "blue")):
        mgr.on_mail("NODE_REPORT", report(name, 1000.5, -3, 45, 1.5, time=0, group=group, type="Kayak"), 0)
    assert values(mgr.iterate(0), "SAY") == ["Ben/ben Kayak blue at 1000.5:-3 hdg 45 spd 1.5"]
    assert sorted(mgr.contacts) == ["Ben", "dan"]       # ownship (abe) and ignored cal are not contacts


def test_alert_verbose_names_the_transition():
    mgr = manager(alert_verbose="true")
    mgr.configure_alert(AVOID_REQUEST, "")
    mgr.on_mail("NODE_REPORT", report("ben", 36, 48, 270, 0, time=0), 0)
    assert values(mgr.iterate(0), "ALERT_VERBOSE") == [
        "contact=ben,alert_id=avd,off-->alerted,alert_range=80,alert_range_cpa=100,range_actual=60.0,range_cpa=60.0"]
    mgr.on_mail("NODE_REPORT", report("ben", 60, 80, 270, 0, time=1), 1)   # 100 m, still: passing wide
    assert values(mgr.iterate(1), "ALERT_VERBOSE") == [
        "contact=ben,alert_id=avd,alerted-->off,alert_range=80,alert_range_cpa=100,range_actual=100.0"]


# ---- reports --------------------------------------------------------------------------------

def test_summaries_closest_ranges_and_recap():
    mgr = manager(post_closest_range="true", post_closest_relbng="true", post_all_ranges="true", recap_interval=5)
    mgr.on_mail("NAV_HEADING", 90.0, 0)
    mgr.on_mail("NODE_REPORT", report("cal", 0, 30.7, time=0), 0)
    mgr.on_mail("NODE_REPORT", report("ben", 40, 0, time=0), 0)
    posts = mgr.iterate(0)
    assert values(posts, "CONTACTS_LIST") == ["ben,cal"]
    assert values(posts, "CONTACT_CLOSEST") == ["cal"] and values(posts, "CONTACT_CLOSEST_TIME") == [0]
    assert values(posts, "CONTACT_CLOSEST_RANGE") == [30.0]
    assert values(posts, "CONTACT_CLOSEST_RELBNG") == [270.0]     # north of a ship heading east: port beam
    assert values(posts, "CONTACT_RANGES") == ["30.7,40"]
    assert values(posts, "CONTACTS_RECAP") == ["vname=ben,range=40.00,age=0.00 # vname=cal,range=30.70,age=0.00"]
    assert values(posts, "CONTACTS_ALERTED") == [] and values(posts, "CONTACTS_COUNT") == []   # unchanged from none
    posts = mgr.iterate(3)                                          # nothing changed, recap not due
    assert [k for k, _ in posts] == ["CONTACT_RANGES"]
    assert values(mgr.iterate(5.5), "CONTACTS_RECAP") == ["vname=ben,range=40.00,age=5.50 # vname=cal,range=30.70,age=5.50"]


def test_report_request_lists_contacts_within_range_on_change():
    mgr = manager()
    mgr.on_mail("BCM_REPORT_REQUEST", "var=CONTACTS_50, range=50", 0)
    mgr.on_mail("NODE_REPORT", report("ben", 40, 0, time=0, group="blue"), 0)
    mgr.on_mail("NODE_REPORT", report("cal", 60, 0, time=0), 0)
    assert values(mgr.iterate(0), "CONTACTS_50") == ["ben"]
    assert values(mgr.iterate(1), "CONTACTS_50") == []
    mgr.on_mail("NODE_REPORT", report("cal", 45, 0, time=2), 2)
    assert values(mgr.iterate(2), "CONTACTS_50") == ["ben,cal"]
    mgr.on_mail("BCM_REPORT_REQUEST", "var=BLUE_50, range=50, group=blue", 3)
    assert values(mgr.iterate(3), "BLUE_50") == ["ben"]
    mgr.on_mail("BCM_REPORT_REQUEST", "range=50", 4, "pHelmIvP")
    assert mgr.warnings and "pHelmIvP" in mgr.warnings[-1]


def test_reject_range_and_max_contacts_retire():
    mgr = manager(reject_range=100, max_contacts=2)
    for name, x in (("far", 106), ("near", 10), ("mid", 50), ("edge", 104)):
        mgr.on_mail("NODE_REPORT", report(name, x, 0, time=0), 0)
    posts = mgr.iterate(0)
    assert values(posts, "CONTACTS_LIST") == ["mid,near"]   # far: beyond 105 m; edge: the farthest of 3 for 2 places
    assert values(posts, "CONTACTS_RETIRED") == ["far,edge"]


# ---- the app shell --------------------------------------------------------------------------

def write_mission(tmp_path, block, name="pContactMgrV20"):
    path = tmp_path / "abe.moos"
    path.write_text(f"ServerHost = localhost\nServerPort = 9000\nCommunity = abe\n\n"
                    f"ProcessConfig = {name}\n{{\n{block}\n}}\n")
    return path


def test_mission_block_alerts_with_quoted_values(tmp_path):
    mission = write_mission(tmp_path, '  alert = id=avdcol_, var=CONTACT_INFO, val="name=$[VNAME] # contact=$[VNAME]"\n'
                                      "  alert = id=avdcol_, alert_range=15, cpa_range=5\n  decay = 30,60\n"
                                      "  contact_max_age = 35\n  display_radii = true\n")
    app = ContactMgr(mission)
    app.on_startup()
    mgr = app.machine
    assert (mgr.ownship, mgr.params.decay, mgr.params.contact_max_age) == ("abe", (30.0, 60.0), 35.0)
    assert (mgr.alerts["avdcol_"].range, mgr.alerts["avdcol_"].cpa_range) == (5, 5)   # cpa_range=5 lowers alert_range
    mgr.on_mail("NODE_REPORT", report("ben", 4, 0, time=0), 0)
    assert values(mgr.iterate(0), "CONTACT_INFO") == ["name=ben # contact=ben"]


def test_bad_parameters_name_the_line(tmp_path):
    with pytest.raises(MissionFileError, match=r"abe\.moos:7: decay"):
        ContactMgr(write_mission(tmp_path, "  decay = 30\n")).on_startup()
    with pytest.raises(MissionFileError, match=r"abe\.moos:7: .*unknown alert component"):
        ContactMgr(write_mission(tmp_path, "  alert = id=a, rnage=5\n")).on_startup()


def test_pbasiccontactmgr_reads_its_own_block(tmp_path):
    app = BasicContactMgr(write_mission(tmp_path, "  contact_max_age = 3600\n", name="pBasicContactMgr"))
    app.on_startup()
    assert app.name == "pBasicContactMgr" and app.machine.params.contact_max_age == 3600


def test_pbasiccontactmgr_alerts_without_ranges_use_the_block_defaults(tmp_path):
    """An old-style block: the alert gives no range, so default_alert_range / alert_cpa_range apply."""
    app = BasicContactMgr(write_mission(tmp_path, "  alert = id=avd, var=CONTACT_INFO\n"
                                                  '  alert = id=avd, val="name=avd_$[VNAME] # contact=$[VNAME]"\n'
                                                  "  alert_range = 40\n  alert_cpa_range = 60\n", name="pBasicContactMgr"))
    app.on_startup()
    mgr = app.machine
    assert mgr.params.default_ranges == (40, 60) and mgr.params.contact_max_age == 3600
    mgr.on_mail("NODE_REPORT", report("ben", 55, 0, 270, 1, time=0), 0)    # 55 m, coming straight in
    assert values(mgr.iterate(0), "CONTACT_INFO") == ["name=avd_ben # contact=ben"]
    mgr.configure_alert("id=far, range=10, on_flag=FAR=$[VNAME]", "")      # its own range; cpa from the default
    assert mgr.alerts["far"].ranges(mgr.params.default_ranges) == (10, 60)
    assert ContactMgrParams.from_config({}, basic=True).default_ranges == (1000, 1000)
    assert ContactMgrParams.from_config({}).default_ranges is None


def test_a_bad_alert_line_is_named(tmp_path):
    mission = write_mission(tmp_path, "  alert = id=a, var=X, val=1, alert_range=5\n  alert = id=b, alert_range=far\n")
    with pytest.raises(MissionFileError, match=r"abe\.moos:8: .*alert_range='far'"):
        ContactMgr(mission).on_startup()
