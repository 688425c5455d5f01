"""pMarineViewer end to end, as an operator uses it: a real headless Chromium loads the page of a
running oil-spill mission (2 vehicles, time warp), watches the vehicles appear, clicks DEPLOY and
sees their phase change, sees them move to the forecast pushed to pPathAssign (two horizons, each
in the legend with its uncertainty band), re-pushes the boundary (a new cycle replacing the
horizons) and calls the fleet back with RETURN_ALL, then replays the shoreside alog with the time slider. Screenshots are kept in artifacts/ (git-ignored).
"""
import asyncio
import contextlib
import json
import time
import urllib.request
from pathlib import Path

import pytest

from browser import Browser, find_chromium
from helpers import free_port, wait_until
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
