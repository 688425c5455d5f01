"""pMarineViewer end to end, as an operator uses it: a real headless Chromium loads the page of a
running oil-spill mission (2 vehicles, time warp), watches the vehicles appear, clicks DEPLOY and
sees their phase change, sees them move to the forecast pushed to pPathAssign (two horizons, each
in the legend with its uncertainty band), re-pushes the boundary (a new cycle replacing the
horizons) and calls the fleet back with RETURN_ALL, then replays the shoreside alog with the time slider,
and sees "mission ended" over the last picture when the mission stops. MOOS-IvP's own s1_alpha (one
vehicle, no spill) shows its vehicle from NODE_REPORT_LOCAL, without the spill's key and buttons.
Labels never cover each other, the status is a readable table, the lat/long grid is labelled.
Screenshots are kept in artifacts/ (git-ignored).
"""
import asyncio
import contextlib
import json
import re
import time
import urllib.request
from pathlib import Path

import pytest

from browser import Browser, find_chromium
from helpers import CORPUS, free_port, requires_shared, wait_until
from mission_run import headless, prepare
from oilspill_moos.forecaster.push import boundary_line, push_lines
from oilspill_moos.oilspill_mission import OilspillMission
from oilspill_moos.viewer.app import viewer_beside

pytestmark = pytest.mark.skipif(find_chromium() is None, reason="no chromium on PATH (Debian package `chromium`); "
                                "the browser tests need it and run in CI, where .ci/run installs it")

ARTIFACTS = Path(__file__).resolve().parents[2] / "artifacts"
WARP = 10.0
TIMEOUT = 45.0   # wall seconds for any one step (generous: CI shares two cores)
ISSUED = time.time()
FORECAST = [boundary_line(polygon, horizon, time=ISSUED + 3600 * horizon, crs="local", uncertainty_m=band)
            for horizon, band, polygon in ((3, 6, [(-30, 80), (30, 80), (30, 140), (-30, 140)]),
                                           (7, 12, [(-10, 110), (60, 110), (60, 180), (-10, 180)]))]
S1_ALPHA = CORPUS / "s1_alpha"
LEGEND = "[...document.querySelectorAll('#forecast-legend li')].map(li => li.querySelector('.horizon').textContent)"


@contextlib.contextmanager
def viewer(mission: OilspillMission, *options: str):
    """pMarineViewer on the mission's shoreside file, as `make demo --viewer` runs it; yields the page URL."""
    port = free_port()
    url = f"http://127.0.0.1:{port}/"
    with viewer_beside(mission.folder / mission.shoreside.moos_file, port, *options) as process:
        def serving():
            assert process.poll() is None, f"pMarineViewer exited with {process.returncode} (stderr above)"
            try:
                return urllib.request.urlopen(url, timeout=1).status == 200
            except OSError:
                return False
        wait_until(serving, timeout=TIMEOUT, interval=0.1)
        yield url


@pytest.fixture(scope="module")
def browser():
    """One Chromium for both tests (it is the slowest thing to start); `run` drives it."""
    loop = asyncio.new_event_loop()
    chromium = Browser(1280, 800)
    loop.run_until_complete(chromium.__aenter__())
    chromium.run = loop.run_until_complete
    try:
        yield chromium
    finally:
        loop.run_until_complete(chromium.__aexit__(None, None, None))
        loop.close()


@pytest.fixture(scope="module")
def live(tmp_path_factory):
    mission = OilspillMission(tmp_path_factory.mktemp("viewer"), vehicles=2, warp=WARP, standoff=10.0)
    mission.start()
    try:
        with viewer(mission) as url:
            yield mission, url
    finally:
        mission.stop()


async def until(browser: Browser, expression: str, timeout: float = TIMEOUT, what: str = ""):
    """Poll a JavaScript expression in the page until it is truthy; return its value."""
    deadline = time.monotonic() + timeout
    while not (value := await browser.evaluate(expression)):
        if time.monotonic() > deadline:
            raise AssertionError(f"page: {what or expression} not within {timeout} s; console: {browser.console}")
        await asyncio.sleep(0.1)
    return value


