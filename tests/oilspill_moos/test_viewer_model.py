"""pMarineViewer's pure parts: NODE_REPORT / VIEW_* / button parsers, the Scene, settings, alog replay."""
import asyncio
import json
import math

import pytest
import shapely
import websockets
from hypothesis import given, settings
from hypothesis import strategies as st

from moosdb_py.alog import alog_header, format_alog_line
from moosdb_py.mission import read_mission
from moosdb_py.source import MissionFileError
from moosdb_py.geodesy import LocalGrid
from oilspill_moos.messages import Boundary, format_forecast
from oilspill_moos.viewer.app import MarineViewer, Replay, page_setup, read_settings, serve_replay
from oilspill_moos.viewer.model import (
    Button,
    Scene,
    ViewError,
    merge_button,
    parse_action,
    parse_button,
    parse_forecast,
    parse_node_report,
    parse_view,
)

SPEC_REPORT = ("NAME=abe,X=12.51,Y=-40.2,SPD=1.98,HDG=181.3,DEP=0,LAT=43.82494,LON=-70.3302,TYPE=kayak,"
               "COLOR=yellow,MODE=MODE@ACTIVE:SURVEYING,ALLSTOP=clear,INDEX=417,YAW=-1.5934856,"
               "TIME=1708012345.23,LENGTH=4")
STATION_CIRCLE = ("radial:: x=20.0,y=-20.0,source=abe:station-keep,pts=32,edge_size=1,vertex_size=1,"
                  "edge_color=light_blue,label_color=white,vertex_color=red,label=abe:station-keep-out,radius=15.0")


def test_node_report_of_the_spec():
    report = parse_node_report(SPEC_REPORT)
    assert (report.name, report.x, report.y, report.speed, report.heading) == ("abe", 12.51, -40.2, 1.98, 181.3)
    assert (report.mode, report.phase, report.color, report.type, report.length) == (
        "MODE@ACTIVE:SURVEYING", "SURVEYING", "yellow", "kayak", 4.0)
    assert report.time == 1708012345.23


def test_node_report_keys_in_any_case_and_lat_long_only_with_a_grid():
    assert parse_node_report("name=ben,x=1,y=2,mode=MODE@INACTIVE").phase == "INACTIVE"
    grid = LocalGrid(28.736667, -88.387222)
    lat, lon = grid.to_latlon(300.0, -120.0)
    report = parse_node_report(f"NAME=cal,LAT={float(lat):.8f},LONG={float(lon):.8f}", grid)
    assert (report.x, report.y) == (pytest.approx(300.0, abs=0.01), pytest.approx(-120.0, abs=0.01))


@pytest.mark.parametrize("text, says", [("X=1,Y=2", "without NAME"), ("NAME=a,Y=2", "without X"),
                                         ("NAME=a,X=east,Y=2", "X: expected a number, got 'east'"),
                                         ("NAME=a,X=1,Y=nan", "Y: expected a finite number")])
def test_bad_node_reports_say_what_is_wrong(text, says):
    with pytest.raises(ViewError, match=says):
        parse_node_report(text)


@settings(max_examples=60, deadline=None)
@given(name=st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True),
       x=st.floats(-1e5, 1e5), y=st.floats(-1e5, 1e5), hdg=st.floats(0, 359.99), spd=st.floats(0, 20))
def test_node_report_reads_back_what_pnodereporter_writes(name, x, y, hdg, spd):
    text = f"NAME={name},X={x:.2f},Y={y:.2f},SPD={spd:.2f},HDG={hdg:.2f},MODE=MODE@ACTIVE:OIL-PATH,INDEX=3"
    report = parse_node_report(text)
    assert report.name == name and report.phase == "OIL-PATH"
    assert (report.x, report.y) == (pytest.approx(round(x, 2)), pytest.approx(round(y, 2)))
    assert report.heading == pytest.approx(round(hdg, 2) % 360.0) and report.speed == pytest.approx(round(spd, 2))


