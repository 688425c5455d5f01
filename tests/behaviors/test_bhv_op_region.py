"""BHV_OpRegion on hand-computed cases: perimeter distances and times, polygon breach with the exit
grace, entry triggering, max_time, and the helm's latched all-stop."""
from __future__ import annotations

import pytest

from behaviors.behavior import InfoBuffer
from behaviors.bhv_op_region import BHV_OpRegion, perimeter_distance_along
from behaviors.helm import Helm

SQUARE = "0,0:0,100:100,100:100,0"
BHV = ("Behavior = BHV_OpRegion\n{\n polygon = " + SQUARE + "\n{extra}}\n"
       "Behavior = BHV_ConstantSpeed\n{\n speed = 2\n duration = no-time-limit\n}\n"
       "Behavior = BHV_ConstantHeading\n{\n heading = 90\n duration = no-time-limit\n}\n")


def helm_with(make_bhv, domain, extra=""):
    helm = Helm([make_bhv(BHV.replace("{extra}", extra))], domain, "abe", active_start=True)
    helm.startup(0.0)
    return helm


def step(helm, t, x, y, heading=0.0, speed=2.0, **more):
    for var, value in dict(NAV_X=x, NAV_Y=y, NAV_HEADING=heading, NAV_SPEED=speed, **more).items():
        helm.on_mail(var, value, t)
    return {var: value for var, value, _ in helm.iterate(t)}


def test_perimeter_distances_and_times(make_bhv, domain):
    helm = helm_with(make_bhv, domain)
    step(helm, 0.0, 50, 20)
    posts = step(helm, 1.0, 50, 20)                  # 80 m ahead at 2 m/s; 20 m to the south edge at 4 m/s
    assert posts["OPREG_TRAJECTORY_PERIM_DIST"] == 80 and posts["OPREG_TRAJECTORY_PERIM_ETA"] == 40
    assert posts["OPREG_ABSOLUTE_PERIM_DIST"] == 20 and posts["OPREG_ABSOLUTE_PERIM_ETA"] == 5
    assert posts["IVPHELM_ALLSTOP"] == "clear" and "OPREG_TIME_REMAINING" not in posts
    posts = step(helm, 1.25, 50, 20, heading=90)      # east: 50 m to x = 100
    assert posts["OPREG_TRAJECTORY_PERIM_DIST"] == 50 and posts["OPREG_TRAJECTORY_PERIM_ETA"] == 25


@pytest.mark.parametrize("x, y, heading, expected", [
    (50, 50, 45, 50 * 2 ** 0.5), (50, 50, 180, 50), (-10, 50, 90, 10), (-10, 50, 270, -1), (99.5, 50, 90, 0.5)])
def test_distance_along_a_heading(x, y, heading, expected):
    import shapely
    square = shapely.Polygon([(0, 0), (0, 100), (100, 100), (100, 0)])
    assert perimeter_distance_along(square, x, y, heading) == pytest.approx(expected)


def test_breach_after_the_exit_grace_all_stops_for_good(make_bhv, domain):
    helm = helm_with(make_bhv, domain)
    step(helm, 0.0, 50, 50)
    assert step(helm, 1.0, 50, 50)["IVPHELM_ALLSTOP"] == "clear"
    step(helm, 1.25, 50, 50)
    out = step(helm, 1.5, 120, 50)                    # just left: the grace (trigger_exit_time 0.5 s) starts
    assert "BHV_ERROR" not in out and out["DESIRED_SPEED"] == 2
    assert "BHV_ERROR" not in step(helm, 1.75, 120, 50)      # 0.25 s outside
    out = step(helm, 2.0, 120, 50)                    # 0.5 s outside: breach
    assert out["BHV_ERROR"] == "bhv_opregion: BHV_OpRegion Polygon containment failure:  x=120.00000 y=50.00000"
    assert out["IVPHELM_ALLSTOP"] == "BehaviorError" and out["DESIRED_SPEED"] == 0
    assert "halted=true" in out["IVPHELM_SUMMARY"]
    out = step(helm, 2.25, 50, 50)                    # back inside: still stopped, still the first reason
    assert out["BHV_ERROR"].endswith("x=120.00000 y=50.00000") and "DESIRED_SPEED" not in out


