"""The helm engine as pure logic: a fake clock and a simple kinematic boat, no MOOS."""
import math
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

from behaviors.bhv_file import parse_bhv, read_bhv
from behaviors.domain import IvPDomain, parse_domain_line
from behaviors.helm import Helm
from moosdb_py.source import MissionFileError, SourceLine

from helm_sim import Boat, run


def bhv_of(text: str):
    return parse_bhv([SourceLine(t, Path("t.bhv"), i) for i, t in enumerate(text.splitlines(), 1)])


def test_alpha_survey_visits_every_waypoint_in_order_and_returns(corpus, domain):
    helm = Helm([read_bhv(corpus / "s1_alpha" / "alpha.bhv")], domain, "alpha", active_start=True)
    helm.startup(0.0)
    boat, log = Boat(0, -20, 180), []
    run(helm, boat, 600, pokes={1.0: {"DEPLOY": "true"}}, log=log)
    track = [(t, val) for t, v, val in log if v == "POS"]
    closest = [0.0]
    for wx, wy in [(60, -40), (60, -160), (150, -160), (180, -100), (150, -40), (0, -20)]:
        t, d = min(((t, math.hypot(x - wx, y - wy)) for t, (x, y) in track if t > closest[-1]),
                   key=lambda p: p[1])
        closest.append(t)
        assert d < 5
    assert closest == sorted(closest)
    indexes = [val for _, v, val in log if v == "WPT_INDEX"]
    assert indexes[:5] == [0.0, 1.0, 2.0, 3.0, 4.0]
    stats = [val for _, v, val in log if v == "WPT_STAT" and "completed" in str(val)]
    assert stats == ["behavior-name=waypt_survey,completed", "behavior-name=waypt_return,completed"]
    posts = {v: val for _, v, val in log}
    assert posts["MISSION"] == "complete" and posts["DEPLOY"] == "false" and posts["RETURN"] == "false"
    assert str(posts["SUMMARY"]).startswith("speed=3,time=")
    assert math.hypot(boat.x - 0, boat.y + 20) < 3
    assert posts["IVPHELM_ALLSTOP"] == "NothingToDo"
    assert any(v == "CINFO" for _, v, _ in log) and posts["INFO"] == "BHV_Waypoint"
    views = [val for _, v, val in log if v == "VIEW_POINT"]
    assert any("alpha's trackpt,active=true" in val for val in views)
    assert views[-1].endswith("active=false")   # erased when the return behaviour went idle
    deaths = [val for _, v, val in log if v == "IVPHELM_LIFE_EVENT"]
    assert deaths == []  # both waypoint behaviours are perpetual


def test_park_until_manual_override_false_then_drive(missions, domain):
    helm = Helm([read_bhv(missions / "s1_alpha" / "alpha.bhv")], domain, "alpha")
    helm.startup(0.0)
    log = []
    end = run(helm, Boat(0, -20), 3, log=log)
    assert {val for _, v, val in log if v == "IVPHELM_STATE"} == {"PARK"}
    assert [val for _, v, val in log if v == "IVPHELM_ALLSTOP"] == ["ManualOverride"]
    assert [(v, val) for _, v, val in log if v.startswith("DESIRED")] == [("DESIRED_HEADING", 0.0),
                                                                          ("DESIRED_SPEED", 0.0)]
    log.clear()
    run(helm, Boat(0, -20), 5, start=end, pokes={round(end, 2): {"MOOS_MANUAL_OVERRIDE": "false",
                                                                 "DEPLOY": "true"}}, log=log)
    assert [val for _, v, val in log if v == "IVPHELM_ALLSTOP"][-1] == "clear"
    assert any(v == "DESIRED_HEADING" and val > 90 for _, v, val in log)


def test_nothing_to_do_quirk_posts_twice_then_zeros(domain):
    helm = Helm([bhv_of("initialize DEPLOY = false\nBehavior = BHV_ConstantSpeed\n{\n condition = DEPLOY = true\n"
                        " speed = 1\n}\n")], domain, "v", active_start=True)
    helm.startup(0.0)
    log = []
    run(helm, Boat(), 3, log=log)
    allstops = [(t, val) for t, v, val in log if v == "IVPHELM_ALLSTOP"]
    assert [val for _, val in allstops] == ["NothingToDo", "NothingToDo"]
    zeros = [t for t, v, _ in log if v == "DESIRED_SPEED"]
    assert zeros == [allstops[1][0]]