PHASES = "[...document.querySelectorAll('#vehicles tbody td.phase')].map(td => td.textContent)"
# Pairs of labels drawn over each other, or over a vehicle or a point, in the last frame (none, whatever
# the picture).
OVERLAPS = ("(() => { const l = window.viewerLabels, o = [], hit = (a, b) => a.x < b.x + b.w && b.x < a.x + a.w"
            " && a.y < b.y + b.h && b.y < a.y + a.h; for (let i = 0; i < l.length; i++) {"
            " for (let j = 0; j < i; j++) if (hit(l[i], l[j])) o.push([l[i].text, l[j].text]);"
            " for (const b of window.viewerObstacles) if (hit(l[i], b)) o.push([l[i].text, 'a vehicle or point']); }"
            " return o; })()")
# The status table: one row per field, each value on one line (no word broken over two).
STATUS_ROWS = ("[...document.querySelectorAll('#status dd')].map(dd => [dd.dataset.key, dd.textContent,"
               " dd.getClientRects().length === 1 && dd.getBoundingClientRect().height < 20])")
POSITIONS = "Object.fromEntries([...viewerState.vehicles.values()].map(v => [v.name, [v.x, v.y]]))"


def test_operator_sees_the_fleet_deploys_it_and_watches_it_move(live, browser):
    mission, url = live

    async def operator():
        await browser.goto(url)
        await until(browser, f"{PHASES}.length === 2", what="both vehicles in the table")
        before = await browser.evaluate(PHASES)   # INACTIVE, or the helm's DRIVE/PARK before its first modes
        assert not set(before) & {"STATION-KEEPING", "STARTING-POSITION", "OIL-PATH"}, before
        assert await browser.evaluate("document.getElementById('link-text').textContent") == "live"
        first = await browser.evaluate(POSITIONS)
        deployed = f"{PHASES}.every(p => p === 'STATION-KEEPING')"
        deadline = time.monotonic() + TIMEOUT
        while True:   # click again if nothing happened: the shore broker may not have bridged DEPLOY yet
            await browser.click("#buttons button[data-label='DEPLOY']")
            try:
                await until(browser, deployed, timeout=3.0)
                break
            except AssertionError:
                assert time.monotonic() < deadline, f"DEPLOY did not take: {await browser.evaluate(PHASES)}"
        log = await browser.evaluate("document.getElementById('log').textContent")
        assert "DEPLOY: DEPLOY_ALL=true" in log
        assert await asyncio.to_thread(push_lines, FORECAST, port=mission.boundary_port) == [1, 2]
        await until(browser, "viewerState.boundary && viewerState.boundary.length === 4", what="the boundary")
        await until(browser, f"{LEGEND}.join() === '+3 h,+7 h'", what="both horizons in the forecast legend")
        bands = await browser.evaluate("viewerState.forecasts.map(f => [f.uncertainty, f.band.length])")
        assert bands == [[6, 2], [12, 2]], bands   # each square's band: the outer ring and the hole
        await until(browser, "Object.keys(viewerState.starts).length === 2", what="both start points")
        moved = (f"(() => {{ const a = {json.dumps(first)}; return Object.entries({POSITIONS})"
                 ".some(([n, p]) => Math.hypot(p[0] - a[n][0], p[1] - a[n][1]) > 10); })()")
        await until(browser, moved, what="a vehicle 10 m from where it appeared")
        await until(browser, f"{PHASES}.some(p => p === 'STARTING-POSITION' || p === 'OIL-PATH')",
                    what="vehicles on their way")
        await until(browser, "viewerStats.frames > 5", what="frames drawn")
        await browser.hover("#map")
        readout = await browser.evaluate("document.getElementById('cursor-ll').textContent")
        assert readout.startswith("lat 28.7") and ", lon -88.3" in readout, readout   # near the mission origin
        scale = await browser.evaluate("viewerView.scale")
        await browser.wheel("#map", -240)
        await until(browser, f"viewerView.scale > {scale} * 1.2", what="zoomed in by the wheel")
        await browser.click("#fit")
        await until(browser, "viewerStats.frames > 0 && window.viewerLabels.length >= 2", what="labels drawn")
        assert await browser.evaluate(OVERLAPS) == []
        assert await browser.evaluate("!document.getElementById('key').hidden")   # an oil-spill mission: its key
        rows = await until(browser, f"(r => r.length > 5 && r)({STATUS_ROWS})", what="the status table")
        assert all(one_line for _, _, one_line in rows), rows
        assert {key for key, _, _ in rows} >= {"phase", "vehicles", "boundary_age", "horizon"}, rows
        assert dict((k, v) for k, v, _ in rows)["vehicles"] == "abe, ben", rows
        grid = await browser.evaluate("window.viewerGrid")
        assert grid["lat"] and all(re.fullmatch(r"28°4\d(\.\d+)?'N", t) for t in grid["lat"]), grid
        assert grid["lon"] and all(re.fullmatch(r"88°2\d(\.\d+)?'W", t) for t in grid["lon"]), grid
        log = await browser.evaluate("document.getElementById('log').textContent")
        for line in ("boundary in force: oilspill_", "fleet phase STATION-KEEPING", "abe: STATION-KEEPING ->",
                     "forecast cycle 1"):
            assert line in log, f"{line!r} not in the log: {log}"
        await browser.screenshot(ARTIFACTS / "viewer_live.png")
        await until(browser, "(m => m && Number(m[1]) > 11)(/boundary_age=([0-9.]+)/.exec(viewerState.status))",
                    what="the boundary older than pPathAssign's min_replan_interval (10 s), so a re-push is no flood")
        await browser.click("#buttons button[data-label='RE-PUSH BOUNDARY']")
        await until(browser, "document.getElementById('log').textContent.includes('RE-PUSH')",
                    what="pPathAssign's answer to RE-PUSH BOUNDARY in the log")
        log = await browser.evaluate("document.getElementById('log').textContent")
        assert "accepted it as boundary 3" in log, log
        await until(browser, f"{LEGEND}.join() === '+0 h'", what="the re-pushed boundary's cycle replacing both horizons")
        await browser.click("#buttons button[data-label='RETURN_ALL']")
        await until(browser, f"{PHASES}.every(p => p === 'RETURNING')", what="the fleet returning")
        assert not [line for line in browser.console if line.startswith("exception")], browser.console

    browser.run(operator())