def test_view_polygon_radial_circle_of_the_station_keep_behaviour():
    marker = parse_view("VIEW_POLYGON", STATION_CIRCLE)
    assert marker.kind == "polygon" and marker.label == "abe:station-keep-out" and marker.active
    assert len(marker.points) == 32
    assert all(math.hypot(x - 20, y + 20) == pytest.approx(15.0) for x, y in marker.points)
    assert dict(marker.style)["edge_color"] == "light_blue" and "radius" not in dict(marker.style)


def test_view_polygon_point_list_may_be_concave_and_inactive_ones_need_no_points():
    spill = parse_view("VIEW_POLYGON", "pts={0,0:100,0:100,100:50,20:0,100},label=standoff,edge_color=orange")
    assert len(spill.points) == 5 and spill.label == "standoff"
    erase = parse_view("VIEW_POLYGON", "label=standoff,active=false")
    assert (erase.label, erase.active, erase.points) == ("standoff", False, ())


def test_view_active_is_a_moos_boolean_and_quoted_labels_keep_their_commas():
    assert not parse_view("VIEW_POLYGON", "label=standoff,active=off").active
    assert parse_view("VIEW_POINT", 'x=1,y=2,label="abe, next",active=1').label == "abe, next"
    with pytest.raises(ViewError, match="VIEW_POLYGON .*active"):
        parse_view("VIEW_POLYGON", "pts={0,0:1,0:1,1},label=standoff,active=maybe")
    with pytest.raises(ViewError, match="unclosed double quote"):
        parse_view("VIEW_POINT", 'x=1,y=2,label="abe')


def test_view_seglist_and_point_as_the_waypoint_behaviour_posts_them():
    seglist = parse_view("VIEW_SEGLIST", "pts={10,-20:30,-40:50,-60},label=abe_waypt_loop,edge_color=gray50")
    assert seglist.points == ((10, -20), (30, -40), (50, -60)) and seglist.label == "abe_waypt_loop"
    point = parse_view("VIEW_POINT", "x=12.5,y=-3,label=abe's nextpt,vertex_color=yellow,active=true")
    assert point.points == ((12.5, -3.0),) and point.label == "abe's nextpt"
    assert not parse_view("VIEW_POINT", "x=12.5,y=-3,label=abe's nextpt,active=false").active


@pytest.mark.parametrize("key, text", [("VIEW_POLYGON", "pts={1,2:3,x=4},label=x"), ("VIEW_POINT", "label=only"),
                                       ("VIEW_SEGLIST", "label=nothing"), ("VIEW_CIRCLE", "x=1,y=2")])
def test_bad_view_strings_are_refused_with_the_string(key, text):
    with pytest.raises(ViewError, match=key):
        parse_view(key, text)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(-5000, 5000), st.integers(-5000, 5000)), min_size=1, max_size=30),
       st.from_regex(r"[a-z][a-z0-9_]{0,10}", fullmatch=True))
def test_view_seglist_round_trip(points, label):
    text = "pts={" + ":".join(f"{x},{y}" for x, y in points) + f"}},label={label}"
    marker = parse_view("VIEW_SEGLIST", text)
    assert marker.points == tuple((float(x), float(y)) for x, y in points) and marker.label == label


decimetres = st.floats(-5e4, 5e4).map(lambda v: round(v, 1))


@settings(max_examples=40, deadline=None)
@given(points=st.lists(st.tuples(decimetres, decimetres), min_size=3, max_size=40),
       cycle=st.integers(1, 10**6), horizon=st.floats(0, 240).map(lambda v: round(v, 3)),
       valid=st.none() | st.floats(0, 4e9).map(lambda v: round(v, 3)),
       uncertainty=st.floats(0, 5000).map(lambda v: round(v, 3)),
       source=st.from_regex(r"[a-z][a-z0-9_.-]{0,12}", fullmatch=True))
