"""pRealm: requests, casts and channel summaries in MOOS-IvP's formats (pure), then the app against a
real moosdb."""
from __future__ import annotations

import asyncio

import pytest
from helpers import async_wait_until, start_moosdb
from hypothesis import given, strategies as st

from moosdb_py.client import MOOSClient
from moosdb_py.message import MOOSMsg
from moosdb_py.realm import REALM_PARAMS, PipeWay, Realm, RealmConfigError, RealmState, format_table, realmcast_string

WARP = 10
T0 = 1000.0


def state(**overrides) -> RealmState:
    return RealmState("abe", {**REALM_PARAMS.read({}), **overrides}, start_time=T0, time_warp=1.0)


def mail(key, value, t, source="pHelmIvP", community="abe") -> MOOSMsg:
    msg = MOOSMsg.notification(key, value, time=t, source=source)
    msg.community = community
    return msg


def test_defaults_are_moos_ivps():
    s = state()
    assert (s.relcast_interval, s.summary_interval, s.wrap_length, s.trunc_length, s.max_hist) == (0.8, 2.0, 90, 270, 10)


def test_pipeway_parsing():
    way = PipeWay.parse("client=pmv,channel=pHelmIvP,duration=3,nosrc,nocom,nosubs,mask,wrap,trunc,utc")
    assert (way.client, way.channel, way.duration) == ("pmv", "pHelmIvP", 3.0)
    assert not (way.show_source or way.show_community or way.show_subscriptions or way.show_masked)
    assert way.wrap and way.trunc and way.utc and not way.force
    watch = PipeWay.parse("client=pmv,vars=RETURN:DEPLOY,duration=3,force")
    assert watch.variables == ("DEPLOY", "RETURN") and watch.force and watch.descriptor() == "vars=DEPLOY,RETURN"
    for bad in ("channel=pHelmIvP,duration=3", "client=pmv,channel=x,duration=0", "client=pmv,duration=3",
                "client=pmv,channel=x,duration=3,colour=red", "client=pmv,channel=x,duration=soon"):
        with pytest.raises(ValueError):
            PipeWay.parse(bad)


def test_rwsummary_learns_apps_and_registers_every_variable():
    s = state()
    new = s.on_mail(mail("DB_RWSUMMARY", "pHelmIvP=NAV_X:NAV_Y&DESIRED_HEADING,uXMS_12=&", T0, "MOOSDB_abe"), T0)
    assert new == ["NAV_X", "NAV_Y", "DESIRED_HEADING"]
    assert s.apps == {"MOOSDB_abe", "pHelmIvP", "uXMS_12"} and s.pubs["MOOSDB_abe"] == {"DB_RWSUMMARY"}
    assert s.on_mail(mail("DB_RWSUMMARY", "pHelmIvP=NAV_X&DESIRED_HEADING", T0 + 1, "MOOSDB_abe"), T0 + 1) == []


def test_channels_summary_timing_and_format():
    s = state(scope_set=["name=events, vars=DEPLOY:RETURN"])
    s.on_mail(mail("DB_RWSUMMARY", "pHelmIvP=DEPLOY&,uXMS_1=&", T0, "MOOSDB_abe"), T0)
    # a new app: at once; uXMS is the user's probe, left out; the history channel after the apps
    assert s.iterate(T0) == [("REALMCAST_CHANNELS", "node=abe#channels=MOOSDB_abe,pHelmIvP,events")]
    assert s.iterate(T0 + 0.4) == []                      # first minute: every 0.5 s, if changed
    assert s.iterate(T0 + 0.6) == []                      # unchanged: waits 10 x 0.5 s
    assert s.iterate(T0 + 5.0)[0][0] == "REALMCAST_CHANNELS"
    assert s.iterate(T0 + 70.0)[0][1].endswith("events")  # after the first minute: unchanged waits 10 x 2 s
    assert s.iterate(T0 + 85.0) == []
    assert state().iterate(T0) == [("REALMCAST_CHANNELS", "node=abe#channels=MOOSDB_abe,")]   # MOOS-IvP's comma


