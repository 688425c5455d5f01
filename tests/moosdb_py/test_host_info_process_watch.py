"""pHostInfo and uProcessWatch: their pure logic, then both against a real moosdb with a pShare and a
node broker that takes its host record from pHostInfo."""
from __future__ import annotations

import asyncio
import os

import pytest
from helpers import async_wait_until, start_moosdb

from moosdb_py.client import MOOSClient
from moosdb_py.host_info import HostInfo, HostRecord, choose_host_ip, interface_addresses, iroutes_from_summary
from moosdb_py.process_watch import ProcessWatch, ProcessWatchState, parse_mapping
from moosdb_py.share import Share
from oilspill_moos.field.node_broker import NodeBroker, NodeBrokerState

WARP = 10


def test_host_ip_choice():
    found = {"lo": "127.0.0.1", "eth0": "10.1.2.3", "wlan0": "192.168.1.5"}
    chosen = choose_host_ip(found, "localhost", "")
    assert (chosen.best, chosen.all) == ("10.1.2.3", ["10.1.2.3", "192.168.1.5"])
    assert chosen.verbose == "LINUX_LO=127.0.0.1,LINUX_ETH0=10.1.2.3,LINUX_WLAN0=192.168.1.5"
    assert choose_host_ip(found, "localhost", "localhost").best == "localhost"
    assert choose_host_ip({"lo": "127.0.0.1"}, "1.2.3.4", "").all == ["1.2.3.4"]
    assert "127.0.0.1" in interface_addresses().values()     # this machine's loopback, read by ioctl


def test_host_record_from_input_summary():
    record = HostRecord(community="abe", hostip="localhost", port_db="9001",
                        pshare_iroutes=iroutes_from_summary("localhost:9201, localhost:9202,"), timewarp="10")
    assert record.spec() == "community=abe,hostip=localhost,port_db=9001,pshare_iroutes=localhost:9201&localhost:9202,timewarp=10"


def test_broker_prefers_a_complete_phi_host_info():
    state = NodeBrokerState("abe")
    state.on_input_summary("localhost:9201", "localhost", 9001, 10.0)
    state.on_host_info("community=abe,hostip=10.0.0.5,port_db=9001,timewarp=10", "abe")   # no routes yet
    assert state.host_record.hostip == "localhost"
    state.on_host_info("community=abe,hostip=10.0.0.5,port_db=9001,pshare_iroutes=localhost:9201,timewarp=10", "abe")
    state.on_input_summary("localhost:9999", "localhost", 9001, 10.0)     # PHI_HOST_INFO now wins
    assert (state.host_record.hostip, state.host_record.pshare_iroutes) == ("10.0.0.5", "localhost:9201")


def test_process_watch_events_and_summaries():
    state = ProcessWatchState("uProcessWatch", watch=["pHelm*"], nowatch=["uXMS*"], summary_wait=-1)
    assert state.iterate(0.0) == []                       # nothing before the first DB_CLIENTS
    events = state.on_clients("uProcessWatch,pLogger,uXMS_1,")
    assert ("PROC_WATCH_EVENT", "Process [pHelm*] is noted to be missing.") in events
    assert state.iterate(1.0) == [("PROC_WATCH_SUMMARY", "AWOL: pHelm*"), ("PROC_WATCH_ALL_OK", "false")]
    state.on_clients("uProcessWatch,pLogger,pHelmIvP,")
    assert state.iterate(2.0) == [("PROC_WATCH_SUMMARY", "All Present"), ("PROC_WATCH_ALL_OK", "true")]
    assert state.iterate(3.0) == []                       # unchanged, summary_wait = -1
    state.on_clients("uProcessWatch,pHelmIvP,")
    assert state.summary() == "AWOL: pLogger"
    assert state.full_summary() == "pHelm*(1/1),pLogger(1/1)"
    assert "uXMS_1" not in state.watched


def test_process_watch_without_retractions_and_with_repeats():
    state = ProcessWatchState("w", watch_all=True, allow_retractions=False, summary_wait=5)
    state.on_clients("a,b,")
    state.on_clients("a,")
    state.on_clients("a,b,")                               # b came back: still AWOL without retractions
    assert state.iterate(0.0)[0] == ("PROC_WATCH_SUMMARY", "AWOL: b")
    assert state.iterate(4.0) == []
    assert state.iterate(5.0)[0] == ("PROC_WATCH_SUMMARY", "AWOL: b")   # repeated after summary_wait
    with pytest.raises(ValueError, match="post_mapping"):
        parse_mapping("NOT_OURS, X", "f.moos:3")
    assert parse_mapping("proc_watch_summary, UPW", "f") == ("PROC_WATCH_SUMMARY", "UPW")


