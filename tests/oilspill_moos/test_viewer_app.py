"""pMarineViewer as a MOOS app against a real moosdb, with a WebSocket client in the page's place:
mail reaches the page, unreadable mail becomes a log line naming its source, a button press is
poked with the community's warped time, so is a chosen action, a page sending nonsense is ignored, and a page from
another site cannot open the WebSocket."""
import asyncio
import json
import logging

import pytest
import websockets

from helpers import CORPUS, async_wait_until, requires_shared, start_moosdb
from moosdb_py.client import MOOSClient
from moosdb_py.message import moos_time
from moosdb_py.mission import read_mission
from oilspill_moos.viewer.app import MarineViewer, warn_config
from oilspill_moos.viewer.server import MapServer

WARP = 20.0


async def next_updates(page, predicate, timeout=10.0):
    """Read batches until one of their updates satisfies `predicate`; return it."""
    async with asyncio.timeout(timeout):
        while True:
            message = json.loads(await page.recv())
            for update in message.get("updates", []):
                if predicate(update):
                    return update


def test_live_viewer_shows_mail_and_pokes_with_warped_time(moosdb_server, tmp_path):
    mission = tmp_path / "shoreside.moos"
    mission.write_text(f"ServerPort = {moosdb_server.port}\nCommunity = shoreside\nMOOSTimeWarp = {WARP:g}\n"
                       "ProcessConfig = pMarineViewer\n{\n  http_port = 0\n  action = MENU_KEY=hold # STATION_KEEP_ALL=true\n}\n"
                       "ProcessConfig = pPathAssign\n{\n  boundary_port = 9100\n}\n")   # an oil-spill shoreside

    async def scenario():
        app = MarineViewer(mission)
        poked = []
        watcher = MOOSClient("uOperatorWatch", port=moosdb_server.port, time_warp=WARP,
                             on_mail=lambda mail: poked.extend(m for m in mail if m.key != "NODE_REPORT"))
        watcher.register("DEPLOY_ALL")
        watcher.register("STATION_KEEP_ALL")
        tasks = [asyncio.create_task(app.run_async()), asyncio.create_task(watcher.run())]
        try:
            await watcher.wait_connected(10)
            await async_wait_until(lambda: getattr(app, "server", None) is not None and app.client.connected, 10)
            with pytest.raises(websockets.InvalidStatus, match="403"):   # another site's page in the browser
                await websockets.connect(f"ws://127.0.0.1:{app.server.port}/ws", origin="http://elsewhere.example")
            async with websockets.connect(f"ws://127.0.0.1:{app.server.port}/ws",
                                          origin=f"http://localhost:{app.server.port}") as page:
                snapshot = json.loads(await page.recv())
                assert snapshot["buttons"] == ["DEPLOY", "RETURN_ALL", "RE-PUSH BOUNDARY"]
                assert snapshot["actions"] == ["hold"] and snapshot["community"] == "shoreside"
                watcher.notify("NODE_REPORT", "NAME=abe,X=5,Y=-7,HDG=90,SPD=1.5,MODE=MODE@ACTIVE:OIL-PATH")
                vehicle = await next_updates(page, lambda u: u["t"] == "vehicle")
                assert (vehicle["name"], vehicle["x"], vehicle["phase"]) == ("abe", 5.0, "OIL-PATH")
                watcher.notify("VIEW_POLYGON", "pts={0,0:10,0:x=1},label=broken")
                note = await next_updates(page, lambda u: u["t"] == "note")
                assert note["level"] == "error" and "VIEW_POLYGON from uOperatorWatch@" in note["text"]
                await page.send("not json")
                await page.send(json.dumps({"cmd": "button", "index": 99}))
                await page.send(json.dumps({"cmd": "button", "index": 0}))
                note = await next_updates(page, lambda u: u["t"] == "note")
                assert note["text"].startswith("DEPLOY: DEPLOY_ALL=true")
                await page.send(json.dumps({"cmd": "action", "index": 0}))
                await async_wait_until(lambda: len(poked) == 2, 10)
                assert [(m.key, m.string) for m in poked] == [("DEPLOY_ALL", "true"), ("STATION_KEEP_ALL", "true")]
                assert abs(poked[0].time - moos_time(WARP)) < 5 * WARP   # warped MOOS time, not the wall clock
        finally:
            app.stop()
            watcher.close()
            await asyncio.wait_for(asyncio.gather(*tasks, return_exceptions=True), 10)

    asyncio.run(scenario())


