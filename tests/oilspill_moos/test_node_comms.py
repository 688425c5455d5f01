"""uFldNodeComms: who hears whom (range, critical range, staleness, groups, stealth/earange, seeded
drops), node messages (addressing, interval, length), and the relay as a real process on a moosdb."""
from __future__ import annotations

import asyncio
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers import async_wait_until, one_app_mission, start_moosdb

from moosdb_py.client import MOOSClient
from moosdb_py.source import MissionFileError
from oilspill_moos.field.node_comms import NodeComms, NodeCommsParams, NodeCommsRelay


def relay(seed=None, **config) -> NodeCommsRelay:
    return NodeCommsRelay(NodeCommsParams.from_config({k: str(v) for k, v in config.items()}),
                          rng=np.random.default_rng(seed))


def heard(r: NodeCommsRelay, now: float, *vehicles) -> set[tuple[str, str]]:
    """Feed (name, x, y[, group]) reports at `now`; return the (sender, receiver) pairs relayed."""
    for name, x, y, *group in vehicles:
        r.on_mail("NODE_REPORT", f"NAME={name},X={x},Y={y},SPD=1,HDG=0" + (f",GROUP={group[0]}" if group else ""), now)
    return {(value.split(",")[0][5:], key[len("NODE_REPORT_"):]) for key, value in r.iterate(now)
            if key.startswith("NODE_REPORT_")}


def test_reports_reach_vehicles_within_comms_range_only():
    r = relay(comms_range=100, critical_range=0)
    assert heard(r, 0, ("abe", 0, 0), ("ben", 60, 80), ("cal", 0, 100.5)) == {
        ("abe", "BEN"), ("ben", "ABE"), ("ben", "CAL"), ("cal", "BEN")}   # abe-cal: 100.5 m apart
    assert r.stats.reports_sent == 4 and r.stats.reports_rcvd == 3


def test_the_report_is_relayed_as_received():
    r = relay()
    r.on_mail("NODE_REPORT", "NAME=abe,X=0,Y=0,SPD=1.5,HDG=45,TYPE=kayak,MODE=MODE@ACTIVE:LOITERING", 0)
    r.on_mail("NODE_REPORT_LOCAL", "NAME=ben,X=10,Y=0", 0)
    assert ("NODE_REPORT_BEN", "NAME=abe,X=0,Y=0,SPD=1.5,HDG=45,TYPE=kayak,MODE=MODE@ACTIVE:LOITERING") in r.iterate(0)


def test_critical_range_always_passes():
    r = relay(comms_range=10, critical_range=30, groups="true", drop_percentage=100)
    assert heard(r, 0, ("abe", 0, 0, "red"), ("ben", 25, 0, "blue"), ("cal", 60, 0, "blue")) == {
        ("abe", "BEN"), ("ben", "ABE")}   # other groups, 100 % drops, beyond comms_range: only the 25 m pair


def test_stale_receivers_hear_nothing_and_long_silent_ones_are_forgotten():
    r = relay(stale_time=5, critical_range=0)
    heard(r, 0, ("abe", 0, 0), ("ben", 10, 0))
    assert heard(r, 5, ("abe", 0, 0)) == {("abe", "BEN")}       # ben last heard 5 s ago: still fresh
    assert heard(r, 5.5, ("abe", 0, 0)) == set()                # 5.5 s: stale
    heard(r, 100.5, ("abe", 0, 0))                              # silent for more than 20 x stale_time
    assert "BEN" not in r.records and r.stats.stale_forgotten == 1


def test_groups_keep_reports_within_a_group():
    r = relay(groups="true", critical_range=0)
    assert heard(r, 0, ("abe", 0, 0, "red"), ("ben", 10, 0, "RED"), ("cal", 20, 0, "blue")) == {
        ("abe", "BEN"), ("ben", "ABE")}