SK_BHV = """
initialize DEPLOY = false, RETURN = false
initialize STATION_KEEP = true
set MODE = ACTIVE {
  DEPLOY = true
} INACTIVE
set MODE = STATION-KEEPING {
  MODE = ACTIVE
  STATION_KEEP = true
}
set MODE = RETURNING {
  MODE = ACTIVE
  RETURN = true
}
Behavior = BHV_StationKeep
{
  name = station-keep
  condition = MODE==STATION-KEEPING
  activeflag = STATIONING = true
  inactiveflag = STATIONING = false
  station_pt = 20,-20
  inner_radius = 5
  outer_radius = 10
  outer_speed = 1.0
  transit_speed = 1.3
}
Behavior = BHV_Waypoint
{
  name = waypt_return
  condition = MODE==RETURNING
  points = 0,0
  speed = 2
}
"""


def test_modes_follow_the_set_entries(domain):
    helm = Helm([bhv_of(SK_BHV)], domain, "v", active_start=True)
    posts = helm.startup(0.0)
    assert ("IVPHELM_MODESET", "MODE=ACTIVE#MODE=STATION-KEEPING@ACTIVE#MODE=RETURNING@ACTIVE", "") in posts
    log = []
    pokes = {2.0: {"DEPLOY": "true"}, 4.0: {"STATION_KEEP": "false", "RETURN": "true"}}
    run(helm, Boat(), 6, pokes=pokes, log=log)
    assert [val for _, v, val in log if v == "MODE"] == ["INACTIVE", "ACTIVE:STATION-KEEPING", "ACTIVE:RETURNING"]
    assert [val for _, v, val in log if v == "STATIONING"] == ["false", "true", "false"]
    assert "name=station-keep,pc=MODE==STATION-KEEPING,updates=0/0,state=idle" in [
        val for _, v, val in log if v == "BHV_STATUS"]


def test_station_keep_settles_inside_outer_radius_under_current(domain):
    helm = Helm([bhv_of(SK_BHV)], domain, "v", active_start=True)
    helm.startup(0.0)
    boat, log = Boat(-40, 30, 90, current=(0.3, -0.2)), []
    run(helm, boat, 300, pokes={1.0: {"DEPLOY": "true"}}, log=log)
    late = [math.hypot(x - 20, y + 20) for t, v, (x, y) in ((t, v, val) for t, v, val in log if v == "POS")
            if t > 150]
    assert max(late) < 10
    dists = [val for t, v, val in log if v == "DIST_TO_STATION"]
    assert dists[0] > 60


def test_unknown_behavior_type_is_a_startup_error(domain):
    with pytest.raises(MissionFileError, match=r"t.bhv:1: unknown behavior type 'BHV_AvdColregsV22'"):
        Helm([bhv_of("Behavior = BHV_AvdColregsV22\n{\n pwt = 1\n}\n")], domain)
    with pytest.raises(MissionFileError, match=r"t.bhv:3: .*unknown parameter 'spede'"):
        Helm([bhv_of("Behavior = BHV_Waypoint\n{\n spede = 1\n}\n")], domain)


def test_updates_posted_while_parked_apply_once_driving(domain, make_bhv):
    helm = Helm([make_bhv("Behavior = BHV_Waypoint\n{\n name = w\n updates = WU\n points = 0,50\n speed = 1\n}\n")],
                domain, "v")
    helm.startup(0.0)
    log = []
    end = run(helm, Boat(), 3, log=log, pokes={1.0: {"WU": "speed=2.5"}})
    run(helm, Boat(), 3, start=end, log=log, pokes={round(end, 2): {"MOOS_MANUAL_OVERRIDE": "false"}})
    assert any(v == "IVPHELM_UPDATE_RESULT" and "result=success" in val for _, v, val in log)
    assert [val for _, v, val in log if v == "DESIRED_SPEED"][-1] == 2.5