def test_single_vehicle_mission_shows_its_node_report_local_and_the_end_of_the_mission(tmp_path):
    """A mission with no spill and no shoreside (s1_alpha-like): NODE_REPORT_LOCAL draws the vehicle, the
    page gets no RE-PUSH BOUNDARY; when the MOOSDB goes away the page is told the mission ended, and a
    page opened afterwards still gets the last picture."""
    db = start_moosdb()
    mission = tmp_path / "alpha.moos"
    mission.write_text(f"ServerPort = {db.port}\nCommunity = alpha\nMOOSTimeWarp = {WARP:g}\n"
                       "ProcessConfig = pMarineViewer\n{\n  http_port = 0\n}\n")

    async def scenario():
        app = MarineViewer(mission)
        vehicle = MOOSClient("pNodeReporter", port=db.port, time_warp=WARP)
        tasks = [asyncio.create_task(app.run_async()), asyncio.create_task(vehicle.run())]
        try:
            await vehicle.wait_connected(10)
            await async_wait_until(lambda: getattr(app, "server", None) is not None and app.client.connected, 10)
            async with websockets.connect(f"ws://127.0.0.1:{app.server.port}/ws") as page:
                snapshot = json.loads(await page.recv())
                assert snapshot["spill"] is False and snapshot["buttons"] == ["DEPLOY", "RETURN_ALL"]
                assert snapshot["ended"] == ""
                vehicle.notify("NODE_REPORT_LOCAL", "NAME=alpha,X=12,Y=-3,HDG=90,SPD=2,MODE=MODE@ACTIVE:SURVEYING")
                shown = await next_updates(page, lambda u: u["t"] == "vehicle")
                assert (shown["name"], shown["x"], shown["phase"]) == ("alpha", 12.0, "SURVEYING")
                vehicle.close()
                db.stop()
                ended = await next_updates(page, lambda u: u["t"] == "ended")
                assert ended["text"] == f"the MOOSDB at 127.0.0.1:{db.port} went away"
            async with websockets.connect(f"ws://127.0.0.1:{app.server.port}/ws") as page:
                snapshot = json.loads(await page.recv())
                assert snapshot["ended"] == ended["text"] and [v["name"] for v in snapshot["vehicles"]] == ["alpha"]
                assert snapshot["notes"][-1]["text"] == f"mission ended: {ended['text']}"
        finally:
            app.stop()
            vehicle.close()
            await asyncio.wait_for(asyncio.gather(*tasks, return_exceptions=True), 10)
            db.stop()

    asyncio.run(scenario())


def test_websocket_only_from_the_viewers_own_page():
    server = MapServer("0.0.0.0", 8080, dict, None)   # served to the whole network: opened by any name
    assert server.own_page("http://shore.example:8080", "shore.example:8080")
    assert server.own_page("http://localhost:8080", "127.0.0.1:8080")
    assert not server.own_page("http://evil.example", "shore.example:8080")
    assert not server.own_page("http://shore.example:8081", "shore.example:8080")


@requires_shared("missions-corpus")
def test_cpp_viewer_parameters_are_one_summary_line_but_misspelt_keys_warn(tmp_path, caplog):
    mission = read_mission(CORPUS / "s1_alpha" / "alpha.moos")
    with caplog.at_level(logging.WARNING):
        warn_config(mission.process_config("pMarineViewer"), "pMarineViewer")
    assert len(caplog.records) == 1
    line = caplog.records[0].getMessage()
    assert line.startswith("pMarineViewer: ignoring 19 parameters of the C++ viewer it does not implement: tiff_file, ")
    assert "right_context[return]" in line and "action+" in line
    caplog.clear()
    path = tmp_path / "m.moos"
    path.write_text("ProcessConfig = pMarineViewer\n{\n  tiff_file = forrest19.tif\n  zoom = 0.6\n"
                    "  tiff_fil = x.tif\n  http_prot = 8081\n  left_context[station] = STATION=true\n}\n")
    with caplog.at_level(logging.WARNING):
        warn_config(read_mission(path).process_config("pMarineViewer"), "pMarineViewer")
    messages = [r.getMessage() for r in caplog.records]
    assert messages[0] == ("pMarineViewer: ignoring 3 parameters of the C++ viewer it does not implement: "
                           "tiff_file, zoom, left_context[station]")
    assert messages[1:] == [f"{path}:5: unhandled parameter 'tiff_fil'", f"{path}:6: unhandled parameter 'http_prot'"]
