"""BHV_AvoidCollision on hand-computed cases: CPA, extrapolation, the contact ledger, relevance,
utility, completion, and spawning per contact through the alert update; a head-on encounter."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from behaviors.behavior import InfoBuffer
from behaviors.bhv_avoid_collision import BHV_AvoidCollision
from behaviors.contacts import closing_speed, cpa_distance, cpa_range, extrapolate, node_report_values
from moosdb_py.geodesy import LocalGrid
from behaviors.helm import Helm
from helm_sim import AVOID_MISSION as TEMPLATE
from helm_sim import Boat, head_on, node_report as report, run


@pytest.mark.parametrize("course, speed, tol, expected", [
    (0, 2, 120, 0.0),                        # straight at each other: they meet after 25 s
    (90, 2, 120, math.hypot(50, 50)),        # relative velocity (2, 2): closest at t = 25 s
    (90, 4, 120, math.hypot(40, 80)),        # relative velocity (4, 2): closest at t = 10 s
    (0, 2, 5, 80.0),                         # only 5 s judged: 100 - 4 x 5
    (0, 0, 120, 0.0),                        # stopped: the contact runs into ownship at t = 50 s
    (180, 2, 120, 100.0),                    # same course and speed as the contact: range holds
])
def test_cpa_of_a_leg_against_a_head_on_contact(course, speed, tol, expected):
    assert cpa_distance(0, 0, course, speed, 0, 100, 180, 2, tol) == pytest.approx(expected)


def test_cpa_broadcasts_over_the_course_speed_grid():
    grid = cpa_distance(0, 0, np.array([0, 90])[:, None], np.array([2, 4])[None, :], 0, 100, 180, 2, 120)
    assert grid.shape == (2, 2) and grid[1, 0] == pytest.approx(math.hypot(50, 50))


def test_closing_speed():
    assert closing_speed(0, 0, 0, 2, 0, 100, 180, 2) == pytest.approx(4)       # head-on
    assert closing_speed(0, 0, 180, 2, 0, 100, 180, 2) == pytest.approx(0)     # same velocity
    assert closing_speed(0, 0, 180, 1, 0, 100, 0, 1) == pytest.approx(-2)      # opening


coordinate, heading, speed = st.floats(-2000, 2000), st.floats(0, 360), st.floats(0, 6)


@given(coordinate, coordinate, heading, speed, coordinate, coordinate, heading, speed, st.floats(0, 600))
def test_scalar_cpa_range_is_the_array_cpa(osx, osy, osh, osv, cnx, cny, cnh, cnv, horizon):
    """The contact manager's plain-float CPA agrees with the helm's array CPA for the same one course."""
    expected = float(cpa_distance(osx, osy, osh, osv, cnx, cny, cnh, cnv, horizon))
    assert cpa_range(osx, osy, osh, osv, cnx, cny, cnh, cnv, horizon) == pytest.approx(expected, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("age, expected_x", [
    (0, 0), (-3, 0), (10, 20), (15, 30),
    (20, 30 + (2 + 2 * (1 - 5 / 15)) / 2 * 5),     # slowing from 2 m/s, 5 s into a 15 s decay
    (30, 45), (40, 45),                           # stopped at the end of the decay: 30 + 15 x 1
])
def test_extrapolation_decays_linearly_to_a_stop(age, expected_x):
    x, y = extrapolate(0, 0, 2, 90, age, 15, 30)
    assert x == pytest.approx(expected_x) and y == pytest.approx(0, abs=1e-9)


def test_node_report_becomes_named_info_values():
    report = "NAME=henry,X=10,Y=-5.5,SPD=2,HDG=90,DEP=0,LAT=43.8,LON=-70.3,TYPE=kayak,GROUP=red,TIME=100.25"
    assert node_report_values(report) == {
        "HENRY_NAV_X": 10, "HENRY_NAV_Y": -5.5, "HENRY_NAV_SPEED": 2, "HENRY_NAV_HEADING": 90,
        "HENRY_NAV_DEPTH": 0, "HENRY_NAV_LAT": 43.8, "HENRY_NAV_LONG": -70.3, "HENRY_NAV_UTC": 100.25,
        "HENRY_NAV_GROUP": "red", "HENRY_NAV_TYPE": "kayak"}
    assert node_report_values("name=gus,x=1,y=2,spd=0,hdg=0,utc_time=5")["GUS_NAV_UTC"] == 5
    assert node_report_values("NAME=henry,X=10,Y=-5,SPD=2,HDG=90") is None         # no time
    assert node_report_values("X=10,Y=-5,SPD=2,HDG=90,TIME=1") is None             # no name


def test_a_lat_lon_only_report_is_placed_on_the_mission_grid():
    """pNodeReporter's coord_policy_global = true (m2_berta) sends LAT/LON without X/Y: the helm places
    the contact about LatOrigin/LongOrigin, or it could never avoid it."""
    grid = LocalGrid(43.8253, -70.3304)
    lat, lon = grid.to_latlon(120.0, -75.0)
    report = f"NAME=deb,SPD=1.4,HDG=288,DEP=0,LAT={lat:.8f},LON={lon:.8f},TYPE=kayak,TIME=17961767081.39"
    values = node_report_values(report, grid)
    assert values["DEB_NAV_X"] == pytest.approx(120.0, abs=0.01) and values["DEB_NAV_Y"] == pytest.approx(-75.0, abs=0.01)
    assert node_report_values(report) is None                                   # no grid: no position
    assert node_report_values(report.replace("LON=", "LONG="), grid)["DEB_NAV_Y"] == values["DEB_NAV_Y"]


def avoider(domain, **params):
    info = InfoBuffer()
    bhv = BHV_AvoidCollision(domain, info, "abe")
    for key, value in {"contact": "henry", **params}.items():
        bhv.apply(key, str(value))
    return bhv, info


def feed(info, t, os=(0.0, 0.0, 0.0, 2.0), cn=(0.0, 100.0, 180.0, 2.0), utc=None):
    for var, value in zip(("NAV_X", "NAV_Y", "NAV_HEADING", "NAV_SPEED"), os):
        info.set(var, value, t)
    for var, value in zip(("X", "Y", "HEADING", "SPEED"), cn):
        info.set(f"HENRY_NAV_{var}", value, t)
    info.set("HENRY_NAV_UTC", t if utc is None else utc, t)


def test_objective_function_on_a_head_on_contact(domain):
    bhv, info = avoider(domain, pwt_grade="linear")
    feed(info, 10.0)
    fn = bhv.tick(10.0)
    assert fn.pwt == pytest.approx(100 * (200 - 100) / 150)                 # relevance 2/3 at 100 m
    speed = domain.var("speed")
    at = lambda crs, spd: fn.values[crs, speed.index_of(spd)]   # noqa: E731
    assert at(0, 2) == 0 and at(0, 0) == 0                                  # collision courses
    assert at(90, 2) == pytest.approx(25 + 75 * (math.hypot(50, 50) - 10) / 65)
    assert at(90, 4) == 100 and fn.values.max() == 100 and fn.values.min() == 0
    posts = {p.var: p.value for p in bhv.take_posts()}
    assert posts["RANGE_AVD_HENRY"] == 100 and posts["CLSG_SPD_AVD_HENRY"] == 4
    assert posts["BHV_STATUS"].endswith("state=active,pwt=66.6667")


@pytest.mark.parametrize("grade, cn_y, relevance", [
    ("quasi", 100, (2 / 3) ** 1.5), ("quadratic", 100, (2 / 3) ** 2), ("linear", 40, 1.0),
    ("linear", 50, 1.0), ("linear", 199, 1 / 150)])
def test_relevance_grades(domain, grade, cn_y, relevance):
    bhv, info = avoider(domain, pwt_grade=grade)
    feed(info, 1.0, cn=(0.0, cn_y, 180.0, 2.0))
    assert bhv.tick(1.0).pwt == pytest.approx(100 * relevance)


def test_no_function_beyond_the_outer_distance_and_completion_beyond_completed_dist(domain):
    bhv, info = avoider(domain, completed_dist=300, endflag="CONTACT_RESOLVED = $[CONTACT]")
    feed(info, 1.0, cn=(0.0, 250.0, 0.0, 2.0))
    assert bhv.tick(1.0) is None and bhv.state == "running"
    feed(info, 2.0, cn=(0.0, 329.0, 0.0, 2.0))                               # 1.1 x 300 = 330
    bhv.tick(2.0)
    assert bhv.state == "running"
    feed(info, 3.0, cn=(0.0, 331.0, 0.0, 2.0))
    bhv.tick(3.0)
    assert bhv.state == "completed"
    assert ("CONTACT_RESOLVED", "henry") in [(p.var, p.value) for p in bhv.take_posts()]


def test_inside_the_min_util_distance_half_the_range_is_the_floor(domain):
    bhv, info = avoider(domain, pwt_grade="linear")
    feed(info, 1.0, cn=(0.0, 8.0, 0.0, 2.0))           # 8 m ahead, same course and speed
    fn = bhv.tick(1.0)                                  # floor 4 m: holding course keeps 8 m, not 0 utility
    speed = domain.var("speed")
    assert fn.values[0, speed.index_of(2)] > 0
    assert fn.values[0, speed.index_of(4)] == 0        # overtaking it closes to 0


def test_extrapolated_contact_position_is_used(domain):
    bhv, info = avoider(domain, pwt_grade="linear")
    feed(info, 20.0, cn=(0.0, 140.0, 180.0, 2.0), utc=10.0)   # reported 10 s ago: now at y = 120
    bhv.tick(20.0)
    assert bhv.range == pytest.approx(120)
    bhv2, info2 = avoider(domain, pwt_grade="linear", extrapolate="false")
    feed(info2, 20.0, cn=(0.0, 140.0, 180.0, 2.0), utc=10.0)
    bhv2.tick(20.0)
    assert bhv2.range == pytest.approx(140)


def test_missing_contact_is_a_warning_or_an_error(domain):
    bhv, info = avoider(domain)
    feed(info, 1.0)
    for var in ("HENRY_NAV_X", "HENRY_NAV_UTC"):
        info.values.pop(var)
    assert bhv.tick(1.0) is None
    assert ("BHV_WARNING", "avoid_collision: HENRY x/y/heading/speed info not found") in [
        (p.var, p.value) for p in bhv.take_posts()]
    strict, info = avoider(domain, on_no_contact_ok="false")
    feed(info, 1.0)
    info.values.pop("HENRY_NAV_UTC")
    strict.tick(1.0)
    assert any(p.var == "BHV_ERROR" for p in strict.take_posts())


def test_contact_flags_and_bearing_line(domain):
    bhv, info = avoider(domain, pwt_grade="linear", cnflag="@<90 NEAR = $[CONTACT] at $[RANGE]",
                        bearing_line_config="white:0, green:0.65, yellow:0.8, red:1.0")
    feed(info, 1.0)
    bhv.tick(1.0)
    posts = {p.var: p.value for p in bhv.take_posts()}
    assert "NEAR" not in posts
    assert posts["VIEW_SEGLIST"] == "pts={0,0:0,100},label=abe_avoid_collision,label_color=white,edge_color=yellow"
    feed(info, 2.0, cn=(0.0, 80.0, 180.0, 2.0))
    bhv.tick(2.0)
    assert {p.var: p.value for p in bhv.take_posts()}["NEAR"] == "henry at 80"


@pytest.mark.parametrize("key, value, message", [
    ("pwt_grade", "cubic", "pwt_grade must be"), ("decay", "30,15", "decay must be start,end"),
    ("cnflag", "@soon X=1", "cnflag must be"), ("min_util_cpa_dist", "-1", "must be a number >= 0")])
def test_bad_parameters(domain, key, value, message):
    with pytest.raises(ValueError, match=message):
        BHV_AvoidCollision(domain, InfoBuffer()).apply(key, value)


def test_pair_parameters_keep_their_order(domain):
    bhv, _ = avoider(domain, pwt_inner_dist=300)
    assert (bhv.pwt_inner_dist, bhv.pwt_outer_dist) == (300, 300)
    bhv.apply("max_util_cpa_dist", "5")
    assert (bhv.min_util_cpa_dist, bhv.max_util_cpa_dist) == (5, 5)


def test_spawned_per_contact_alert_and_dies_when_clear(domain, make_bhv):
    helm = Helm([make_bhv(TEMPLATE)], domain, "abe", active_start=True)
    start = {var: value for var, value, _ in helm.startup(0.0)}
    assert start["BCM_ALERT_REQUEST"] == ("id=avd_, on_flag=CONTACT_INFO=name=$[VNAME] # contact=$[VNAME],"
                                          "alert_range=100, cpa_range=150")
    assert "NODE_REPORT" in helm.subscriptions()
    boat, log = Boat(0, 0, 0), []
    pokes = {1.5: {"CONTACT_INFO": "name=henry # contact=henry", "NODE_REPORT": report("henry", 0, 80, 180, 0, 1.5)}}
    run(helm, boat, 3, log=log, pokes=pokes)
    assert [b.name for b in helm.behaviors] == ["transit", "avd_henry"]
    assert helm.behaviors[1].contact == "henry" and helm.behaviors[1].state == "active"
    helm.on_mail("NODE_REPORT", report("henry", 0, 900, 0, 0, 3.0), 3.0)      # far away: done
    run(helm, boat, 1, start=3.0, log=log)
    assert [b.name for b in helm.behaviors] == ["transit"]
    events = [val for _, v, val in log if v == "IVPHELM_LIFE_EVENT"]
    assert "bname=avd_henry" in events[0] and "event=spawn" in events[0]
    assert "bname=avd_henry" in events[1] and "event=death" in events[1]
    assert ("CONTACT_RESOLVED", "henry") in [(v, val) for _, v, val in log]


def test_head_on_at_2_mps_keeps_the_cpa_above_min_util_cpa_dist(domain, make_bhv):
    """Without the avoidance they would collide (see benchmarks/helm_bench.py); with it the closest
    approach stays above min_util_cpa_dist and the transit goes on."""
    helm = Helm([make_bhv(TEMPLATE)], domain, "abe", active_start=True)
    helm.startup(0.0)
    closest, arrived, log = head_on(helm)
    assert closest >= 10 and arrived < 250
    assert [e.split(",event=")[1].split(",")[0] for _, v, e in log if v == "IVPHELM_LIFE_EVENT"] == ["spawn", "death"]