def test_stealth_and_earange_scale_the_comms_range():
    r = relay(comms_range=100, critical_range=0)
    r.on_mail("UNC_STEALTH", "vname=abe,stealth=0.5", 0)     # abe is heard only within 50 m
    r.on_mail("UNC_EARANGE", "vname=cal,earange=2", 0)       # cal hears from 100 m (x 0.5 x 2)
    # abe->ben: 60 m > 50; abe->cal: 90 <= 100 x 0.5 x 2; ben->cal: 150 <= 200; cal->ben: 150 > 100
    assert heard(r, 0, ("abe", 0, 0), ("ben", 60, 0), ("cal", -90, 0)) == {
        ("abe", "CAL"), ("ben", "ABE"), ("ben", "CAL"), ("cal", "ABE")}
    r.on_mail("UNC_STEALTH", "vname=abe,stealth=0.01", 0)
    assert r.params.stealth["ABE"] == 0.1                     # clipped as the C++ app does


def test_drop_percentage_is_seeded_and_drops_that_share():
    vehicles = [(f"v{i}", i, 0) for i in range(11)]          # all within 10 m: 110 relays a round
    runs = []
    for seed in (3, 3, 4):
        r = relay(seed=seed, drop_percentage=20, critical_range=0)
        runs.append([sorted(heard(r, t, *vehicles)) for t in range(100)])
        if len(runs) == 1:
            sent, dropped = r.stats.reports_sent, r.stats.reports_dropped
    assert runs[0] == runs[1] and runs[0] != runs[2]          # same seed, same drops
    assert sent + dropped == 11_000
    assert abs(dropped - 2200) < 4 * np.sqrt(11_000 * 0.2 * 0.8)   # 20 % within four standard deviations


def test_min_rpt_interval_thins_reports_per_pair():
    r = relay(min_rpt_interval=2, critical_range=0)
    rounds = [heard(r, t, ("abe", 0, 0), ("ben", 50, 0)) for t in (0, 1, 2, 3, 4)]
    assert [len(x) for x in rounds] == [2, 0, 2, 0, 2]


def test_nolimit_and_zero_range():
    assert NodeCommsParams.from_config({"comms_range": "nolimit"}).comms_range == -1
    far = relay(comms_range="nolimit", critical_range=0)
    assert len(heard(far, 0, ("abe", 0, 0), ("ben", 1e6, 0))) == 2
    deaf = relay(comms_range=0, critical_range=0)
    assert heard(deaf, 0, ("abe", 0, 0), ("ben", 1, 0)) == set()


# ---- node messages --------------------------------------------------------------------------

def messages(r, now, *texts):
    for text in texts:
        r.on_mail("NODE_MESSAGE", text, now, "pHelmIvP@abe")
    return [(k, v) for k, v in r.iterate(now) if k.startswith("NODE_MESSAGE_")]


def fleet(r, now):
    heard(r, now, ("abe", 0, 0, "red"), ("ben", 10, 0, "red"), ("cal", 20, 0, "blue"), ("dan", 500, 0, "red"))


def test_messages_go_to_the_named_node_group_or_all_within_range():
    r = relay(min_msg_interval=0, critical_range=0)
    fleet(r, 0)
    one = "src_node=abe,dest_node=ben,var_name=FOO,string_val=bar"
    assert messages(r, 0, one) == [("NODE_MESSAGE_BEN", one)]
    listed = "src_node=abe,dest_node=ben:cal,var_name=FOO,double_val=3"
    assert [k for k, _ in messages(r, 0, listed)] == ["NODE_MESSAGE_BEN", "NODE_MESSAGE_CAL"]
    group = "src_node=abe,dest_group=red,var_name=FOO,string_val=\"a, b\""
    assert [k for k, _ in messages(r, 0, group)] == ["NODE_MESSAGE_BEN"]   # dan is red but 500 m away
    assert r.stats.blk_far == 1
    every = "src_node=abe,dest_node=all,var_name=FOO,string_val=x"
    assert [k for k, _ in messages(r, 0, every)] == ["NODE_MESSAGE_BEN", "NODE_MESSAGE_CAL"]


