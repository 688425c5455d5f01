"""Behaviour geometry and life-cycle details, with a hand-set info buffer and clock."""
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from behaviors.behavior import InfoBuffer
from behaviors.bhv_station_keep import BHV_StationKeep
from behaviors.bhv_waypoint import BHV_Waypoint
from behaviors.flags import expand_macros, parse_flag
from behaviors.geometry import GeometryError, format_seglist, parse_point, parse_polygon, parse_seglist
from behaviors.helm import Helm


def waypoint(domain, **params):
    info = InfoBuffer()
    w = BHV_Waypoint(domain, info, "abe")
    for k, v in params.items():
        w.apply(k, str(v))
    return w, info


def at(info, x, y, heading=0.0, speed=1.0, t=0.0):
    for var, value in dict(NAV_X=x, NAV_Y=y, NAV_HEADING=heading, NAV_SPEED=speed).items():
        info.set(var, value, t)


def test_geometry_strings():
    assert parse_seglist("pts={1,2:3,4},label=foo").tolist() == [[1, 2], [3, 4]]
    assert parse_seglist("points: 1 , 2 : 3,4 : label,bar").tolist() == [[1, 2], [3, 4]]
    assert parse_seglist("x=1,y=2:x=5,y=6").tolist() == [[1, 2], [5, 6]]
    radial = parse_polygon("format=radial, x=60, y=-65, radius=25, pts=8, snap=1")
    assert radial.shape == (8, 2) and radial[0].tolist() == [70, -42]
    assert np.allclose(parse_polygon("radial: 0, 0, 10, 4"), parse_polygon("radial:: x=0,y=0,radius=10,pts=4"))
    assert parse_point("x=3,y=-4,label=a") == (3, -4) and parse_point("3:4") == (3, 4)
    assert format_seglist(np.array([[1.0, 2.5], [3.0, -4.1234]])) == "pts={1,2.5:3,-4.123}"
    for bad in ("radial:: x=0,y=0,radius=-1,pts=4", "pts={1,2", "abc", "0,0:10,10:0,10:10,0"):
        with pytest.raises(GeometryError):
            parse_polygon(bad)


def test_lawnmower_pattern():
    """MOOS-IvP's lawnmower (XYPatternBlock): rows east-west unless `rows=ns`; the entry is the outer
    lane end nearest startx,starty (default 0,0); there is no `start=` corner key (it is ignored)."""
    pts = parse_seglist("format=lawnmower, x=0, y=0, width=40, height=20, swath=10, rows=ns")
    assert pts[:4] == pytest.approx(np.array([[-20, 10], [-20, -10], [-10, -10], [-10, 10]])) and len(pts) == 10
    rows_ew = parse_seglist("format=lawnmower, x=0, y=0, width=40, height=20, swath=10")
    assert rows_ew == pytest.approx(np.array([[20, 10], [-20, 10], [-20, 0], [20, 0], [20, -10], [-20, -10]]))
    turned = parse_seglist("lawnmower: x=5, y=5, width=40, height=20, swath=10, rows=ew, start=bl, degs=90")
    assert turned[:2] == pytest.approx(np.array([[-5, -15], [-5, 25]]))      # lanes north-south, entry nearest 0,0
    with pytest.raises(GeometryError):
        parse_seglist("format=lawnmower, x=0, y=0, width=40, height=20")


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.integers(-500, 500), st.integers(-500, 500)), min_size=1, max_size=8))
def test_seglist_round_trip(points):
    arr = np.array(points, dtype=float)
    assert parse_seglist(format_seglist(arr)).tolist() == arr.tolist()


def test_polygon_waypoints_start_nearest_ownship(domain):
    w, info = waypoint(domain)
    at(info, 100, 100)
    w.apply("polygon", "radial:: x=0,y=0,radius=10,pts=4")
    assert w.points[0].tolist() == pytest.approx([7.0710678, 7.0710678])


def test_capture_slip_and_capture_line(domain):
    w, _ = waypoint(domain, points="0,10:0,20", capture_radius=3, slip_radius=6)
    assert w.advance(0, 0) == "in-transit"
    assert w.advance(0, 8) == "advanced" and w.capture_hits == 1 and w.cpa == pytest.approx(12)
    assert w.advance(4, 15) == "in-transit"       # cpa now ~6.4
    assert w.advance(4.5, 17) == "in-transit"     # cpa 5.3 (< slip radius) and still closing
    assert w.advance(5, 17.5) == "completed" and w.slip_hits == 1
    line, _ = waypoint(domain, points="0,10", capture_radius=1, slip_radius=0, capture_line="true")
    line.prev = (0.0, 0.0)
    assert line.advance(20, 9) == "in-transit"
    assert line.advance(20, 10.5) == "completed"


def test_repeat_cycles_then_completes(domain):
    w, _ = waypoint(domain, points="0,10:10,10", repeat=1, capture_radius=2)
    assert w.perpetual
    results = [w.advance(*p) for p in [(0, 10), (10, 10), (0, 10), (10, 10)]]
    assert results == ["advanced", "cycled", "advanced", "completed"]
    forever, _ = waypoint(domain, points="0,10", repeat="forever")
    assert all(forever.advance(0, 10) == "cycled" for _ in range(5))
    assert forever.remaining_distance(0, 0) == -1


