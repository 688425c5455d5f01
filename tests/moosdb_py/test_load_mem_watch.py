"""uLoadWatch and uMemWatch: their pure logic, their config errors, then both against a real moosdb
with a client standing in for pHelmIvP (its PID, its ITER_GAP)."""
from __future__ import annotations

import asyncio
import os

import pytest
from helpers import async_wait_until, one_app_mission, start_moosdb
from hypothesis import given
from hypothesis import strategies as st

from moosdb_py.client import MOOSClient
from moosdb_py.load_watch import LoadWatch, LoadWatchState, parse_thresh
from moosdb_py.mem_watch import Measured, MemWatch, MemWatchState, app_list, resident_kb

WARP = 10


def test_thresholds_own_then_any_and_none_at_or_below_one():
    state = LoadWatchState(thresholds={"PHELMIVP": 3.0, "ANY": 2.0, "PLOGGER": 1.0})
    assert state.threshold("PHELMIVP") == 3.0
    assert state.threshold("USIMMARINE") == 2.0
    assert state.threshold("PLOGGER") is None          # a gap of 1 is on time: no threshold there
    assert LoadWatchState().threshold("PHELMIVP") is None


def test_breaches_after_the_forgiven_offences():
    state = LoadWatchState("alpha", {"PHELMIVP": 3.0}, near_breach_thresh=0.5, breach_trigger=1)
    assert state.on_gap("PHELMIVP_ITER_GAP", 1.0, "pHelmIvP") == []
    near = state.on_gap("PHELMIVP_ITER_GAP", 2.5, "pHelmIvP")     # above 1 + (3 - 1) x 0.5 = 2
    assert near == [("ULW_NEAR_BREACH", "true"), ("ULW_NEAR_BREACH_COUNT", 1.0),
                    ("ULW_NEAR_BREACH_LIST", "pHelmIvP")]
    forgiven = state.on_gap("PHELMIVP_ITER_GAP", 3.5, "pHelmIvP")  # the first offence is forgiven
    assert ("ULW_NEAR_BREACH_COUNT", 2.0) in forgiven and not any(k.startswith("ULW_BREACH") for k, _ in forgiven)
    breach = dict(state.on_gap("PHELMIVP_ITER_GAP", 4.25, "pHelmIvP"))
    assert breach["ULW_BREACH"] == "true" and breach["ULW_BREACH_COUNT"] == 1.0
    assert breach["ULW_BREACH_LIST"] == "pHelmIvP"
    assert breach["LOAD_WARNING"] == "app=PHELMIVP, maxgap=4.25, node=alpha"
    again = dict(state.on_gap("PHELMIVP_ITER_GAP", 5.0, "pHelmIvP"))
    assert again["ULW_BREACH_COUNT"] == 2.0 and "ULW_BREACH" not in again and "ULW_BREACH_LIST" not in again
    load = state.apps["PHELMIVP"]
    assert (load.gap_count, load.gap_max, load.breaches) == (5, 5.0, 3)


def test_breach_list_grows_sorted_and_lengths_are_kept():
    state = LoadWatchState("alpha", {"ANY": 2.0}, breach_trigger=0)
    state.on_gap("USIMMARINEV22_ITER_GAP", 3.0, "uSimMarineV22")
    posts = dict(state.on_gap("PHELMIVP_ITER_GAP", 3.0, "pHelmIvP"))
    assert posts["ULW_BREACH_LIST"] == "pHelmIvP,uSimMarineV22"
    state.on_len("PHELMIVP_ITER_LEN", 0.25)
    state.on_len("PHELMIVP_ITER_LEN", 0.75)
    assert (state.apps["PHELMIVP"].len_total, state.apps["PHELMIVP"].len_max) == (1.0, 0.75)


@given(st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,20}", fullmatch=True), st.floats(0.01, 1e6, allow_nan=False))
def test_thresh_lines_parse(app, gap):
    assert parse_thresh(f"app={app}, gapthresh={gap!r}") == (app.upper(), gap)


@pytest.mark.parametrize("line, message", [("app=pHelmIvP", "needs app"), ("gapthresh=2", "needs app"),
                                           ("app=x, gapthresh=two", "gapthresh expected a number"),
                                           ("app=x, gapthresh=0", "must be positive"),
                                           ("app=x, gap=2", "unknown key 'gap'")])
def test_bad_thresh_lines(line, message):
    with pytest.raises(ValueError, match=message):
        parse_thresh(line)


@pytest.mark.parametrize("app, lines, message", [
    (LoadWatch, "  thresh = app=any, gapthresh=2\n  thresh = app=pHelmIvP\n", "thresh 'app=pHelmIvP' needs"),
    (MemWatch, "  watch_only = pHelmIvP\n  ignore = pHelmIvP\n", "pHelmIvP is both watched and ignored"),
    (MemWatch, "  watch_only = pHelmIvP\n  ignore = u XMS\n", "ignore = 'u XMS': app names are comma-separated")])