def test_realmcast_of_an_app_channel():
    s = state()
    s.on_mail(mail("DB_RWSUMMARY", "pHelmIvP=NAV_X:NAV_Y&DESIRED_HEADING:BHV_IPF", T0, "MOOSDB_abe"), T0)
    s.on_mail(mail("NAV_X", 12.5, T0 + 2, "uSimMarine"), T0 + 2)
    s.on_mail(mail("DESIRED_HEADING", 90.0, T0 + 3), T0 + 3)
    s.on_mail(mail("BHV_IPF", "a long report", T0 + 3), T0 + 3)
    s.on_mail(mail("REALMCAST_REQ", "client=pmv,channel=pHelmIvP,duration=3", T0 + 3, "pMarineViewer"), T0 + 3)
    casts = [p for p in s.iterate(T0 + 4) if p[0] == "REALMCAST"]
    table_subs = format_table(["Variable", "Source", "Time", "Comm", "Value"],
                              [["NAV_X", "uSimMarine", "2.00", "abe", "12.5"], ["NAV_Y", "-", "never", "-", "-"]])
    table_pubs = format_table(["Variable", "Source", "Time", "Comm", "Value"],
                              [["BHV_IPF", "pHelmIvP", "3.00", "abe", "formatted report"],
                               ["DESIRED_HEADING", "pHelmIvP", "3.00", "abe", "90"]])
    text = f"Subscriptions\n{'=' * 39}\n{table_subs}\n\n{'=' * 39}\nPublications\n{'=' * 39}\n{table_pubs}\n"
    assert casts == [("REALMCAST", realmcast_string("abe", "pHelmIvP", text))]
    assert casts[0][1].startswith("node=abe!Q!proc=pHelmIvP!Q!messages=Subscriptions!Z!=======")
    assert s.iterate(T0 + 4.5) == []                        # relcast_interval 0.8 s
    assert s.iterate(T0 + 7.5) == []                        # expired at T0 + 6
    s.iterate(T0 + 37.0)
    assert "pmv" not in s.pipeways                          # forgotten 30 s after expiry


def test_realmcast_options_and_history_channel():
    s = state(hist_var=["TASK_BID"], wrap_length=4)
    for i, bid in enumerate(("b1", "b2", "b3")):
        s.on_mail(mail("TASK_BID", bid, T0 + i, "pTaskMgr"), T0 + i)
    s.on_mail(mail("REALMCAST_REQ", "client=pmv,channel=TASK_BID,duration=3,nosrc,nocom", T0 + 3), T0 + 3)
    (_, cast), = s.iterate(T0 + 3)[:1]
    rows = format_table(["Variable", "Time", "Value"], [["TASK_BID", "2.00", "b3"], ["TASK_BID", "1.00", "b2"],
                                                       ["TASK_BID", "0.00", "b1"]])
    assert cast == realmcast_string("abe", "TASK_BID", f"History Channel [TASK_BID]: TASK_BID\n{'=' * 39}\n{rows}\n\n")
    s.on_mail(mail("DB_RWSUMMARY", "pTaskMgr=&TASK_NOTE", T0 + 4, "MOOSDB_abe"), T0 + 4)
    s.on_mail(mail("TASK_NOTE", "abcdefghij", T0 + 4, "pTaskMgr"), T0 + 4)
    s.on_mail(mail("REALMCAST_REQ", "client=pmv,channel=pTaskMgr,duration=3,wrap,nosubs", T0 + 4), T0 + 4)
    cast = next(v for k, v in s.iterate(T0 + 5) if k == "REALMCAST")
    rows = format_table(["Variable", "Source", "Time", "Comm", "Value"],
                        [["TASK_NOTE", "pTaskMgr", "4.00", "abe", "abcd"], ["", "", "", "", "efgh"], ["", "", "", "", "ij"]])
    assert cast == realmcast_string("abe", "pTaskMgr", f"Publications\n{'=' * 39}\n{rows}\n")
    assert len(s.data["TASK_BID"]) == 3 and len(s.data["TASK_NOTE"]) == 1     # strings: only hist vars keep more


def test_watchcasts():
    s = state()
    s.on_mail(mail("DEPLOY", "true", T0 + 1, "uPokeDB"), T0 + 1)
    s.on_mail(mail("REALMCAST_REQ", "client=pmv,vars=DEPLOY:SPEED,duration=10", T0 + 2), T0 + 2)
    assert [p for p in s.iterate(T0 + 2) if p[0] == "WATCHCAST"] == [
        ("WATCHCAST", "node=abe!X!var=DEPLOY!X!src=uPokeDB!X!comm=abe!X!loc_time=1!X!utc_time=1001!X!sval=true")]
    assert s.iterate(T0 + 3) == []                        # nothing new, SPEED never written
    s.on_mail(mail("SPEED", 1.23456, T0 + 3.5, "pHelmIvP"), T0 + 3.5)
    assert s.iterate(T0 + 4) == [
        ("WATCHCAST", "node=abe!X!var=SPEED!X!src=pHelmIvP!X!comm=abe!X!loc_time=3.5!X!utc_time=1003.5!X!dval=1.235")]
    s.on_mail(mail("REALMCAST_REQ", "client=pmv,vars=DEPLOY:NEVER,duration=10,force", T0 + 4), T0 + 4)
    forced = [v for _, v in s.iterate(T0 + 5)]
    assert forced[1] == "node=abe!X!var=NEVER!X!src=n/a!X!comm=n/a!X!loc_time=-1!X!utc_time=0!X!sval=n/a"
    assert forced[0].startswith("node=abe!X!var=DEPLOY!X!src=uPokeDB")