def test_lead_steering_point_and_damper(domain):
    w, _ = waypoint(domain, points="0,0:100,0", lead=10)
    w.ix = 1
    assert w.steering_point(30, -20) == pytest.approx((40, 0))
    w.apply("lead_damper", "5")
    assert w.steering_point(30, 0) == pytest.approx((60, 0))   # on the line: factor 3
    assert w.steering_point(95, -1) == pytest.approx((100, 0))  # clamped at the next point


def test_end_speed_ramp_and_objective_peak(domain):
    w, info = waypoint(domain, points="0,100", speed=2, end_spd="slow_dist=50,stop_dist=10")
    assert w.cruise_speed(0, 0) == 2 and w.cruise_speed(0, 70) == pytest.approx(1.0)
    assert w.cruise_speed(0, 95) == 0
    fn = w.objective(0, 0, heading=90)
    i, j = np.unravel_index(np.argmax(fn.values), fn.values.shape)
    assert (i, j) == (0, 20) and fn.values.max() == pytest.approx(100)


def test_flags_and_macros(domain):
    assert parse_flag("@<20 #all+ X = 3 [if] (A=1) and (B=2)").dest == "#all+"
    assert parse_flag("clearall") is None
    w, info = waypoint(domain, points="5,6:7,8")
    at(info, 1.23456, 2)
    assert expand_macros("$[OSX],$(NX)/$[BHVNAME]/$[NOPE]", w.macro) == "1.235,5/bhv_waypoint/$[NOPE]"
    assert expand_macros("$[WPTS]", w.macro) == 2.0


def test_updates_results_and_wptflag_dedup(domain, make_bhv):
    helm = Helm([make_bhv("Behavior = BHV_Waypoint\n{\n name = w\n updates = WU\n points = 0,50:0,100\n"
                          " speed = 1\n wptflag = HIT = yes\n endflag = DONE = $[NI]\n}\n")],
                domain, "abe", active_start=True)
    helm.startup(0)
    posts = []

    def step(t, x, y, **mail):
        for k, v in dict(NAV_X=x, NAV_Y=y, NAV_HEADING=0.0, NAV_SPEED=1.0, **mail).items():
            helm.on_mail(k, v, t)
        posts.extend(helm.iterate(t))

    step(0, 0, 0)
    step(2, 0, 0)
    step(3, 0, 49)
    step(4, 0, 60, WU="speed=1.5 # bogus=1")
    step(5, 0, 60, WU="name=other # speed=2")
    step(6, 0, 60, WU="points=0,70 # speed=2")
    step(7, 0, 60, WU="points=0,70 # speed=2")
    step(8, 0, 70)
    results = [v.split("result=")[1].split(",")[0] for k, v, _ in posts if k == "IVPHELM_UPDATE_RESULT"]
    assert results == ["param_error", "name_mismatch", "success", "duplicate"]
    assert [v for k, v, _ in posts if k == "HIT"] == ["yes"]   # wptflags are deduplicated
    assert ("BHV_WARNING", "Faulty update for behavior: w. Bad parameter(s): bogus") in [
        (k, v) for k, v, _ in posts]
    assert [v for k, v, _ in posts if k == "DONE"] == [0.0]
    assert any(k == "IVPHELM_LIFE_EVENT" and "event=death" in v for k, v, _ in posts)
    status = [v for k, v, _ in posts if k == "BHV_STATUS"]
    assert "name=w,updates=0/0,state=active,pwt=100" in status
    assert status[-1] == "name=w,updates=1/2,state=completed"


def test_duration_completes_and_reset(domain, make_bhv):
    helm = Helm([make_bhv("Behavior = BHV_ConstantSpeed\n{\n speed = 1\n duration = 5\n perpetual = true\n"
                          " duration_reset = RST=true\n duration_status = LEFT\n endflag = OVER = 1\n}\n")],
                domain, "abe", active_start=True)
    helm.startup(0)
    posts = []
    for t in range(0, 16):
        mail = dict(NAV_X=0.0, NAV_Y=0.0, NAV_HEADING=0.0, NAV_SPEED=0.0)
        if t == 9:
            mail["RST"] = "true"
        for k, v in mail.items():
            helm.on_mail(k, v, float(t))
        posts += [(t, k, v) for k, v, _ in helm.iterate(float(t))]
    assert [t for t, k, _ in posts if k == "OVER"] == [6, 14]   # clock restarted at 6, reset by RST at 9
    assert (2, "LEFT", 4.0) in posts