def test_a_single_wild_fix_is_forgiven(make_bhv, domain):
    helm = helm_with(make_bhv, domain)
    step(helm, 0.0, 50, 50)
    for t, x in ((1.0, 50), (1.25, 500), (1.5, 50), (1.75, 50)):
        out = step(helm, t, x, 50)
        assert "BHV_ERROR" not in out and out["DESIRED_SPEED"] == 2


def test_trigger_entry_time_waits_for_a_real_entry(make_bhv, domain):
    helm = helm_with(make_bhv, domain, " trigger_entry_time = 1\n trigger_exit_time = 0\n")
    step(helm, 0.0, -50, 50)
    for t in (1.0, 1.25, 1.5):                        # launched outside: not enforced yet
        assert "BHV_ERROR" not in step(helm, t, -50, 50)
    for t in (1.75, 2.0, 2.25, 2.5):                  # inside 0.75 s: not yet an entry
        step(helm, t, 50, 50)
    assert "BHV_ERROR" not in step(helm, 2.75, -50, 50)
    for t in (3.0, 3.25, 3.5, 3.75, 4.0):              # inside 1 s: entry made
        step(helm, t, 50, 50)
    assert step(helm, 4.25, -50, 50)["IVPHELM_ALLSTOP"] == "BehaviorError"


def test_max_time_counts_from_the_first_run(make_bhv, domain):
    helm = helm_with(make_bhv, domain, " max_time = 10\n")
    step(helm, 0.0, 50, 50)
    assert step(helm, 1.0, 50, 50)["OPREG_TIME_REMAINING"] == 10    # first run at t = 1
    assert step(helm, 7.5, 50, 50)["OPREG_TIME_REMAINING"] == 3.5
    out = step(helm, 11.25, 50, 50)
    assert out["OPREG_TIME_REMAINING"] == 0
    assert out["BHV_ERROR"] == "bhv_opregion: OpRegion timeout failure: MaxTime:10.00000  Elapsed Time: 10.25000"


def test_depth_and_altitude_limits(domain):
    info = InfoBuffer()
    bhv = BHV_OpRegion(domain, info, "abe")
    for key, value in (("polygon", SQUARE), ("max_depth", "20"), ("min_altitude", "3")):
        bhv.apply(key, value)
    for var, value in dict(NAV_X=50.0, NAV_Y=50.0, NAV_HEADING=0.0, NAV_SPEED=1.0, NAV_DEPTH=25.0,
                           NAV_ALTITUDE=2.0).items():
        info.set(var, value, 0.0)
    assert bhv.tick(0.0) is None
    errors = [p.value for p in bhv.take_posts() if p.var == "BHV_ERROR"]
    assert errors == ["bhv_opregion: OpRegion Depth failure: max:20.00000 detected:25.00000"]


@pytest.mark.parametrize("key, value, message", [
    ("polygon", "0,0:50,50:100,0:50,10", "not convex"), ("max_time", "-1", "max_time must be a number >= 0"),
    ("trigger_exit_time", "soon", "trigger_exit_time must be a number")])
def test_bad_parameters(domain, key, value, message):
    with pytest.raises(ValueError, match=message):
        BHV_OpRegion(domain, InfoBuffer()).apply(key, value)


def test_the_drawn_polygon_follows_a_hints_update(make_bhv, domain):
    """The VIEW_POLYGON text is built once and kept; an update of the hints rebuilds it."""
    helm = helm_with(make_bhv, domain, " updates = OPR_UPDATES\n visual_hints = edge_color=red\n")
    step(helm, 0.0, 50, 20)
    shown = [step(helm, t, 50, 20).get("VIEW_POLYGON") for t in (1.0, 1.25)]
    assert shown[0].endswith(",label=abe_bhv_opregion,edge_color=red") and shown[1] is None   # unchanged: not re-posted
    helm.on_mail("OPR_UPDATES", "visual_hints=edge_color=green", 1.5)
    assert step(helm, 1.5, 50, 20)["VIEW_POLYGON"].endswith(",label=abe_bhv_opregion,edge_color=green")