def test_finished_run_replays_with_the_time_slider(live, browser):
    mission, _ = live
    alog = mission.alog("shoreside")
    wait_until(lambda: alog.exists() and b"NODE_REPORT" in alog.read_bytes(), timeout=TIMEOUT)
    with viewer(mission, f"--replay={alog}") as url:
        async def reviewer():
            await browser.goto(url)
            await until(browser, "!document.getElementById('replay-bar').hidden", what="the replay bar")
            end = await browser.evaluate("Number(document.getElementById('slider').max)")
            assert end > 0
            await browser.evaluate("(() => { const s = document.getElementById('slider'); s.value = s.max;"
                                   " s.dispatchEvent(new Event('change')); })()")
            await until(browser, f"{PHASES}.length === 2", what="vehicles at the end of the log")
            await until(browser, "viewerState.boundary !== null && viewerState.forecasts.length > 0",
                        what="the boundary and the forecast in the replay")
            shown = await browser.evaluate("document.getElementById('replay-time').textContent")
            assert shown.startswith(f"{end:.1f} /"), shown
            await browser.screenshot(ARTIFACTS / "viewer_replay.png")
        browser.run(reviewer())


def test_the_page_says_mission_ended_and_keeps_the_last_picture(live, browser):
    mission, url = live

    async def operator():
        await browser.goto(url)
        await until(browser, f"{PHASES}.length === 2", what="both vehicles in the table")
        assert await browser.evaluate("document.getElementById('ended').hidden")
        mission.stop()   # the MOOSDBs go away; the viewer beside them stays up
        await until(browser, "document.getElementById('link-text').textContent === 'mission ended'",
                    what="the page saying the mission ended")
        assert not await browser.evaluate("document.getElementById('ended').hidden")
        assert await browser.evaluate(f"{PHASES}.length") == 2 and await browser.evaluate("viewerState.boundary")
        log = await browser.evaluate("document.getElementById('log').textContent")
        assert "mission ended: the MOOSDB at 127.0.0.1:" in log, log
        await browser.screenshot(ARTIFACTS / "viewer_ended.png")

    browser.run(operator())