def test_forecast_round_trip_from_path_assign(points, cycle, horizon, valid, uncertainty, source):
    text = format_forecast(Boundary(tuple(points), time=valid, horizon_h=horizon, uncertainty_m=uncertainty,
                                    source=source), cycle)
    forecast = parse_forecast(text)
    assert (forecast.cycle, forecast.horizon_h, forecast.valid, forecast.uncertainty_m, forecast.source) == (
        cycle, horizon, valid, uncertainty, source)
    assert forecast.points == tuple(points)
    assert bool(forecast.band) == (uncertainty > 0)


def test_forecast_band_is_the_outline_buffered_out_and_in():
    forecast = parse_forecast("cycle=3,horizon=7,valid=1272092400,uncertainty=100,source=ltc-rk4,"
                              "pts={0,0:1000,0:1000,1000:0,1000}")
    outer, hole = (shapely.LinearRing(ring) for ring in forecast.band)
    assert outer.bounds == pytest.approx((-100, -100, 1100, 1100), abs=0.1)
    assert hole.bounds == pytest.approx((100, 100, 900, 900), abs=0.1)
    assert parse_forecast("cycle=1,horizon=3,pts={0,0:10,0:0,10}").band == ()   # no uncertainty, no band


@pytest.mark.parametrize("text, says", [("horizon=3,pts={0,0:1,0:0,1}", "needs cycle="),
                                         ("cycle=1,horizon=3", "needs cycle="),
                                         ("cycle=1,horizon=soon,pts={0,0:1,0:0,1}", "horizon: expected a number"),
                                         ("cycle=1,horizon=3,uncertainty=-5,pts={0,0:1,0:0,1}", "uncertainty"),
                                         ("cycle=1,horizon=3,pts={0,0:1,0}", "3 points at least")])
def test_bad_forecasts_are_refused_with_the_string(text, says):
    with pytest.raises(ViewError, match=f"OILSPILL_FORECAST .*{says}"):
        parse_forecast(text)


def test_scene_keeps_the_horizons_of_the_latest_forecast_cycle():
    scene = Scene()
    square = "pts={0,0:100,0:100,100:0,100}"
    logged = []
    for horizon in (7, 3, 15):
        update, *notes = scene.apply("OILSPILL_FORECAST", f"cycle=1,horizon={horizon},uncertainty=20,{square}", 1.0)
        logged += notes
    assert [f["horizon"] for f in update["forecasts"]] == [3, 7, 15] and update["t"] == "forecasts"
    assert [n["text"] for n in logged] == ["forecast cycle 1 (no source)"]   # a new forecast is logged once
    [update] = scene.apply("OILSPILL_FORECAST", f"cycle=1,horizon=7,uncertainty=50,{square}", 2.0)
    assert [(f["horizon"], f["uncertainty"]) for f in update["forecasts"]] == [(3, 20), (7, 50), (15, 20)]
    with pytest.raises(ViewError):
        scene.apply("OILSPILL_FORECAST", "cycle=2,horizon=3,pts={0,0}", 3.0)
    assert len(scene.forecasts) == 3   # a bad one leaves the picture alone
    update, note = scene.apply("OILSPILL_FORECAST", f"cycle=2,horizon=3,source=ltc-rk4,{square}", 4.0)
    assert [(f["cycle"], f["horizon"], f["source"]) for f in update["forecasts"]] == [(2, 3, "ltc-rk4")]
    assert note["text"] == "forecast cycle 2 (ltc-rk4)" and note["time"] == 4.0
    snap = scene.snapshot()
    json.dumps(snap)
    assert snap["forecasts"] == update["forecasts"]


