"""Gaps found auditing the helm against docs/spec/ivp-helm.md: config warnings, nav grace, hold_on_apps, the
summary's timing fields, WPT_EFF_* posts, node-message flags and the unsupported roc objective."""
from pathlib import Path

import pytest

from behaviors.behavior import InfoBuffer
from behaviors.bhv_waypoint import BHV_Waypoint
from behaviors.helm import Helm

from helm_sim import Boat, run

MISSION = ("ServerHost = localhost\nServerPort = 9000\nCommunity = abe\n{origin}\n"
           "ProcessConfig = pHelmIvP\n{{\n  AppTick = 4\n  behaviors = t.bhv\n  domain = course:0:359:360\n"
           "  domain = speed:0:4:41\n{extra}}}\n")
GO = "Behavior = BHV_Waypoint\n{\n  name = go\n  points = 0,100\n  speed = 2\n}\n"


def helm_app(tmp_path: Path, extra: str = "", origin: str = "LatOrigin = 43.8\nLongOrigin = -70.3\n"):
    from behaviors.helm_app import HelmIvP
    (tmp_path / "t.bhv").write_text(GO)
    moos = tmp_path / "t.moos"
    moos.write_text(MISSION.format(origin=origin, extra=extra))
    app = HelmIvP(moos)
    app.on_startup()
    return app, moos


def test_unknown_parameter_gives_malconfig_naming_file_and_line(tmp_path, capsys):
    app, moos = helm_app(tmp_path, "  nav_grace = 3\n  colour = red\n  standby = 5\n  verbose = true\n"
                                   "  hold_on_apps = pMarinePID\n")
    assert app.helm.status == "MALCONFIG"
    err = capsys.readouterr().err
    assert f"{moos}:14: unknown pHelmIvP parameter 'colour'" in err
    assert f"{moos}:15: pHelmIvP parameter 'standby' is not supported by this helm" in err
    assert "MALCONFIG" in err and "verbose" not in err and "hold_on_apps" not in err
    posts = app.helm.iterate(app.moos_time())
    assert posts == [("IVPHELM_STATE", "MALCONFIG", "")]          # it never drives
    assert app.status_fields()["warnings"] == 2


def test_missing_origin_is_a_named_malconfig_and_corpus_keys_are_known(tmp_path, capsys):
    app, moos = helm_app(tmp_path, "  ok_skew = any\n  bhv_dir_not_found_ok = true\n  app_logging = true\n",
                         origin="")
    assert app.helm.config_warnings == [f"{moos}: LatOrigin/LongOrigin not set"]
    (tmp_path / "b").mkdir()
    app2, _ = helm_app(tmp_path / "b", "  ok_skew = any\n  bhv_dir_not_found_ok = true\n")
    assert app2.helm.status == "PARK" and app2.helm.config_warnings == []
    assert "unknown" not in capsys.readouterr().err


def go_helm(domain, make_bhv, text=GO, **kw):
    helm = Helm([make_bhv(text)], domain, "abe", active_start=True, **kw)
    helm.startup(0.0)
    return helm


def test_nav_grace_warning_once_and_counted_in_summary(domain, make_bhv):
    helm = go_helm(domain, make_bhv)
    helm.nav_grace = 2.0
    for t in (0.0, 1.0, 2.5, 3.0):
        helm.iterate(t)
    assert helm.run_warnings == ["No NAV_X,NAV_Y,NAV_HEADING,NAV_SPEED received after nav_grace=2 s"]
    log = []
    run(helm, Boat(), 2, start=3.25, log=log)
    summaries = [val for _, v, val in log if v == "IVPHELM_SUMMARY"]
    assert "warnings=1" in summaries[0]
    for field in ("create_time=", "solve_time=", "loop_time=", "max_loop_time=", "max_solve_time=",
                  "max_create_time=", "active_goal=false", "ofnum=1"):
        assert field in summaries[0]
    assert float(summaries[0].split("max_loop_time=")[1].split(",")[0]) > 0


def test_hold_on_apps_until_db_clients_lists_them(domain, make_bhv):
    helm = go_helm(domain, make_bhv)
    helm.hold_on_apps = ["pMarinePID", "uSimMarine"]
    assert "DB_CLIENTS" in helm.subscriptions()
    helm.on_mail("DB_CLIENTS", "pHelmIvP,uSimMarine,", 0.0)
    log = []
    end = run(helm, Boat(), 8, log=log)
    assert not any(v.startswith("DESIRED_") for _, v, _ in log)
    assert helm.run_warnings == ["hold_on_apps: holding until pMarinePID connect (DB_CLIENTS)"]
    helm.on_mail("DB_CLIENTS", "pHelmIvP,uSimMarine,pMarinePID,", end)
    log.clear()
    run(helm, Boat(), 2, start=end, log=log)
    assert any(v == "DESIRED_SPEED" and val == 2.0 for _, v, val in log)