@requires_shared("missions-corpus")
def test_single_vehicle_s1_alpha_shows_its_vehicle_without_the_spill(browser, tmp_path):
    """`pAntler alpha.moos`: pMarineViewer inside the mission, as a MOOS-IvP user runs it."""
    port, http_port = free_port(), free_port()
    mission = prepare(S1_ALPHA, "alpha.moos", tmp_path, port, WARP)
    text = mission.read_text()   # two test runs at once must not both want the viewer's default port 8080
    mission.write_text(re.sub(r"(ProcessConfig = pMarineViewer\s*\{)", rf"\1\n  http_port = {http_port}", text, count=1))
    url = f"http://127.0.0.1:{http_port}/"

    def serving():
        try:
            return urllib.request.urlopen(url, timeout=1).status == 200
        except OSError:
            return False

    async def operator():
        async with headless(mission, port, WARP, ["NODE_REPORT_LOCAL"]):
            await asyncio.to_thread(wait_until, serving, TIMEOUT, 0.1)
            await browser.goto(url)
            await until(browser, f"{PHASES}.length === 1", what="alpha in the vehicle table")
            hidden = await browser.evaluate("['key', 'phase-section', 'forecast-toggle']"
                                            ".map(id => document.getElementById(id).hidden)")
            assert hidden == [True, True, True], hidden   # no spill: no spill key, phase or forecast toggle
            buttons = await browser.evaluate("[...document.querySelectorAll('#buttons button')].map(b => b.dataset.label)")
            assert buttons == ["DEPLOY", "RETURN", "SLOWER", "FASTER", "RETURN_ALL"], buttons
            first = await browser.evaluate(POSITIONS)
            await browser.click("#buttons button[data-label='DEPLOY']")
            moved = (f"(() => {{ const a = {json.dumps(first)}; return Object.entries({POSITIONS})"
                     ".some(([n, p]) => Math.hypot(p[0] - a[n][0], p[1] - a[n][1]) > 20); })()")
            await until(browser, moved, what="alpha 20 m on its survey")
            await until(browser, "window.viewerLabels.some(l => l.text !== 'alpha')", what="the waypoint's label")
            await browser.click("#fit")
            await until(browser, "viewerStats.frames > 3", what="frames drawn")
            assert await browser.evaluate(OVERLAPS) == []
            grid = await browser.evaluate("window.viewerGrid")
            assert grid["lat"] and all(re.fullmatch(r"43°4\d(\.\d+)?'N", t) for t in grid["lat"]), grid
            assert grid["lon"] and all(re.fullmatch(r"70°\d\d(\.\d+)?'W", t) for t in grid["lon"]), grid
            log = await browser.evaluate("document.getElementById('log').textContent")
            assert "alpha reporting" in log and "DEPLOY: DEPLOY=true" in log, log
            await browser.screenshot(ARTIFACTS / "viewer_s1_alpha.png")
        # pAntler stopped the mission, the viewer with it: the page says so and keeps the picture
        await until(browser, "document.getElementById('link-text').textContent === 'mission ended'",
                    what="the page saying the mission ended")
        assert await browser.evaluate(f"{PHASES}.length") == 1
        await browser.screenshot(ARTIFACTS / "viewer_s1_alpha_ended.png")

    browser.run(operator())