def test_buttons_configured_as_in_pmarineviewer():
    button = parse_button("DEPLOY # DEPLOY_ALL=true # MOOS_MANUAL_OVERRIDE_ALL=false")
    assert button.label == "DEPLOY"
    assert button.pokes == (("DEPLOY_ALL", "true"), ("MOOS_MANUAL_OVERRIDE_ALL", "false"))
    assert parse_button('SLOWER # WPT_UPDATE=speed=1.5 # GAIN=2.5 # LABEL="3"').pokes == (
        ("WPT_UPDATE", "speed=1.5"), ("GAIN", 2.5), ("LABEL", "3"))
    # corpus missions split one button over lines, and may give no label at all
    joined = merge_button([parse_button("DEPLOY  # DEPLOY_ALL=true "), parse_button("MOOS_MANUAL_OVERRIDE_ALL=false")])
    assert joined == Button("DEPLOY", (("DEPLOY_ALL", "true"), ("MOOS_MANUAL_OVERRIDE_ALL", "false")))
    assert merge_button([parse_button("RETURN_ALL=false # STATION_KEEP_ALL=false")]).label == "RETURN_ALL=false"
    for bad in ("A # B # C=1", "GO # TWO WORDS=1", "GO # =1", "GO ## X=1"):
        with pytest.raises(ViewError, match="button"):
            parse_button(bad)
    with pytest.raises(ViewError, match="no VAR=value"):
        merge_button([parse_button("DEPLOY")])


def test_action_menu_lines_as_in_pmarineviewer():
    assert parse_action("MENU_KEY=deploy # DEPLOY = true # RETURN = false") == Button(
        "deploy", (("DEPLOY", "true"), ("RETURN", "false")))
    assert parse_action("UPDATES_RETURN=speed=1.4") == Button("UPDATES_RETURN=speed=1.4",
                                                              (("UPDATES_RETURN", "speed=1.4"),))
    for bad in ("HOLD # X=1", "MENU_KEY=empty", "# "):
        with pytest.raises(ViewError, match="action|button"):
            parse_action(bad)


def test_scene_follows_the_mission_and_snapshots_it():
    scene = Scene(trail_length=3)
    for i in range(5):
        update, *notes = scene.apply("NODE_REPORT", f"NAME=abe,X={i},Y=0,HDG=90,MODE=MODE@ACTIVE:STATION-KEEPING",
                                     10.0 + i)
        assert len(notes) == (1 if i == 0 else 0)   # the log has its first report, not every one
    assert update["phase"] == "STATION-KEEPING" and update["seen"] == 14.0
    scene.apply("OILSPILL_BOUNDARY", "pts={0,0:100,0:100,100},label=oilspill_1", 15.0)
    scene.apply("OILSPILL_PHASE", "STARTING-POSITION", 15.0)
    assert scene.apply("OILSPILL_PHASE_ALL", "STARTING-POSITION", 15.0) == [
        {"t": "commanded", "name": "abe", "phase": "STARTING-POSITION"}]
    scene.apply("STARTING_POSITION_UPDATES_ABE", "points=-10.0,5.0", 15.0)
    scene.apply("OIL_PATH_UPDATES_ABE", "points=-10,5:0,-10:10,5#repeat=forever#speed=2", 16.0)
    scene.apply("VIEW_POLYGON", "pts={0,0:1,0:1,1},label=standoff", 16.0)
    [status] = scene.apply("OILSPILL_STATUS", "phase=OIL-PATH,vehicles=abe,Boundary_Age=2.5", 17.0)
    assert status["fields"] == [["phase", "OIL-PATH"], ["vehicles", "abe"], ["boundary_age", "2.5"]]
    with pytest.raises(ViewError, match="OILSPILL_STATUS 'phase=OIL-PATH,oops'"):   # the page shows one field a row
        scene.apply("OILSPILL_STATUS", "phase=OIL-PATH,oops", 17.0)
    scene.apply("OILSPILL_WARNING", "127.0.0.1:5000: bad JSON", 17.0)
    snap = scene.snapshot()
    json.dumps(snap)  # the page gets it as JSON
    assert snap["vehicles"][0]["trail"] == [[2.0, 0.0], [3.0, 0.0], [4.0, 0.0]]
    assert snap["boundary"] == [[0, 0], [100, 0], [100, 100]] and snap["phase"] == "STARTING-POSITION"
    assert snap["starts"] == {"abe": [-10.0, 5.0]} and snap["loops"]["abe"][1] == [0.0, -10.0]
    assert [m["label"] for m in snap["markers"]] == ["standoff"] and snap["notes"][-1]["level"] == "warning"
    assert [(n["level"], n["text"]) for n in snap["notes"][:-1]] == [   # pushes and phase changes are logged
        ("event", "abe reporting, STATION-KEEPING"), ("event", "boundary in force: oilspill_1, 3 vertices"),
        ("phase", "fleet phase STARTING-POSITION")]
    scene.apply("VIEW_POLYGON", "pts={0,0:1,0:1,1},label=standoff,active=false", 18.0)
    assert scene.snapshot()["markers"] == []
    with pytest.raises(ViewError, match="STARTING_POSITION_UPDATES_ABE"):
        scene.apply("STARTING_POSITION_UPDATES_ABE", "x=1,y=2", 19.0)
    assert scene.starts == {"abe": [-10.0, 5.0]}   # a bad update leaves the picture alone