def test_message_interval_length_and_validity():
    r = relay(min_msg_interval=30, max_msg_length=5, critical_range=0)
    fleet(r, 0)
    short = "src_node=abe,dest_node=ben,var_name=FOO,string_val=12345"
    assert len(messages(r, 0, short, short)) == 1 and r.stats.blk_quick == 1    # one per 30 s per sender
    assert messages(r, 10, short) == [] and r.stats.blk_quick == 2
    fleet(r, 30)
    assert messages(r, 30, "src_node=abe,dest_node=ben,var_name=FOO,string_val=123456") == []
    assert r.stats.blk_long == 1
    assert messages(r, 30, "src_node=abe,var_name=FOO,string_val=x") == []      # no destination
    assert r.stats.blk_invalid == 1 and "pHelmIvP@abe" in r.warnings[-1]


def test_messages_to_unknown_or_stale_vehicles_are_blocked():
    r = relay(min_msg_interval=0, stale_time=5, critical_range=0)
    fleet(r, 0)
    heard(r, 10, ("abe", 0, 0))
    assert messages(r, 10, "src_node=abe,dest_node=ben,var_name=FOO,string_val=x") == []
    assert messages(r, 10, "src_node=abe,dest_node=zed,var_name=FOO,string_val=x") == []
    assert (r.stats.blk_stale, r.stats.blk_noinfo) == (1, 1)


# ---- configuration and the real process -----------------------------------------------------

def test_configuration_errors_name_the_line(tmp_path):
    path = tmp_path / "shore.moos"
    path.write_text("ServerPort = 9000\nCommunity = shoreside\n\nProcessConfig = uFldNodeComms\n{\n"
                    "  comms_range = 100\n  stealth = vname=abe\n}\n")
    with pytest.raises(MissionFileError, match=r"shore\.moos:7: stealth"):
        NodeComms(path).on_startup()


def test_relay_as_a_process_between_two_vehicles(tmp_path):
    """A real uFldNodeComms process on a real moosdb: reports within range come back as NODE_REPORT_<V>."""
    db = start_moosdb("--moos_community", "shoreside")
    mission = one_app_mission(tmp_path / "shoreside.moos", db.port, "shoreside", "uFldNodeComms",
                              "  AppTick = 10\n  comms_range = 100\n  critical_range = 5\n  stale_time = 50\n"
                              "  min_msg_interval = 0\n")
    app = subprocess.Popen([str(Path(sys.executable).parent / "uFldNodeComms"), str(mission)],
                           stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    mail = []
    client = MOOSClient("shore_watch", "127.0.0.1", db.port, on_mail=mail.extend, time_warp=10,
                        on_connect=lambda: [client.register(k) for k in
                                            ("NODE_REPORT_ABE", "NODE_REPORT_BEN", "NODE_REPORT_CAL", "NODE_MESSAGE_BEN")])

    def got(key):
        return [m.string for m in mail if m.key == key]

    async def scenario():
        task = asyncio.create_task(client.run())
        try:
            await async_wait_until(lambda: client.connected, timeout=10)
            reports = {"abe": "NAME=abe,X=0,Y=0,SPD=1,HDG=90", "ben": "NAME=ben,X=80,Y=0,SPD=1,HDG=270",
                       "cal": "NAME=cal,X=300,Y=0,SPD=1,HDG=0"}

            def post_all():
                for text in reports.values():
                    client.notify("NODE_REPORT", text)
                return got("NODE_REPORT_ABE") and got("NODE_REPORT_BEN")

            await async_wait_until(post_all, timeout=20, interval=0.2)
            client.notify("NODE_MESSAGE", "src_node=abe,dest_node=ben,var_name=HELLO,string_val=there")
            await async_wait_until(lambda: got("NODE_MESSAGE_BEN"), timeout=10)
        finally:
            client.close()
            await task
        return reports

    try:
        reports = asyncio.run(scenario())
    finally:
        app.terminate()
        err = app.communicate(timeout=10)[1].decode()
        db.stop()
    assert set(got("NODE_REPORT_BEN")) == {reports["abe"]} and set(got("NODE_REPORT_ABE")) == {reports["ben"]}
    assert got("NODE_REPORT_CAL") == []                       # 220 m and more from the others
    assert got("NODE_MESSAGE_BEN") == ["src_node=abe,dest_node=ben,var_name=HELLO,string_val=there"]
    assert "Traceback" not in err, err
