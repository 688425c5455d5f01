"""pMarineViewer end to end, as an operator uses it: a real headless Chromium loads the page of a
running oil-spill mission (2 vehicles, time warp), watches the vehicles appear, clicks DEPLOY and
sees their phase change, sees them move to the boundary pushed to pPathAssign, then replays the
shoreside alog with the time slider. Screenshots are kept in artifacts/ (git-ignored).
"""
import asyncio
import json
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from helpers import wait_until
from oilspill_moos.demo import OilspillMission, free_port
from oilspill_moos.forecaster.push import push_lines
from oilspill_moos.viewer.browser import Browser, find_chromium

pytestmark = pytest.mark.skipif(find_chromium() is None, reason="no chromium on PATH (Debian package `chromium`); "
                                "the browser tests need it and run in CI, where .ci/run installs it")

ARTIFACTS = Path(__file__).resolve().parents[2] / "artifacts"
BIN = Path(sys.executable).parent
WARP = 10.0
TIMEOUT = 30.0
SPILL = b"pts={-30,80:30,80:30,140:-30,140},label=viewer-test-spill\n"


def start_viewer(args: list[str], cwd: Path) -> tuple[subprocess.Popen, str]:
    port = free_port()
    process = subprocess.Popen([str(BIN / "pMarineViewer"), *args, f"--http_port={port}"], cwd=cwd,
                               stdout=subprocess.DEVNULL, stderr=open(cwd / f"viewer_{port}.err", "wb"))
    url = f"http://127.0.0.1:{port}/"

    def serving():
        assert process.poll() is None, (cwd / f"viewer_{port}.err").read_text()
        try:
            return urllib.request.urlopen(url, timeout=1).status == 200
        except OSError:
            return False
    wait_until(serving, timeout=TIMEOUT, interval=0.1)
    return process, url


def stop(process: subprocess.Popen) -> None:
    process.terminate()
    try:
        process.wait(timeout=5)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()


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
    viewer = None
    try:
        viewer, url = start_viewer([mission.shoreside.moos_file], mission.folder)
        yield mission, url
    finally:
        if viewer is not None:
            stop(viewer)
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
        assert await asyncio.to_thread(push_lines, [SPILL], port=mission.boundary_port) == [1]
        await until(browser, "viewerState.boundary && viewerState.boundary.length === 4", what="the boundary")
        await until(browser, "Object.keys(viewerState.starts).length === 2", what="both start points")
        moved = (f"(() => {{ const a = {json.dumps(first)}; return Object.entries({POSITIONS})"
                 ".some(([n, p]) => Math.hypot(p[0] - a[n][0], p[1] - a[n][1]) > 10); })()")
        await until(browser, moved, what="a vehicle 10 m from where it appeared")
        await until(browser, f"{PHASES}.some(p => p === 'STARTING-POSITION' || p === 'OIL-PATH')",
                    what="vehicles on their way")
        await until(browser, "viewerStats.frames > 5", what="frames drawn")
        await browser.screenshot(ARTIFACTS / "viewer_live.png")
        assert not [line for line in browser.console if line.startswith("exception")], browser.console

    browser.run(operator())


def test_finished_run_replays_with_the_time_slider(live, browser):
    mission, _ = live
    alog = mission.alog("shoreside")
    wait_until(lambda: alog.exists() and b"NODE_REPORT" in alog.read_bytes(), timeout=TIMEOUT)
    viewer, url = start_viewer([mission.shoreside.moos_file, f"--replay={alog}"], mission.folder)
    try:
        async def reviewer():
            await browser.goto(url)
            await until(browser, "!document.getElementById('replay-bar').hidden", what="the replay bar")
            end = await browser.evaluate("Number(document.getElementById('slider').max)")
            assert end > 0
            await browser.evaluate("(() => { const s = document.getElementById('slider'); s.value = s.max;"
                                   " s.dispatchEvent(new Event('change')); })()")
            await until(browser, f"{PHASES}.length === 2", what="vehicles at the end of the log")
            await until(browser, "viewerState.boundary !== null", what="the boundary in the replay")
            shown = await browser.evaluate("document.getElementById('replay-time').textContent")
            assert shown.startswith(f"{end:.1f} /"), shown
            await browser.screenshot(ARTIFACTS / "viewer_replay.png")
        browser.run(reviewer())
    finally:
        stop(viewer)