def test_scene_keeps_the_vessels_oil_observations_and_the_fusion_edge():
    scene = Scene()
    [obs] = scene.apply("OIL_OBSERVATION", "vname=abe,id=17,utc=5.5,x=12,y=-3.5,oil=1,range=15", 20.0)
    assert obs == {"t": "obs", "vname": "abe", "x": 12.0, "y": -3.5, "oil": True, "range": 15.0}
    scene.apply("OIL_OBSERVATION", "vname=ben,id=2,utc=6,x=40,y=0,oil=0,range=15", 21.0)
    with pytest.raises(ViewError, match="OIL_OBSERVATION: .*lacks oil"):
        scene.apply("OIL_OBSERVATION", "vname=ben,id=3,utc=6,x=40,y=0", 22.0)
    scene.apply("OIL_OBSERVED_EDGE", "26.0,-1.8:30.5,4.0", 23.0)
    scene.apply("OIL_FUSION_SKILL", "cycle=oilspill_1,observations=2,agreement=0.5", 23.0)
    snap = scene.snapshot()
    assert [o["oil"] for o in snap["observations"]] == [True, False]
    assert snap["observed_edge"] == [[26.0, -1.8], [30.5, 4.0]] and snap["skill"].startswith("cycle=oilspill_1")


def test_settings_default_buttons_and_boundary_port_from_path_assign(tmp_path):
    moos = tmp_path / "shore.moos"
    moos.write_text("ServerPort = 9000\nCommunity = shoreside\nLatOrigin = 28.7\nLongOrigin = -88.4\n"
                    "ProcessConfig = pPathAssign\n{\n  boundary_port = 9321\n}\n"
                    "ProcessConfig = pMarineViewer\n{\n  http_port = 0\n  button_one = GO # DEPLOY_ALL=true\n"
                    "  button_two = RETURN # RETURN_ALL=true\n  button_one = MOOS_MANUAL_OVERRIDE_ALL=false\n"
                    "  action = RETURN=true\n}\n")
    mission = read_mission(moos)
    got = read_settings(mission.process_config("pMarineViewer"), mission)
    assert got["boundary_port"] == 9321 and got["http_port"] == 0 and got["http_host"] == "127.0.0.1"
    assert [b.label for b in got["buttons"]] == ["GO", "RETURN", "RETURN_ALL"]
    assert got["buttons"][0].pokes == (("DEPLOY_ALL", "true"), ("MOOS_MANUAL_OVERRIDE_ALL", "false"))
    assert got["actions"] == [Button("RETURN=true", (("RETURN", "true"),))]
    assert [b.label for b in read_settings({}, None)["buttons"]] == ["DEPLOY", "RETURN_ALL"]
    moos.write_text(moos.read_text().replace("RETURN # RETURN_ALL=true", "RETURN # RETURN ALL=true"))
    mission = read_mission(moos)
    with pytest.raises(MissionFileError, match=r"shore.moos:13: .*RETURN ALL=true"):
        read_settings(mission.process_config("pMarineViewer"), mission)


