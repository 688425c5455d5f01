"""MOOS-IvP missions as users have them: pAntler runs what it can, names each app it cannot launch once
(with the mission line), keeps the rest running, and leaves nothing behind when stopped."""
from __future__ import annotations

import asyncio
import os
import re
import shutil
from pathlib import Path

from helpers import CORPUS, async_wait_until, requires_shared
from mission_run import headless, latest, prepare

WARP = 10
S1_ALPHA_APPS = ("pLogger", "uSimMarineV22", "pMarinePIDV22", "pHelmIvP", "pMarineViewer", "uProcessWatch",
                 "pNodeReporter", "pRealm")


def clients(watcher) -> set[str]:
    return {c for c in str(latest(watcher, "DB_CLIENTS") or "").split(",") if c}


def left_running(folder: Path) -> list[str]:
    """Command lines of live processes that still name the mission folder (our children would)."""
    found = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit() and proc.name != str(os.getpid()):
            try:
                cmdline = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            except OSError:
                continue
            if str(folder) in cmdline:
                found.append(cmdline)
    return found


def warnings_about(log: Path, app: str) -> list[str]:
    return [line for line in log.read_text().splitlines() if re.search(rf"cannot launch {app}\b", line)]


def test_unknown_app_mid_mission_is_named_once_and_the_rest_runs(tmp_path, free_port):
    """A corpus-like ANTLER block with iM300 (a hardware driver, not a project app) between two apps we have (hosted
    in-process, as `--one-process`)."""
    port = free_port()
    mission = tmp_path / "meta.moos"
    mission.write_text(
        f"ServerHost = localhost\nServerPort = {port}\nCommunity = alpha\nMOOSTimeWarp = {WARP}\n\n"
        "ProcessConfig = ANTLER\n{\n  MSBetweenLaunches = 100\n\n"
        "  Run = MOOSDB         @ NewConsole = false\n"
        "  Run = iM300          @ NewConsole = false\n"
        "  Run = uTimerScript   @ NewConsole = false\n}\n\n"
        "ProcessConfig = uTimerScript\n{\n  AppTick = 4\n  event = var=TIMER_UP, val=$(COUNT), time=1\n}\n")

    async def scenario():
        async with headless(mission, port, WARP, ["DB_CLIENTS", "TIMER_UP"]) as watcher:
            await async_wait_until(lambda: latest(watcher, "TIMER_UP") == 1.0, timeout=15)
            await async_wait_until(lambda: "uTimerScript" in clients(watcher), timeout=10)
    asyncio.run(scenario())

    log = tmp_path / "antler.log"
    warnings = warnings_about(log, "iM300")
    assert warnings == ["pAntler: meta.moos:11: cannot launch iM300: not a project app and not found on PATH"], \
        log.read_text()
    assert not left_running(tmp_path)


@requires_shared("missions-corpus")
def test_corpus_s1_alpha_runs_what_we_implement(tmp_path, free_port):
    """The MOOS-IvP s1_alpha mission, unchanged but for its port, warp and the viewer's HTTP port."""
    port, http_port = free_port(), free_port()
    mission = prepare(CORPUS / "s1_alpha", "alpha.moos", tmp_path, port, WARP)
    for extra in (CORPUS / "s1_alpha").iterdir():    # the viewer's tiff and info files, if any
        if extra.is_file() and not (tmp_path / extra.name).exists():
            shutil.copy(extra, tmp_path / extra.name)
    text = mission.read_text()   # two test runs at once must not both want the viewer's default port 8080
    mission.write_text(re.sub(r"(ProcessConfig = pMarineViewer\s*\{)", rf"\1\n  http_port = {http_port}", text, count=1))

    async def scenario():
        async with headless(mission, port, WARP, ["DB_CLIENTS", "PROC_WATCH_SUMMARY"]) as watcher:
            await async_wait_until(lambda: set(S1_ALPHA_APPS) <= clients(watcher), timeout=20, interval=0.05)
            # every app of the Run list connects, so uProcessWatch (watch_all = true) has nothing missing
            await async_wait_until(lambda: latest(watcher, "PROC_WATCH_SUMMARY") == "All Present", timeout=10)
    asyncio.run(scenario())

    log = tmp_path / "antler.log"
    assert not re.findall(r"cannot launch \S+", log.read_text()), log.read_text()   # pRealm was the last one
    assert not left_running(tmp_path)