def test_bad_request_is_a_warning_and_bad_config_an_error():
    s = state()
    s.on_mail(mail("REALMCAST_REQ", "channel=pHelmIvP,duration=3", T0, "pMarineViewer"), T0)
    assert s.warnings and "pMarineViewer@abe" in s.warnings[0] and "needs client=" in s.warnings[0]
    with pytest.raises(RealmConfigError, match="scope_set needs name"):
        state(scope_set=["vars=A:B"])
    with pytest.raises(RealmConfigError, match="unknown key 'colour'"):
        state(scope_set=["name=x, vars=A, colour=red"])


@given(st.lists(st.text(alphabet="ab c|=:!", max_size=12), max_size=6))
def test_realmcast_lines_round_trip(lines):
    """Every line of the text comes back between the !Z! separators (MOOS-IvP's bite at each newline)."""
    text = "".join(line + "\n" for line in lines)
    messages = realmcast_string("n", "p", text).split("messages=", 1)[1]
    assert messages.split("!Z!")[:-1] == lines and messages.endswith("!Z!") == bool(lines)


def test_bad_scope_set_names_its_line(tmp_path):
    path = tmp_path / "m.moos"
    path.write_text("ServerPort = 9000\nCommunity = abe\nProcessConfig = pRealm\n{\n  scope_set = vars=A\n}\n")
    with pytest.raises(ValueError, match=r"m.moos:5: scope_set needs"):
        Realm(path).on_startup()


def test_realm_against_a_moosdb(tmp_path):
    db = start_moosdb("--moos_community", "abe")
    path = tmp_path / "abe.moos"
    path.write_text(f"ServerHost = localhost\nServerPort = {db.port}\nCommunity = abe\nMOOSTimeWarp = {WARP}\n\n"
                    "ProcessConfig = pRealm\n{\n  AppTick = 4\n  scope_set = name=events, vars=DEPLOY:RETURN\n}\n")
    realm = Realm(path)
    viewer = MOOSClient("pMarineViewer", port=db.port, time_warp=WARP)
    for key in ("REALMCAST", "REALMCAST_CHANNELS", "WATCHCAST", "VIEWER_FOO"):
        viewer.register(key)

    def values(key):
        return [m.string for m in viewer.inbox if m.key == key]

    async def scenario():
        tasks = [asyncio.create_task(realm.run_async()), asyncio.create_task(viewer.run())]
        try:
            # the viewer's registrations reach DB_RWSUMMARY, so pRealm lists it as a channel
            await async_wait_until(lambda: any("pMarineViewer" in v for v in values("REALMCAST_CHANNELS")), timeout=20)
            assert values("REALMCAST_CHANNELS")[-1].startswith("node=abe#channels=MOOSDB_abe,")
            assert values("REALMCAST_CHANNELS")[-1].endswith(",events")
            viewer.notify("DEPLOY", "true")
            viewer.notify("VIEWER_FOO", 3.0)
            viewer.notify("REALMCAST_REQ", "client=pmv,vars=DEPLOY,duration=30")
            await async_wait_until(lambda: any("var=DEPLOY" in v and "sval=true" in v for v in values("WATCHCAST")),
                                   timeout=20)
            assert values("WATCHCAST")[-1].startswith("node=abe!X!var=DEPLOY!X!src=pMarineViewer!X!comm=")
            viewer.notify("REALMCAST_REQ", "client=pmv,channel=pMarineViewer,duration=30,nosrc")
            await async_wait_until(lambda: any("VIEWER_FOO" in v for v in values("REALMCAST")), timeout=20)
            cast = next(v for v in values("REALMCAST") if "VIEWER_FOO" in v)
            assert cast.startswith("node=abe!Q!proc=pMarineViewer!Q!messages=Subscriptions!Z!")
        finally:
            realm.stop()
            viewer.close()
            await asyncio.gather(*tasks)
    try:
        asyncio.run(scenario())
    finally:
        db.stop()
