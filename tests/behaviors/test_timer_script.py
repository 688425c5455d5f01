"""uTimerScript: the script clock as a pure state machine, then the app on a real moosdb with time warp."""
from __future__ import annotations

import asyncio
import random
import re

import pytest
from helpers import CORPUS, async_wait_until, requires_shared
from hypothesis import given, settings
from hypothesis import strategies as st

from behaviors.logic import parse_condition
from behaviors.timer_script import Event, RandVar, TimerScript, TimerScriptState
from moosdb_py.formats import split_fields
from moosdb_py.antler import expanded_mission
from moosdb_py.client import MOOSClient

MACROS = {"DBTIME": "12.00", "UTCTIME": "1000.00"}


def script(*events: str, **options) -> TimerScriptState:
    return TimerScriptState([Event.parse(e, "test") for e in events], rng=random.Random(1), **options)


def test_event_lines():
    event = Event.parse('var=UP_LOITER_2, val="center_assign=$[X1],$[Y1]", time=180', "f:1")
    assert (event.var, event.val, event.quoted, event.window) == ("UP_LOITER_2", "center_assign=$[X1],$[Y1]", True, (180, 180))
    assert Event.parse("var=A, val=3, time=1:2.5", "f").window == (1.0, 2.5)
    for bad in ("var=A, time=3", "val=1, time=3", "var=A, val=1, time=5:2", "var=A, val=1, time=-1", "var=A, val=1, when=3"):
        with pytest.raises(ValueError, match="f:9"):
            Event.parse(bad, "f:9")
    with pytest.raises(ValueError, match="randvar"):
        RandVar.parse("varname=X, min=5, max=1", "f")


@settings(max_examples=50)
@given(st.lists(st.text(alphabet='ab=" ', min_size=1, max_size=6), min_size=1, max_size=4))
def test_split_fields_keeps_quoted_commas(parts):
    quoted = [f'"{p.replace(chr(34), "")},x"' for p in parts]
    assert [f.strip() for f in split_fields(",".join(quoted))] == [q.strip() for q in quoted if q.strip()]


def test_events_post_in_time_order_with_types_and_macros():
    state = script("var=B, val=$(COUNT)/$(TCOUNT) at $(DBTIME), time=2", "var=A, val=4.5, time=1",
                   'var=C, val="7", time=3')
    assert state.step(0.5, MACROS) == []
    assert state.step(2.0, MACROS) == [("A", 4.5), ("B", "2/2 at 12.00")]
    assert state.step(1.0, MACROS) == [("C", "7")]
    assert state.step(100.0, MACROS) == []            # reset_time none: the script ran once


def test_random_times_and_randvars_redrawn_each_round():
    state = TimerScriptState([Event.parse("var=P, val=$[X], time=10:20", "t")], reset_time="end", reset_max=3,
                             randvars=[RandVar.parse("varname=X, min=0, max=5, key=at_reset", "t")],
                             rng=random.Random(7))
    posted, times = [], []
    while state.resets < 3:
        times.append(state.events[0].time)
        posted += state.step(0.25, MACROS)
    assert len(posted) == 3 and all(0 <= float(v) <= 5 for _, v in posted) and len(set(posted)) == 3
    assert all(10 <= t <= 20 for t in times) and len(set(times)) == 3
    assert len(state.step(100, MACROS)) == 1 and state.step(100, MACROS) == []   # the last round; no 4th reset
    assert state.resets == 3


def test_reset_max_and_reset_time():
    state = script("var=A, val=1, time=1", reset_time="5", reset_max=1)
    assert state.step(1.0, MACROS) == [("A", 1.0)]
    state.step(4.0, MACROS)                             # 5 s: the one reset allowed
    assert state.resets == 1 and state.elapsed == 0
    assert state.step(1.0, MACROS) == [("A", 1.0)]
    state.step(10.0, MACROS)
    assert state.resets == 1 and not state.reset()


def test_pause_forward_delay_warp_and_conditions():
    state = script("var=A, val=1, time=10", "var=B, val=2, time=20", delay_start=(2.0, 2.0), time_warp=(2.0, 2.0))
    assert state.step(1.0, MACROS) == [] and state.elapsed == 0        # 2 script seconds of delay
    state.pause("true")
    assert state.step(100.0, MACROS) == []
    state.pause("toggle")
    state.forward(0.0)                                                 # to the next event
    assert state.step(0.0, MACROS) == [("A", 1.0)]
    state.forward(5.0)
    assert state.elapsed == 15.0
    assert state.step(2.5, MACROS) == [("B", 2.0)]                     # 2.5 MOOS s at warp 2
    awake = script("var=A, val=1, time=1", conditions=[parse_condition("DEPLOY = true")], upon_awake="restart")
    awake.on_mail("DEPLOY", "false")
    assert awake.step(5.0, MACROS) == []
    awake.on_mail("DEPLOY", "true")
    assert awake.resets == 1 and awake.step(1.0, MACROS) == [("A", 1.0)]


