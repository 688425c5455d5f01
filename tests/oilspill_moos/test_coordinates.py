"""pCoordinates against a real moosdb: reports when station-keeping begins and on request, never without nav."""
import asyncio

from helpers import async_wait_until
from moosdb_py.client import MOOSClient
from oilspill_moos.messages import coordinates_report
from oilspill_moos.response.coordinates import Coordinates


def write_mission(tmp_path, port, block=""):
    path = tmp_path / "abe.moos"
    path.write_text(f"ServerHost = localhost\nServerPort = {port}\nCommunity = abe\n\n"
                    f"ProcessConfig = pCoordinates\n{{\n  AppTick = 20\n{block}}}\n")
    return path


async def with_app(mission, scenario):
    app = Coordinates(mission)
    got = []
    probe = MOOSClient("probe", port=app.client.port, on_mail=lambda mail: got.extend(
        m for m in mail if m.key == "VEHICLE_COORDINATES"))
    tasks = [asyncio.create_task(app.run_async()), asyncio.create_task(probe.run())]
    try:
        assert await probe.wait_connected(5)
        probe.register("VEHICLE_COORDINATES")
        await async_wait_until(lambda: app.client.connected and "REPORT_COORDINATES" in app.client.registrations, 5)
        await scenario(app, probe, got)
    finally:
        app.stop()
        probe.close()
        await asyncio.wait_for(asyncio.gather(*tasks), 5)


def test_reports_on_station_keep_edge_and_on_request(moosdb_server, tmp_path):
    async def scenario(app, probe, got):
        probe.notify("STATION_KEEP", "true")  # before any nav: remembered, not sent
        await async_wait_until(lambda: app.pending, 5)
        assert got == []
        probe.notify("NAV_X", 12.5)
        probe.notify("NAV_Y", -3.0)
        await async_wait_until(lambda: len(got) == 1, 5)
        assert got[0].string.startswith("vname=abe,x=12.50,y=-3.00,utc=")
        probe.notify("STATION_KEEP", "true")  # still station-keeping: no new report
        probe.notify("REPORT_COORDINATES", "2")  # the shore asks again: one report
        await async_wait_until(lambda: len(got) == 2, 5)
        probe.notify("STATION_KEEP", "false")
        probe.notify("NAV_X", 20.0)
        probe.notify("STATION_KEEP", "true")  # a new cycle begins
        await async_wait_until(lambda: len(got) == 3, 5)
        assert got[2].string.startswith("vname=abe,x=20.00,y=-3.00")
        assert app.reports == 3

    asyncio.run(with_app(write_mission(tmp_path, moosdb_server.port), scenario))


def test_vname_comes_from_config_else_community(moosdb_server, tmp_path):
    async def scenario(app, probe, got):
        assert app.vname == "ben"
        assert app.status_fields() == {"vname": "ben", "reports": 0}

    asyncio.run(with_app(write_mission(tmp_path, moosdb_server.port, "  vname = BEN\n"), scenario))
    assert coordinates_report("abe", 1, 2, 3) == "vname=abe,x=1.00,y=2.00,utc=3.00"


def test_help_example_interface(capsys):
    for flag, text in (("--help", "VEHICLE_COORDINATES"), ("--example", "vname"), ("--interface", "SUBSCRIPTIONS")):
        assert Coordinates.main([flag]) == 0
        assert text in capsys.readouterr().out