def test_station_keep_speed_profile_and_hibernation(domain):
    info = InfoBuffer()
    sk = BHV_StationKeep(domain, info, "abe")
    for k, v in dict(station_pt="0,0", inner_radius=5, outer_radius=10, outer_speed=1, transit_speed=2,
                     hibernation_radius=20).items():
        sk.apply(k, str(v))
    sk.pskeep = "seeking_station"
    assert [sk.desired_speed(d) for d in (3, 7.5, 12)] == [0, 0.5, 2]
    at(info, 30, 0)
    sk.now = 0.0
    assert sk.on_run_state() is not None and sk.pskeep == "seeking_station"   # set, then 30 > 20
    assert sk.posts[-1].var == "VIEW_POLYGON" and "radius=20.0" in sk.posts[-1].value
    at(info, 3, 0)
    sk.now = 1.0
    fn = sk.on_run_state()
    assert sk.pskeep == "hibernating"
    assert np.unravel_index(np.argmax(fn.values), fn.values.shape)[1] == 0
    with pytest.raises(ValueError):
        sk.apply("station_pt", "nowhere")


def test_station_keep_rings_follow_their_settings(domain):
    """The ring texts are kept between iterations and rebuilt when the radius, hints or station change."""
    info = InfoBuffer()
    sk = BHV_StationKeep(domain, info, "abe")
    sk.apply("station_pt", "0,0")
    at(info, 30, 0)

    def rings(now):
        sk.now, sk.posts = now, []
        sk.on_run_state()
        return {p.key: p.value for p in sk.posts if p.var == "VIEW_POLYGON"}

    first = rings(0.0)
    assert rings(1.0) == first and "radius=15.0" in first["out"]
    sk.apply("outer_radius", "25")
    sk.apply("visual_hints", "edge_color=pink")
    assert "radius=25.0" in rings(2.0)["out"] and "edge_color=pink" in rings(3.0)["in"]
    sk.apply("station_pt", "10,5")
    assert "x=10.0,y=5.0" in rings(4.0)["out"]


def test_greedy_tour_from_ownship(domain):
    w, info = waypoint(domain)
    at(info, 100, 0)
    w.apply("points", "0,0:90,0:50,0:10,0")
    w.apply("greedy_tour", "true")
    assert w.points.tolist() == [[90, 0], [50, 0], [10, 0], [0, 0]]


def test_loiter_direction_and_parameters(domain):
    from behaviors.bhv_loiter import BHV_Loiter
    info = InfoBuffer()
    lt = BHV_Loiter(domain, info, "abe")
    lt.apply("polygon", "0,0:0,10:10,10:10,0")             # clockwise as written
    lt.apply("clockwise", "false")
    assert lt.points.tolist() == [[10, 0], [10, 10], [0, 10], [0, 0]]
    at(info, 9, 11)
    lt.apply("center_assign", "50,50")
    assert lt.points.mean(axis=0).tolist() == [50, 50] and lt.ix == 3   # entered at (45,45), the nearest
    for key, value in (("clockwise", "maybe"), ("points", "1,2"), ("polygon", "radial:: x=0,y=0,radius=5")):
        with pytest.raises(ValueError):
            lt.apply(key, value)


def test_hibernation_after_the_approach_stops_closing(domain):
    info = InfoBuffer()
    sk = BHV_StationKeep(domain, info, "abe")
    for k, v in dict(station_pt="0,0", inner_radius=5, outer_radius=10, hibernation_radius=20).items():
        sk.apply(k, str(v))
    track = [(0, 30)] + [(t, 19 - t) for t in range(1, 8)] + [(t, 12) for t in range(8, 16)]
    modes = []
    for t, d in track:
        sk.now = float(t)
        at(info, d, 0)
        sk.posts = []
        sk.on_run_state()
        modes.append(sk.pskeep)
    assert modes[0] == "seeking_station" and "hibernating" not in modes[:14]
    assert modes[-1] == "hibernating"                      # 12 m out, inside the 20 m radius, stalled
    sk.now = 16.0
    at(info, 25, 0)
    sk.on_run_state()
    assert sk.pskeep == "seeking_station" and sk.desired_speed(25) == sk.transit_speed


def test_post_suffix_and_silent_status(domain):
    w, info = waypoint(domain, points="0,50", post_suffix="b", wpt_index="silent")
    at(info, 0, 0)
    w.on_run_state()
    names = {p.var for p in w.posts}
    assert {"WPT_STAT_b", "CYCLE_INDEX_b"} <= names and not any(n.startswith(("WPT_INDEX", "silent")) for n in names)


def test_distance_posts_and_their_idle_value(domain):
    w, info = waypoint(domain, points="0,50:0,100", wpt_dist_to_next="TO_NEXT", wpt_dist_to_prev="TO_PREV")
    at(info, 0, 10)
    w.on_run_state()
    posted = {p.var: p.value for p in w.posts}
    assert (posted["TO_NEXT"], posted["TO_PREV"]) == (40, 0)
    w.posts = []
    w.on_run_to_idle()
    assert {p.var: p.value for p in w.posts if p.var.startswith("TO_")} == {"TO_NEXT": -1, "TO_PREV": -1}


def test_leg_odometer(domain):
    w, info = waypoint(domain, points="0,50:0,100", capture_radius=3)
    odo = []
    for y in (0, 10, 25, 48, 60):
        at(info, 0, y)
        w.posts = []
        w.on_run_state()
        odo.append(next(p.value for p in w.posts if p.var == "WPT_ODO"))
    assert odo == [0, 10, 25, 0, 12]