def test_bad_config_names_its_line(tmp_path, app, lines, message):
    path = one_app_mission(tmp_path / "m.moos", 9000, "abe", app.default_name, lines)
    with pytest.raises(ValueError, match=rf"m.moos:\d+: {message}"):
        app(path).on_startup()


def test_mem_watch_learns_clients_and_pids():
    state = MemWatchState(watch_only=["pHelmIvP", "uSimMarineV22"])
    assert state.on_clients("pHelmIvP,uSimMarineV22,pLogger,") == ["PHELMIVP_PID", "USIMMARINEV22_PID",
                                                                    "PLOGGER_PID"]
    assert state.on_clients("pHelmIvP,uXMS_12,") == ["UXMS_12_PID"]     # only new clients
    state.on_pid("PHELMIVP_PID", 4242)
    state.on_pid("PHELMIVP_PID", 999)                # a PID once known stays
    state.on_pid("PLOGGER_PID", 77)                  # not on the watch_only list
    state.on_pid("PUNKNOWN_PID", 5)                  # not a client the DB named
    state.on_pid("USIMMARINEV22_PID", 4243)
    assert [(m.app, m.pid) for m in state.measured] == [("pHelmIvP", 4242), ("uSimMarineV22", 4243)]
    assert [state.next_app().app for _ in range(3)] == ["pHelmIvP", "uSimMarineV22", "pHelmIvP"]
    item = Measured("pHelmIvP", 4242)
    assert state.on_measure(item, 51200.0) == [("PHELMIVP_MEM", 51.2)]
    state.on_measure(item, 52200.0)
    assert item.delta_mb == pytest.approx(1.0)


def test_mem_watch_ignore_and_lists():
    state = MemWatchState(ignore=["uXMS"])
    state.on_clients("uXMS,pHelmIvP")
    state.on_pid("UXMS_PID", 10)
    state.on_pid("PHELMIVP_PID", 11)
    assert [m.app for m in state.measured] == ["pHelmIvP"]
    assert app_list(["pHelmIvP, pLogger", "pLogger"], "watch_only") == ["pHelmIvP", "pLogger"]
    with pytest.raises(ValueError, match="comma-separated"):
        app_list(["pHelm IvP"], "watch_only")


def test_resident_memory_of_this_process_and_of_none(tmp_path):
    assert resident_kb(os.getpid()) > 1000          # this Python process holds more than 1 MB
    assert resident_kb(2 ** 22 + 7, proc=tmp_path) is None


def test_load_and_mem_watch_against_a_moosdb(tmp_path):
    db = start_moosdb("--moos_community", "abe")
    load_path = one_app_mission(tmp_path / "load.moos", db.port, "abe", "uLoadWatch",
                                "  AppTick = 4\n  thresh = app=pHelmIvP, gapthresh=3\n  breach_trigger = 0\n", WARP)
    mem_path = one_app_mission(tmp_path / "mem.moos", db.port, "abe", "uMemWatch",
                               "  AppTick = 4\n  absolute_time_gap = 1\n  watch_only = pHelmIvP\n", WARP)
    apps = [LoadWatch(load_path), MemWatch(mem_path)]
    helm = MOOSClient("pHelmIvP", port=db.port, time_warp=WARP)
    for key in ("ULW_BREACH", "LOAD_WARNING", "PHELMIVP_MEM"):
        helm.register(key)

    def values(key):
        return [m.value for m in helm.inbox if m.key == key]

    async def scenario():
        tasks = [asyncio.create_task(app.run_async()) for app in apps] + [asyncio.create_task(helm.run())]
        try:
            await helm.wait_connected(10)
            helm.notify("PHELMIVP_PID", float(os.getpid()))
            # uMemWatch registers for PHELMIVP_PID once DB_CLIENTS names pHelmIvP; the DB then sends the value
            await async_wait_until(lambda: values("PHELMIVP_MEM"), timeout=30)
            assert values("PHELMIVP_MEM")[0] == pytest.approx(resident_kb(os.getpid()) / 1000, rel=0.5)
            for gap in (1.0, 1.1, 4.5):
                helm.notify("PHELMIVP_ITER_GAP", gap)
            await async_wait_until(lambda: values("LOAD_WARNING"), timeout=20)
            assert values("ULW_BREACH") == ["true"]
            assert values("LOAD_WARNING") == ["app=PHELMIVP, maxgap=4.5, node=abe"]
        finally:
            for app in apps:
                app.stop()
            helm.close()
            await asyncio.gather(*tasks)
    try:
        asyncio.run(scenario())
    finally:
        db.stop()