def test_bad_watch_all_names_its_line(tmp_path):
    path = tmp_path / "m.moos"
    path.write_text("ServerPort = 9000\nProcessConfig = uProcessWatch\n{\n  watch_all = sometimes\n}\n")
    with pytest.raises(ValueError, match=r"m.moos:4: watch_all"):
        ProcessWatch(path).on_startup()


@pytest.fixture
def abe_db():
    """A moosdb of community abe: the broker takes only its own community's PHI_HOST_INFO."""
    db = start_moosdb("--moos_community", "abe")
    yield db
    db.stop()


def test_host_info_and_process_watch_against_a_moosdb(abe_db, tmp_path, free_port):
    udp = free_port()
    path = tmp_path / "abe.moos"
    path.write_text(
        f"ServerHost = localhost\nServerPort = {abe_db.port}\nCommunity = abe\nMOOSTimeWarp = {WARP}\n\n"
        f"ProcessConfig = pShare\n{{\n  AppTick = 10\n  input = route = localhost:{udp}\n}}\n"
        "ProcessConfig = pHostInfo\n{\n  AppTick = 4\n  default_hostip_force = 10.9.8.7\n}\n"
        "ProcessConfig = uFldNodeBroker\n{\n  AppTick = 4\n  try_shore_host = pshare_route=localhost:9200\n}\n"
        "ProcessConfig = uProcessWatch\n{\n  AppTick = 4\n  watch_all = false\n  watch = pShare\n"
        "  watch = pHostInfo\n  summary_wait = -1\n  post_mapping = PROC_WATCH_FULL_SUMMARY, UPW_FULL\n}\n")
    apps = [HostInfo(path), ProcessWatch(path), NodeBroker(path)]
    share = Share(path)
    watcher = MOOSClient("watch", port=abe_db.port, time_warp=WARP)
    keys = ["PHI_HOST_INFO", "PHI_HOST_IP", "PHI_HOST_PORT_DB", "PROC_WATCH_SUMMARY", "PROC_WATCH_EVENT",
            "UPW_FULL", "PROC_WATCH_TIME_WARP", "NODE_BROKER_PING_0", "UFLDNODEBROKER_PID"]
    for key in keys:
        watcher.register(key)

    def values(key):
        return [m.value for m in watcher.inbox if m.key == key]

    async def scenario():
        tasks = [asyncio.create_task(a.run_async()) for a in [*apps, share]]
        watching = asyncio.create_task(watcher.run())
        try:
            # the full record comes once pShare has said where it listens; the broker pings with it
            info = f"community=abe,hostip=10.9.8.7,port_db={abe_db.port},pshare_iroutes=localhost:{udp},timewarp=10"
            await async_wait_until(lambda: info in values("PHI_HOST_INFO"), timeout=15)
            await async_wait_until(lambda: any(str(v).startswith(info) for v in values("NODE_BROKER_PING_0")), timeout=15)
            assert values("PHI_HOST_IP")[-1] == "10.9.8.7" and values("PHI_HOST_PORT_DB")[-1] == str(abe_db.port)
            await async_wait_until(lambda: "All Present" in values("PROC_WATCH_SUMMARY"), timeout=15)
            assert values("PROC_WATCH_TIME_WARP") == [float(WARP)]
            assert values("UFLDNODEBROKER_PID") == [float(os.getpid())]   # what uMemWatch measures
            share.stop()                                       # pShare goes away: noticed from DB_CLIENTS
            await async_wait_until(lambda: "AWOL: pShare" in values("PROC_WATCH_SUMMARY"), timeout=15)
            assert "Process [pShare] is noted to be missing." in values("PROC_WATCH_EVENT")
            assert values("UPW_FULL")[-1] == "pShare(1/1),pHostInfo(1/0)"
        finally:
            for app in apps:
                app.stop()
            share.stop()
            await asyncio.gather(*tasks)
            watcher.close()
            await watching

    asyncio.run(scenario())


def test_watch_all_antler_watches_the_run_list(tmp_path):
    path = tmp_path / "m.moos"
    path.write_text("ServerPort = 9000\nProcessConfig = ANTLER\n{\n  Run = MOOSDB @ NewConsole = false\n"
                    "  Run = pHelmIvP @ NewConsole = false\n  Run = uXMS @ NewConsole = false\n"
                    "  Run = uSimMarine @ NewConsole = false ~ uSim_abe\n  Run = uProcessWatch @ NewConsole = false\n}\n"
                    "ProcessConfig = uProcessWatch\n{\n  watch_all = antler\n  nowatch = uXMS*\n}\n")
    app = ProcessWatch(path)
    app.on_startup()
    assert list(app.state.watched) == ["pHelmIvP", "uSim_abe"] and not app.state.watch_all
    app.state.on_clients("pHelmIvP,uProcessWatch,pLogger,")
    assert app.state.summary() == "AWOL: uSim_abe"     # pLogger is not in the Run list: not watched