def test_another_helm_state_disables_and_deferred_initialize(domain, make_bhv):
    helm = Helm([make_bhv("initialize_ LATE = 5\ninitialize_ KEPT = a\nBehavior = BHV_ConstantSpeed\n{\n"
                          " speed = 1\n}\n")], domain, "v", active_start=True)
    assert "LATE" in helm.subscriptions()
    helm.startup(0.0)
    helm.on_mail("KEPT", "b", 0.0)
    helm.on_mail("IVPHELM_STATE", "DRIVE", 0.0, source="pHelmIvP")
    log = []
    run(helm, Boat(), 1, log=log)
    assert [(v, val) for _, v, val in log if v in ("LATE", "KEPT")] == [("LATE", 5.0)]
    helm.on_mail("IVPHELM_STATE", "DRIVE", 1.0, source="pHelmIvP_other")
    log.clear()
    run(helm, Boat(), 2, start=1.0, log=log)
    assert [val for _, v, val in log if v == "IVPHELM_STATE"] == ["DISABLED"]
    assert not any(v.startswith("DESIRED") for _, v, _ in log)


def test_spawned_behavior_from_template(domain, make_bhv):
    helm = Helm([make_bhv("Behavior = BHV_ConstantSpeed\n{\n name = cs_\n templating = spawn\n updates = CS\n"
                          " speed = 1\n duration = no-time-limit\n}\nBehavior = BHV_ConstantHeading\n{\n"
                          " heading = 45\n duration = no-time-limit\n}\n")],
                domain, "v", active_start=True)
    helm.startup(0.0)
    log = []
    run(helm, Boat(), 2, log=log, pokes={1.5: {"CS": "name=a # speed=2.5"}})
    assert [b.name for b in helm.behaviors] == ["bhv_constantHeading", "cs_a"]
    assert any(v == "IVPHELM_LIFE_EVENT" and "bname=cs_a" in val and "event=spawn" in val for _, v, val in log)
    assert [val for _, v, val in log if v == "DESIRED_SPEED"][-1] == 2.5
    assert [val for _, v, val in log if v == "DESIRED_HEADING"][-1] == 45


def test_constant_depth_needs_and_uses_the_depth_domain(domain, make_bhv):
    bhv = make_bhv("Behavior = BHV_ConstantDepth\n{\n depth = 8\n duration = -1\n}\nBehavior = BHV_StationKeep\n{\n point = 0,0\n}\n")
    with pytest.raises(MissionFileError, match="needs domain variable"):
        Helm([bhv], domain)
    from behaviors.domain import parse_domain_line
    deep = domain.model_copy(update={"vars": domain.vars + [parse_domain_line("depth:0:100:101")]})
    helm = Helm([bhv], deep, "uuv", active_start=True)
    helm.startup(0.0)
    for t in (0.0, 1.0, 2.0):
        for var, value in dict(NAV_X=20.0, NAV_Y=0.0, NAV_HEADING=0.0, NAV_SPEED=0.0, NAV_DEPTH=0.0).items():
            helm.on_mail(var, value, t)
        posts = dict((v, val) for v, val, _ in helm.iterate(t))
    assert posts["DESIRED_DEPTH"] == 8 and posts["DESIRED_HEADING"] == 270


def test_loiter_acquires_then_circles_the_lab_polygon(corpus, domain):
    helm = Helm([read_bhv(corpus / "minicourse_lab_henry_gilda_baseline" / "targ_henry.bhv")], domain, "henry",
                active_start=True)
    helm.startup(0.0)
    boat, log = Boat(80, 0, 180), []
    run(helm, boat, 400, dt=0.5, log=log)               # initialize DEPLOY = true, LOITER = true
    assert [val for _, v, val in log if v == "MODE"] == ["ACTIVE:LOITERING"]
    assert [val for _, v, val in log if v == "LOITER_ACQUIRE"][:2] == [1.0, 0.0]
    assert max(val for _, v, val in log if v == "LOITER_CYCLES_A") >= 2
    loiter = helm.behaviors[0]
    centre = loiter.points.mean(axis=0)
    late = [math.hypot(x - centre[0], y - centre[1]) for t, v, (x, y) in
            ((t, v, val) for t, v, val in log if v == "POS") if t > 200]
    assert 10 < min(late) and max(late) < 30         # on the ring of the radius-20 octagon