def test_command_line_pages(capsys):
    for flag, says in (("--example", "button_one = DEPLOY"), ("--interface", "VIEW_POLYGON"),
                       ("--help", "--replay=FILE")):
        assert MarineViewer.main([flag]) == 0
        assert says in capsys.readouterr().out
    assert MarineViewer.main(["--http_port=eighty"]) == 1
    assert "--http_port=eighty is not a port" in capsys.readouterr().err


def write_alog(path, lines):
    with open(path, "w") as f:
        f.write(alog_header(str(path), 1000.0))
        for t, key, value in lines:
            f.write(format_alog_line(t, key, "pNodeReporter", value))


def test_replay_plays_seeks_back_and_reports_bad_lines(tmp_path):
    alog = tmp_path / "LOG_SHORESIDE.alog"
    write_alog(alog, [(1.0, "NODE_REPORT", "NAME=abe,X=0,Y=0,MODE=MODE@INACTIVE"),
                      (2.0, "DB_UPTIME", "2"),
                      (5.0, "NODE_REPORT", "NAME=abe,X=10,Y=0,MODE=MODE@ACTIVE:STATION-KEEPING"),
                      (6.0, "NODE_REPORT", "NAME=abe,X=oops,Y=0"),
                      (9.0, "OILSPILL_PHASE", "OIL-PATH")])
    replay = Replay(alog)
    assert replay.end == 9.0 and len(replay.entries) == 4
    replay.speed = 2.0
    assert [u["x"] for u in replay.advance(1.0) if u["t"] == "vehicle"] == [0.0]       # t = 2
    updates = replay.advance(2.5)                                                     # t = 7
    assert [u["t"] for u in updates] == ["vehicle", "note", "note"] and "LOG_SHORESIDE.alog:" in updates[2]["text"]
    assert updates[1]["text"] == "abe: INACTIVE -> STATION-KEEPING" and updates[1]["level"] == "phase"
    replay.seek(3.0)
    assert replay.scene.vehicles["abe"].report.x == 0.0 and len(replay.scene.vehicles["abe"].trail) == 1
    replay.advance(100.0)
    assert replay.scene.phase == "OIL-PATH" and not replay.playing and replay.t == 9.0


def test_replay_server_serves_the_page_and_obeys_its_controls(tmp_path):
    alog = tmp_path / "LOG.alog"
    write_alog(alog, [(float(t), "NODE_REPORT", f"NAME=abe,X={t},Y=0") for t in range(0, 100, 5)])
    asyncio.run(drive_replay(Replay(alog)))


async def drive_replay(replay):
    ready, stop = asyncio.get_running_loop().create_future(), asyncio.Event()
    task = asyncio.create_task(serve_replay(replay, "127.0.0.1", 0, 20.0, page_setup(None, [], "", "replay"),
                                            ready, stop))
    port = await asyncio.wait_for(ready, 5)
    async with websockets.connect(f"ws://127.0.0.1:{port}/ws") as page:
        snapshot = json.loads(await page.recv())
        assert snapshot["type"] == "snapshot" and snapshot["mode"] == "replay" and snapshot["replay"]["end"] == 95.0
        await page.send(json.dumps({"cmd": "pause"}))
        await page.send(json.dumps({"cmd": "seek", "t": 50}))
        while (message := json.loads(await asyncio.wait_for(page.recv(), 5)))["type"] != "snapshot":
            pass
        assert message["replay"]["t"] == 50.0 and not message["replay"]["playing"]
        assert message["vehicles"][0]["x"] == 50.0 and len(message["vehicles"][0]["trail"]) == 11
        await page.send(json.dumps({"cmd": "speed", "speed": 40}))
        await page.send(json.dumps({"cmd": "speed", "speed": -3}))     # refused: the clock only runs forward
        await page.send(json.dumps({"cmd": "play"}))
        while not (message := json.loads(await asyncio.wait_for(page.recv(), 5))).get("updates"):
            pass
        assert message["replay"]["speed"] == 40.0 and message["replay"]["playing"] and message["replay"]["t"] > 50.0
        assert message["updates"][0]["x"] > 50.0
    stop.set()
    await asyncio.wait_for(task, 5)