def test_statevars_posted_at_startup(domain, make_bhv):
    helm = Helm([make_bhv("set MODE = ACTIVE {\n  DEPLOY = true\n}\n" + GO.replace(
        "speed = 2", "speed = 2\n  condition = RETURN = false"))], domain, "abe")
    posts = {v: val for v, val, _ in helm.startup(0.0)}
    assert posts["IVPHELM_STATEVARS"] == "DEPLOY,RETURN"


def test_dest_flags_become_node_messages(domain, make_bhv):
    helm = go_helm(domain, make_bhv, GO.replace("speed = 2", (
        "speed = 2\n  runflag = #all HELLO = from $[OWNSHIP]\n  runflag = #group+ ARRIVING = 3\n"
        "  runflag = #ben LIST = a,b\n  runflag = #group=red GO = true")))
    helm.on_mail("ABE_NAV_GROUP", "blue", 0.0)
    assert "ABE_NAV_GROUP" in helm.subscriptions()
    log = []
    run(helm, Boat(), 1.5, log=log)
    node = [val for _, v, val in log if v == "NODE_MESSAGE_LOCAL"]
    assert node == ["src_node=abe,dest_node=all,var_name=HELLO,string_val=from abe",
                    "src_node=abe,dest_node=all,dest_group=blue,var_name=ARRIVING,double_val=3",
                    'src_node=abe,dest_node=ben,var_name=LIST,string_val="a,b"',
                    "src_node=abe,dest_node=all,dest_group=red,var_name=GO,string_val=true"]
    local = {v for _, v, _ in log}
    assert "ARRIVING" in local and not {"HELLO", "LIST", "GO"} & local    # only `+` also posts locally


def test_efficiency_measure_posts_per_leg_and_totals(domain):
    info = InfoBuffer()
    w = BHV_Waypoint(domain, info, "abe")
    for k, v in dict(points="0,10:0,30:20,30", speed="2", capture_radius="1", efficiency_measure="all",
                     post_suffix="A").items():
        w.apply(k, v)
    track = [(0, 0, 0), (0, 9.5, 5), (5, 20, 12), (0, 29.5, 20), (10, 32, 26), (19.5, 30, 32)]
    posts = []
    for t, (x, y, _) in enumerate(track):
        w.now = track[t][2]
        for var, value in dict(NAV_X=x, NAV_Y=y, NAV_HEADING=0.0, NAV_SPEED=2.0).items():
            info.set(var, float(value), w.now)
        w.posts = []
        w.on_run_state()
        posts.append({p.var: p.value for p in w.posts})
    assert not any(k.startswith("WPT_EFF") for p in posts[:3] for k in p)   # first hit only sets the mark
    leg = posts[3]
    odo = ((5 ** 2 + 10.5 ** 2) ** 0.5 + (5 ** 2 + 9.5 ** 2) ** 0.5)
    assert leg["WPT_EFF_DIST_LEG_A"] == pytest.approx(20 / odo)
    assert leg["WPT_EFF_TIME_LEG_A"] == pytest.approx((20 / 2) / 15)
    assert leg["WPT_EFF_SUMM_LEG_A"] == (f"vname=abe, bhv_name=bhv_waypoint, linear_dist=20, odo_dist={odo:.1f}, "
                                         f"efficiency_dist={20 / odo:.3f}, linear_time=10, odo_time=15, "
                                         f"efficiency_time=0.667")
    done = posts[5]
    assert "completed" in str(done["WPT_STAT_A"]) and done["WPT_EFF_DIST_ALL_A"] < 1
    assert done["WPT_EFF_SUMM_ALL_A"].startswith("vname=abe, bhv_name=bhv_waypoint, linear_dist=39.5,")


def test_roc_objective_is_a_clear_error(domain):
    w = BHV_Waypoint(domain, InfoBuffer(), "abe")
    with pytest.raises(ValueError, match="rate of closure.*not supported.*use zaic or zaic_spd"):
        w.apply("ipf_type", "roc")