def test_nostarve_post_mapping_and_conditional_flags(domain, make_bhv):
    helm = Helm([make_bhv("Behavior = BHV_ConstantSpeed\n{\n speed = 1\n nostarve = FEED,3\n"
                          " duration = no-time-limit\n runxflag = TICK = $[CTR]\n runflag = GO = yes [if] LEVEL > 2\n"
                          " activeflag = OLD = 1\n post_mapping = OLD,NEW\n idleflag = HUSH = 1\n"
                          " post_mapping = HUSH,silent\n}\n")], domain, "v", active_start=True)
    helm.startup(0.0)
    log = []
    run(helm, Boat(), 3, log=log, pokes={1.0: {"LEVEL": 5.0}, 1.5: {"FEED": "x"}})
    assert [t for t, v, _ in log if v == "GO"] == [1.5]
    assert [val for _, v, val in log if v == "TICK"][:3] == [1.0, 2.0, 3.0]
    assert [v for _, v, _ in log if v in ("OLD", "NEW", "HUSH")] == ["NEW"]
    log.clear()
    run(helm, Boat(), 6, start=3.0, log=log)                 # FEED goes stale after 3 s
    assert any(v == "IVPHELM_BHV_IDLE" and val == "bhv_constant_speed" for _, v, val in log)


def test_helm_prefix_names_the_decision_but_not_the_zeros(domain, make_bhv):
    helm = Helm([make_bhv("initialize GO = true\nBehavior = BHV_ConstantHeading\n{\n condition = GO = true\n"
                          " heading = 30\n duration = -1\n}\nBehavior = BHV_ConstantSpeed\n{\n condition = GO = true\n"
                          " speed = 1\n duration = -1\n}\n")],
                domain, "v", active_start=True, helm_prefix="SIM_")
    helm.startup(0.0)
    log = []
    run(helm, Boat(), 3, log=log, pokes={2.0: {"GO": "false"}})
    assert {v for _, v, _ in log if "DESIRED" in v} == {"SIM_DESIRED_HEADING", "SIM_DESIRED_SPEED",
                                                        "DESIRED_HEADING", "DESIRED_SPEED"}
    assert [val for _, v, val in log if v == "DESIRED_SPEED"] == [0.0]


def test_constant_behaviours_time_out_at_once_without_a_duration(domain, make_bhv):
    helm = Helm([make_bhv("Behavior = BHV_ConstantSpeed\n{\n speed = 1\n endflag = DONE = $[BHVNAME]\n}\n")],
                domain, "v", active_start=True)
    helm.startup(0.0)
    log = []
    run(helm, Boat(), 2, log=log)
    assert [(t, val) for t, v, val in log if v == "DONE"] == [(1.0, "bhv_constant_speed")]
    assert helm.behaviors == [] and "DESIRED_SPEED" not in [v for _, v, val in log if val != 0.0]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.text(alphabet="pointsspeedrepeatforevercapture_radiusorderlead=#,:.-0123456789 xyz{}",
                        max_size=40), min_size=1, max_size=4))
def test_any_update_string_leaves_the_helm_running(updates):
    bhv = bhv_of("Behavior = BHV_Waypoint\n{\n name = w\n updates = U\n points = 0,50\n speed = 1\n}\n"
                 "Behavior = BHV_StationKeep\n{\n name = s\n updates = U\n point = 0,0\n duration = -1\n}\n")
    domain = IvPDomain(vars=[parse_domain_line("course:0:359:36"), parse_domain_line("speed:0:4:9")])
    helm = Helm([bhv], domain, "v", active_start=True)
    helm.startup(0.0)
    log = []
    run(helm, Boat(), 2 + 0.25 * len(updates), log=log,
        pokes={2.0 + 0.25 * i: {"U": text} for i, text in enumerate(updates)})
    results = [val for _, v, val in log if v == "IVPHELM_UPDATE_RESULT"]
    assert len(results) == 2 * sum(bool(u.strip()) for u in updates)
    assert all(v == "IVPHELM_STATE" and val == "DRIVE" for _, v, val in log if v == "IVPHELM_STATE")
