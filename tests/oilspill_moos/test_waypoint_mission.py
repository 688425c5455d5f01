"""missions/s1_alpha end to end: pAntler, uPokeDB DEPLOY, the kayak flies the survey in order and comes home."""
from __future__ import annotations

import asyncio

from helpers import async_wait_until
from mission_run import MISSIONS, distance, headless, latest, mission_alog, nav_track, poke, prepare, until_helm_is_up

WARP = 15
SURVEY = [(60, -40), (60, -160), (150, -160), (180, -100), (150, -40)]   # alpha.bhv polygon, in order
SURVEY_CAPTURE = 5.0
HOME, HOME_CAPTURE = (0, -20), 2.0


def test_alpha_survey_passes_every_waypoint_in_order_and_returns(tmp_path, free_port):
    port = free_port()
    mission = prepare(MISSIONS / "s1_alpha", "alpha.moos", tmp_path, port, WARP)

    async def scenario():
        async with headless(mission, port, WARP, ["IVPHELM_STATE", "MISSION", "NAV_X"]) as watcher:
            # deploy only once the helm has posted its `initialize DEPLOY = false`
            await until_helm_is_up(watcher)
            await poke(mission, "DEPLOY=true", "MOOS_MANUAL_OVERRIDE=false")
            # about 215 s of mission time: 410 m of survey at 3 m/s, 150 m home at 2 m/s
            await async_wait_until(lambda: latest(watcher, "MISSION") == "complete", 40, interval=0.1)
            # pLogger flushes each AppTick: stop only once the endflags are on disk
            await async_wait_until(lambda: _logged(tmp_path, "MISSION", "complete"), 10, interval=0.1)
    asyncio.run(scenario())

    alog = mission_alog(tmp_path)
    track = nav_track(alog)
    targets = [(p, SURVEY_CAPTURE) for p in SURVEY] + [(HOME, HOME_CAPTURE)]
    reached, closest = [], [float("inf")] * len(targets)
    for t, x, y in track:
        if len(reached) == len(targets):
            break
        point, radius = targets[len(reached)]
        d = distance(point, x, y)
        closest[len(reached)] = min(closest[len(reached)], d)
        if d <= radius:
            reached.append(t)
    assert len(reached) == len(targets), f"reached {len(reached)} of {len(targets)}; closest {closest}"
    # the helm agrees: waypoint indices in order, the survey's endflag, then the return's
    indices = [int(v) for v in alog.values("WPT_INDEX")]
    assert [i for n, i in enumerate(indices) if n == 0 or i != indices[n - 1]][:5] == [0, 1, 2, 3, 4]
    summary = alog.last("SUMMARY")
    assert summary is not None and str(summary.value).startswith("speed=3,time=")
    survey_time = float(str(summary.value).rsplit("=", 1)[1])
    assert 120 < survey_time < 160, survey_time   # ~410 m at 3 m/s plus the turns
    assert alog.last("DEPLOY").value == "false" and alog.last("RETURN").value == "false"
    reports = alog.values("NODE_REPORT_LOCAL")
    assert reports and all(str(r).startswith("NAME=alpha,X=") for r in reports)
    assert any(",MODE=DRIVE," in str(r) for r in reports)


def _logged(folder, key: str, value: str) -> bool:
    """True once the mission's alog on disk has a line posting `key` = `value`."""
    return any(line.split()[1:2] == [key] and line.rstrip().endswith(f" {value}")
               for log in folder.glob("LOG_*/*.alog") for line in log.read_text(errors="replace").splitlines())