def test_visual_hints_reach_the_drawings(domain):
    from behaviors.bhv_station_keep import BHV_StationKeep
    info = InfoBuffer()
    w = BHV_Waypoint(domain, info, "abe")
    for k, v in (("points", "0,50:0,100"), ("visual_hints", "nextpt_color=red, nextpt_vertex_size=8"),
                 ("visual_hints", "edge_color=off, vertex_size=5, label=ignored")):
        w.apply(k, v)
    for var, value in dict(NAV_X=0.0, NAV_Y=0.0, NAV_HEADING=0.0, NAV_SPEED=1.0).items():
        info.set(var, value, 0.0)
    w.on_run_state()
    posts = {(p.var, p.key): p.value for p in w.posts}
    assert posts[("VIEW_SEGLIST", "")] == ("pts={0,50:0,100},label=abe_bhv_waypoint,vertex_color=dodger_blue,"
                                           "edge_color=off,label_color=white,edge_size=1,vertex_size=5")
    assert posts[("VIEW_POINT", "nextpt")] == ("x=0,y=50,label=abe's nextpt,active=true,vertex_color=red,"
                                               "label_color=aqua,vertex_size=8")
    with pytest.raises(ValueError, match="visual_hints vertex_size must be a number >= 0"):
        w.apply("visual_hints", "vertex_size=big")
    sk = BHV_StationKeep(domain, info, "abe")
    sk.apply("visual_hints", "edge_color=pink, vertex_size=2")
    sk.apply("station_pt", "20,-20")
    sk.on_run_state()
    circle = next(p.value for p in sk.posts if p.var == "VIEW_POLYGON")
    assert circle == ("radial:: x=20.0,y=-20.0,source=abe:station_keep,pts=32,edge_size=1,vertex_size=2,"
                      "edge_color=pink,label_color=white,vertex_color=red,label=abe:station-keep-out,radius=15.0")


def test_greedy_tour_waits_for_nav_and_radius_ranges(domain):
    info = InfoBuffer()
    w = BHV_Waypoint(domain, info, "abe")
    w.apply("points", "0,0:90,0:50,0:10,0")
    w.apply("greedy_tour", "true")                        # at startup ownship is not known yet
    assert w.points.tolist() == [[0, 0], [90, 0], [50, 0], [10, 0]]
    for var, value in dict(NAV_X=100.0, NAV_Y=0.0, NAV_HEADING=0.0, NAV_SPEED=1.0).items():
        info.set(var, value, 0.0)
    w.on_run_state()
    assert w.points.tolist() == [[90, 0], [50, 0], [10, 0], [0, 0]]
    for key, value in (("capture_radius", "0"), ("lead_damper", "0"), ("crs_spd_zaic_ratio", "100")):
        with pytest.raises(ValueError, match=key):
            w.apply(key, value)


def test_distance_to_go_macros(domain):
    from behaviors.flags import expand_macros
    info = InfoBuffer()
    w = BHV_Waypoint(domain, info, "abe")
    w.apply("points", "0,10:0,30:20,30")
    w.apply("repeat", "1")
    for var, value in dict(NAV_X=0.0, NAV_Y=0.0).items():
        info.set(var, value, 0.0)
    loop = 20 + 20 + (20 ** 2 + 20 ** 2) ** 0.5              # list length plus the closing gap
    assert expand_macros("$[CYC_DIST_TOGO]", w.macro) == 50.0
    assert expand_macros("$[ALL_DIST_TOGO]", w.macro) == pytest.approx(50 + loop, abs=1e-3)   # one repeat left


def test_behavior_error_halts_and_summary_says_so(domain, make_bhv):
    helm = go_helm(domain, make_bhv, GO.replace("speed = 2", "speed = 2\n  runxflag = BHV_ERROR = go: boom"))
    log = []
    run(helm, Boat(), 1.5, log=log)
    assert [val for _, v, val in log if v == "IVPHELM_ALLSTOP"] == ["BehaviorError"]
    assert "halted=true" in [val for _, v, val in log if v == "IVPHELM_SUMMARY"][0]
    assert not any(v == "DESIRED_SPEED" and val > 0 for _, v, val in log)


@pytest.mark.parametrize("params, warning", [
    ({}, "w: No waypts given. Set val to empty if intentional"),
    ({"point": "empty"}, None),
    ({"point": "5,5", "repeat": "2"}, "w: cycles/repeats not supported with single waypt"),
    ({"points": "5,5:9,9", "repeat": "forever"}, None),
])
def test_waypoint_list_warnings(domain, params, warning):
    info = InfoBuffer()
    w = BHV_Waypoint(domain, info, "abe")
    for k, v in {"name": "w", **params}.items():
        w.apply(k, v)
    for var, value in dict(NAV_X=0.0, NAV_Y=0.0, NAV_HEADING=0.0, NAV_SPEED=1.0).items():
        info.set(var, value, 0.0)
    w.on_run_state()
    assert [p.value for p in w.posts if p.var == "BHV_WARNING"] == ([warning] if warning else [])


def test_moos_lint_reports_what_would_malconfig_the_helm(tmp_path, capsys):
    from behaviors.lint import main
    moos = tmp_path / "m.moos"
    moos.write_text("LatOrigin = 1\nLongOrigin = 2\nProcessConfig = pHelmIvP\n{\n  behaviors = a.bhv\n"
                    "  colour = red\n  standby = 5\n}\n")
    assert main([str(moos)]) == 1
    assert capsys.readouterr().out.splitlines() == [
        f"{moos}:6: unknown pHelmIvP parameter 'colour'",
        f"{moos}:7: pHelmIvP parameter 'standby' is not supported by this helm"]