@pytest.mark.parametrize("line, message", [
    ("event = var=A, val=1, time=x", "m.moos:4: event: time: 'x'"),
    ("condition = A = = ", "m.moos:4: condition: bad value"),
    ("reset_max = often", "m.moos:4: reset_max: 'often'"),
    ("delay_start = 5:1", "m.moos:4: delay_start: '5:1'"),
])
def test_bad_config_names_its_line(tmp_path, line, message):
    path = tmp_path / "m.moos"
    path.write_text(f"ServerPort = 9000\nProcessConfig = uTimerScript\n{{\n  {line}\n}}\n")
    with pytest.raises(ValueError, match=re.escape(message)):
        TimerScript(path).on_startup()


def test_timer_script_app_on_the_mission_clock(moosdb_server, tmp_path):
    """Warp 20: the 40 s event lands in about 2 s; a pause and a reset from the DB take effect."""
    path = tmp_path / "m.moos"
    path.write_text(f"ServerPort = {moosdb_server.port}\nMOOSTimeWarp = 20\n\nProcessConfig = uTimerScript\n{{\n"
                    "  AppTick = 10\n  condition = DEPLOY = true\n  script_name = probe\n"
                    "  event = var=EARLY, val=$(COUNT), time=2\n  event = var=LATE, val=\"done\", time=40\n}\n")
    app = TimerScript(path)
    watcher = MOOSClient("watch", port=moosdb_server.port, time_warp=20)
    for key in ("EARLY", "LATE", "UTS_STATUS"):
        watcher.register(key)

    def values(key):
        return [m.value for m in watcher.inbox if m.key == key]

    async def scenario():
        task = asyncio.create_task(app.run_async())
        watching = asyncio.create_task(watcher.run())
        try:
            await watcher.wait_connected(5)
            await async_wait_until(lambda: any("conditions_ok=false" in s for s in values("UTS_STATUS")), timeout=5)
            assert values("EARLY") == []                       # the condition holds the clock
            watcher.notify("UTS_PAUSE", "maybe")               # not a MOOS boolean: refused, the script runs on
            started = watcher.moos_time()
            watcher.notify("DEPLOY", "true")
            await async_wait_until(lambda: values("EARLY") == [1.0], timeout=5)
            await async_wait_until(lambda: values("LATE") == ["done"], timeout=8)
            assert 35 <= watcher.moos_time() - started <= 200     # 40 MOOS seconds: never early, late only by load
            watcher.notify("UTS_RESET", "true")
            await async_wait_until(lambda: len(values("EARLY")) == 2, timeout=5)
        finally:
            app.stop()
            await task
            watcher.close()
            await watching

    asyncio.run(scenario())


@requires_shared("missions-corpus")
def test_m2_berta_shoreside_script(tmp_path):
    """The corpus m2_berta shoreside block (nsplug'd with its launch defaults): loiter centres at
    180 s and 360 s from randvars redrawn every round, then the script starts over."""
    folder = CORPUS / "m2_berta"
    defines = {"WARP": "1", "IP_ADDR": "localhost", "MOOS_PORT": "9000", "PSHARE_PORT": "9200",
               "VNAMES": "abe:ben", "LAUNCH_GUI": "yes"}
    _, expanded = expanded_mission(folder / "meta_shoreside.moos", defines, {}, tmp_path)
    app = TimerScript(expanded)
    app.on_startup()
    first = app.state.step(180.0, MACROS)
    assert [var for var, _ in first] == ["UP_LOITER_2", "UP_LOITER_1"]
    x1, y1 = map(float, first[0][1].removeprefix("center_assign=").split(","))
    assert 0 <= x1 <= 5 and -80 <= y1 <= -70
    assert [var for var, _ in app.state.step(180.0, MACROS)] == ["UP_LOITER_1", "UP_LOITER_2"]
    assert app.state.resets == 1 and app.state.elapsed == 0        # reset_time = end, reset_max = unlimited
