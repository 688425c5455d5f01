"""uPokeDB and uXMS: poke parsing, the scope table, and both tools against a real moosdb."""
import asyncio
import os
import subprocess
import sys
import threading

import pytest

from moosdb_py.client import MOOSClient
from moosdb_py.message import SERVER_REQUEST_ID, MOOSMsg
from moosdb_py.poke import Poke, parse_poke, poke_db
from moosdb_py.poke import main as poke_main
from moosdb_py.xms import Scope, format_table, history_line, value_text
from moosdb_py.xms import main as xms_main

from helpers import async_wait_until, start_moosdb


def tool(name, *args, timeout=20):
    return subprocess.run([sys.executable, "-m", f"moosdb_py.{name}", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, env={**os.environ, "PYTHONUNBUFFERED": "1"})


@pytest.mark.parametrize("text,poke", [
    ("DEPLOY=true", Poke("DEPLOY", "true")),
    ("SPEED=2.5", Poke("SPEED", 2.5)),
    ("NAME:=12", Poke("NAME", "12")),
    ("PTS=x=1,y=2", Poke("PTS", "x=1,y=2")),
    ("EMPTY:=", Poke("EMPTY", "")),
])
def test_parse_poke(text, poke):
    assert parse_poke(text) == poke


@pytest.mark.parametrize("text", ["DEPLOY", "=1", ":=x"])
def test_bad_pokes(text):
    with pytest.raises(ValueError, match="expected VAR=value"):
        parse_poke(text)


def msg(key, value, source="src", time=10.0, community="c", aux=""):
    m = MOOSMsg.notification(key, value, time=time, source=source, source_aux=aux)
    m.community = community
    return m


def test_scope_wildcards_sources_and_table():
    scope = Scope(["NAV_X", "MISSING", "DB_*"], sources=["uSim*", "MOOSDB*"], start=8.0)
    taken = scope.take([msg("NAV_X", 1.5, "uSimMarine"), msg("NAV_X", 9.0, "intruder"),
                        msg("DB_TIME", 3.0, "MOOSDB_c"), msg("OTHER", 1.0, "uSimMarine"),
                        msg("NAV_Y", "x", "uSimMarine")])
    assert [m.key for m in taken] == ["NAV_X", "DB_TIME"]
    assert format_table(scope, {"source", "time", "community", "aux"}).splitlines() == [
        "VarName  (S)ource    (T)ime  (C)ommunity  (A)ux Source  VarValue",
        "-------  --------    ------  -----------  ------------  --------",
        "NAV_X    uSimMarine  2.00    c                          1.5",
        "MISSING  n/a         n/a     n/a          n/a           n/a",
        "DB_TIME  MOOSDB_c    2.00    c                          3"]
    assert "MISSING" not in format_table(scope, set(), novirgins=True)


def test_value_text_and_history_line():
    assert value_text(msg("A", "hello world"), trunc=5) == '"hell...'
    assert value_text(msg("A", b"\x00" * 3)) == "<binary: 3 bytes>"
    assert history_line(msg("DEPLOY", "true", "uPokeDB", time=12.5), 10.0) == \
        '2.50       DEPLOY               uPokeDB         "true"'


def test_poke_then_scope_by_mission_and_by_port(moosdb_server, tmp_path):
    mission = tmp_path / "m.moos"
    mission.write_text(f"ServerHost = {moosdb_server.host}\nServerPort = {moosdb_server.port}\n"
                       "ProcessConfig = uXMS\n{\n  var = DEPLOY, SPEED\n  display_community = true\n}\n"
                       "ProcessConfig = uPokeDB\n{\n  poke = RETURN:=false\n}\n")
    first = tool("poke", mission, "DEPLOY=true", "SPEED=2.5", "--cache")
    assert first.returncode == 0, first.stderr
    prior, after = first.stdout.split("AFTER Poking the MOOSDB")
    assert "DEPLOY   n/a" in prior and '"true"' in after and "2.5" in after and '"false"' in after
    second = tool("poke", "--host", moosdb_server.host, "--port", moosdb_server.port, "SPEED=3", "NAME:=12")
    assert second.returncode == 0, second.stderr
    assert "2.5" in second.stdout.split("AFTER")[0] and "3" in second.stdout.split("AFTER")[1]
    shown = tool("xms", mission, "--once")
    assert shown.returncode == 0, shown.stderr
    rows = {line.split()[0]: line.split() for line in shown.stdout.splitlines()[2:]}
    assert rows["DEPLOY"][-1] == '"true"' and rows["SPEED"][-1] == "3" and rows["SPEED"][1] == "uPokeDB"
    assert "(C)ommunity" in shown.stdout
    by_port = tool("xms", "--port", moosdb_server.port, "NAME", "RET*", "NEVER", "--once", "--show=source")
    lines = by_port.stdout.splitlines()
    assert lines[0].split() == ["VarName", "(S)ource", "VarValue"]
    assert [line.split()[0] for line in lines[2:]] == ["NAME", "NEVER", "RETURN"]
    assert lines[3].split() == ["NEVER", "n/a", "n/a"]


def test_history_mode_prints_every_post(moosdb_server):
    scope = subprocess.Popen([sys.executable, "-m", "moosdb_py.xms", "--port", str(moosdb_server.port),
                              "--history=COUNT", "--duration=60"], stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        assert scope.stdout.readline().split() == ["Time", "VarName", "Source", "VarValue"]  # registered now
        for n in (1, 2):
            asyncio.run(poke_db(moosdb_server.host, moosdb_server.port, [Poke("COUNT", float(n))]))
        lines = [scope.stdout.readline(), scope.stdout.readline()]
    finally:
        scope.terminate()
        scope.wait(5)
    assert [line.split()[1:] for line in lines] == [["COUNT", "uPokeDB", "1"], ["COUNT", "uPokeDB", "2"]]


def in_process(main, capsys, *args):
    """Run a tool's main() here (no interpreter start-up); returns (code, stdout, stderr)."""
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_tools_fail_clearly_without_a_db(free_port, capsys):
    port = free_port()
    code, _, err = in_process(poke_main, capsys, "--port", port, "--timeout", "0.3", "A=1")
    assert code == 1 and f"no MOOSDB answering on localhost:{port}" in err
    code, _, err = in_process(xms_main, capsys, "--port", port, "--wait", "0.3", "A", "--once")
    assert code == 1 and f"no MOOSDB answering on localhost:{port}" in err


def test_a_name_the_db_refuses_is_explained(moosdb_server, capsys):
    connected, release = threading.Event(), threading.Event()

    async def hold_the_name():
        holder = MOOSClient("uXMS", moosdb_server.host, moosdb_server.port)
        running = asyncio.create_task(holder.run())
        if await holder.wait_connected(10):
            connected.set()
        await asyncio.to_thread(release.wait, 30)
        holder.close()
        await running

    thread = threading.Thread(target=asyncio.run, args=(hold_the_name(),))
    thread.start()
    try:
        assert connected.wait(15)
        code, _, err = in_process(xms_main, capsys, "--port", moosdb_server.port, "A", "--once")
    finally:
        release.set()
        thread.join(15)
    assert code == 1 and f"the MOOSDB on localhost:{moosdb_server.port} refused uXMS" in err


def test_bad_command_lines(tmp_path, capsys):
    assert "nothing to poke" in in_process(poke_main, capsys)[2]
    assert "nothing to watch" in in_process(xms_main, capsys)[2]
    assert "unknown column" in in_process(xms_main, capsys, "A", "--show=colour")[2]
    broken = tmp_path / "b.moos"
    broken.write_text("ProcessConfig = a\n{\n")
    assert f"{broken}:1: block a is never closed" in in_process(poke_main, capsys, broken, "A=1")[2]


@pytest.mark.parametrize("main", [poke_main, xms_main])
def test_example_and_interface(main, capsys):
    assert "ProcessConfig = " in in_process(main, capsys, "--example")[1]
    assert "SUBSCRIPTIONS" in in_process(main, capsys, "--interface")[1]


def test_refreshing_table_until_duration(moosdb_server, capsys):
    code, out, _ = in_process(xms_main, capsys, "--port", moosdb_server.port, "DB_UPTIME", "--mode=streaming",
                              "--refresh=0.2", "--duration=0.6")
    tables = [chunk for chunk in out.split("VarName") if chunk.strip()]
    assert code == 0 and len(tables) >= 2 and "DB_UPTIME" in tables[-1]


def test_options_after_the_mission_file_and_pokes_on_the_dbs_clock(tmp_path):
    """The mission on disk says warp 1 (pAntler --MOOSTimeWarp=10 overrode it): pokes still carry DB time."""
    db = start_moosdb("--moos_time_warp", "10")
    try:
        mission = tmp_path / "alpha.moos"
        mission.write_text("ServerHost = localhost\nServerPort = 1\nMOOSTimeWarp = 1\n")
        poked = tool("poke", mission, "--port", db.port, "DEPLOY=true", "--quiet", "RETURN:=false")
        assert poked.returncode == 0, poked.stderr

        async def deploy_and_community_clock():
            watcher = MOOSClient("watcher", port=db.port, time_warp=10)   # on the community's clock
            watcher.register("DEPLOY")
            watcher.register("DB_UPTIME")   # and until the DB has posted its uptime (uXMS's time origin)
            running = asyncio.create_task(watcher.run())
            try:
                await async_wait_until(lambda: {m.key for m in watcher.inbox} >= {"DEPLOY", "DB_UPTIME"}, 10)
                return next(m for m in watcher.inbox if m.key == "DEPLOY"), watcher.moos_time()
            finally:
                watcher.close()
                await running
        deploy, now = asyncio.run(deploy_and_community_clock())
        # stamped with uPokeDB's own warp-1 clock it would be 9 x the epoch (~15e9 s) behind
        assert (deploy.string, deploy.source) == ("true", "uPokeDB") and abs(deploy.time - now) < 60
        # uXMS on the same file counts (T)ime on the DB's clock too, from the DB's start as the C++ uXMS
        # (issue 14: it counted from its own start, so the poke showed a negative time): a few warped
        # seconds after the DB started, never negative
        shown = tool("xms", mission, "--port", db.port, "DEPLOY", "DB_UPTIME", "--once", "--show=time")
        assert shown.returncode == 0, shown.stderr
        rows = {line.split()[0]: line.split() for line in shown.stdout.splitlines()[2:]}
        age, uptime = float(rows["DEPLOY"][1]), float(rows["DB_UPTIME"][2])
        assert 0 <= age <= uptime + 1 and age < 120, shown.stdout
    finally:
        db.stop()



def test_time_column_counts_from_the_db_start_as_the_cpp_uxms():
    """C++ uXMS: (T)ime = message time - (DB time - DB_UPTIME) at the first DB_UPTIME, two decimals, so a
    value written before uXMS started is not negative (issue 14 saw -0.61)."""
    scope = Scope(["DEPLOY"], start=1000.0)              # uXMS's own start on the DB's clock, the fallback
    reply = MOOSMsg.notification("DB_UPTIME", 3.0, time=3.0, source="MOOSDB_#1")
    reply.id = SERVER_REQUEST_ID                         # the ALL answer stamps variables with their age
    deploy = msg("DEPLOY", "true", "uPokeDB", time=999.39)
    scope.note_db_start([reply, deploy])
    scope.take([deploy])
    assert not scope.db_started and format_table(scope, {"time"}).splitlines()[2].split()[1] == "-0.61"
    scope.note_db_start([msg("DB_UPTIME", 12.5, "MOOSDB_#1", time=1002.5), deploy])
    assert scope.db_started and scope.start == 990.0
    assert format_table(scope, {"time"}).splitlines()[2].split()[1] == "9.39"
    scope.note_db_start([msg("DB_UPTIME", 99.0, "MOOSDB_#1", time=1100.0)])   # the first one counts
    assert scope.start == 990.0 and history_line(deploy, scope.start).split()[0] == "9.39"
