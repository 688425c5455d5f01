"""pAntler: launch plans, nsplug'd missions, and real runs that must leave no process behind."""
import asyncio
import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from helpers import async_wait_until, wait_until
from moosdb_py.alog import read_alog
from moosdb_py.antler import DB_TARGET, LaunchSpec, _parser, expanded_mission, plan, split_overrides
from moosdb_py.client import MOOSClient
from moosdb_py.mission import AntlerRun, Where, read_mission
from moosdb_py.source import MissionFileError

ANTLER = """ServerHost = localhost
ServerPort = {port}
Community = test

ProcessConfig = ANTLER
{{
  MSBetweenLaunches = 10
{runs}
  SleepArgs = 300
  LsArgs = /no/such/folder/for/pantler
  HeadArgs = -c,200000,/dev/zero
}}
"""


def write(tmp_path, runs, port=9000, name="m.moos"):
    path = tmp_path / name
    path.write_text(ANTLER.format(port=port, runs=runs))
    return path


def test_plan_resolves_python_apps_the_db_and_path_programs(tmp_path):
    (tmp_path / "bin").mkdir()
    tool = tmp_path / "bin" / "iTool"
    tool.write_text("#!/bin/sh\n")
    tool.chmod(0o755)
    path = write(tmp_path, "\n".join([
        "  Run = MOOSDB @ NewConsole = false",
        "  Run = pLogger @ NewConsole = true ~ pLogger_2",
        "  Run = sleep @ InhibitMOOSParams = true, ExtraProcessParams = SleepArgs",
        f"  Run = iTool @ Path = {tmp_path / 'bin'}",
        "  Run = pNoSuchApp",
    ]))
    specs, problems = plan(read_mission(path), path)
    assert [(s.name, s.target, s.executable, s.args) for s in specs] == [
        ("MOOSDB", DB_TARGET, None, [str(path)]),
        ("pLogger_2", "moosdb_py.logger:Logger", None, [str(path), "pLogger_2"]),
        ("sleep", None, subprocess.run(["which", "sleep"], capture_output=True, text=True).stdout.strip(), ["300"]),
        ("iTool", None, str(tool), [str(path), "iTool"])]
    bin_dir = Path(sys.executable).parent
    assert specs[0].argv() == [sys.executable, str(bin_dir / "moosdb"), str(path)]
    assert specs[1].argv() == [sys.executable, str(bin_dir / "pLogger"), str(path), "pLogger_2"]
    assert problems == [f"{path}:12: cannot launch pNoSuchApp: not a project app and not found on PATH"]
    only, _ = plan(read_mission(path), path, ["pLogger_2", "iTool"])
    assert [s.name for s in only] == ["pLogger_2", "iTool"]


@pytest.mark.parametrize("target,expected", [("moosdb_py.xms:main", "ProcessConfig = uXMS"),
                                             ("moosdb_py.logger:Logger", "ProcessConfig = pLogger")])
def test_apps_without_a_console_script_start_through_the_boot_line(tmp_path, target, expected):
    run = AntlerRun(exe="pPlugin", moos_name="pPlugin", source=Where(file=tmp_path / "m.moos", line=1))
    argv = LaunchSpec(run, ["--example"], target=target).argv()
    assert argv[1] == "-c"
    assert expected in subprocess.run(argv, capture_output=True, text=True, timeout=20).stdout


def test_command_line_mixes_filters_macros_and_overrides():
    rest, overrides = split_overrides(["m.moos", "--nsplug", "A=1", "pLogger", "--MOOSTimeWarp=3", "uXMS",
                                       "--nsplug=B=2", "--ServerPort=9100"])
    assert overrides == {"MOOSTimeWarp": "3", "ServerPort": "9100"}
    args = _parser().parse_intermixed_args(rest)
    assert (args.mission, args.only, args.nsplug) == ("m.moos", ["pLogger", "uXMS"], ["A=1", "B=2"])


def test_plan_needs_an_antler_block(tmp_path):
    path = tmp_path / "x.moos"
    path.write_text("Community = a\n")
    with pytest.raises(MissionFileError, match="no ProcessConfig = ANTLER block"):
        plan(read_mission(path), path)


def test_templates_and_overrides_are_expanded_for_the_children(tmp_path):
    meta = tmp_path / "meta.moos"
    meta.write_text("ServerPort = $(PORT)\nMOOSTimeWarp = 1\n#ifdef SIM\nCommunity = sim\n#endif\n")
    out = tmp_path / "out"
    out.mkdir()
    mission, child_file = expanded_mission(meta, {"PORT": "9555", "SIM": "1"}, {"MOOSTimeWarp": "20"}, out)
    assert child_file == out / "meta.moos"
    assert (mission.server_port, mission.community, mission.time_warp) == (9555, "sim", 20.0)
    plain = tmp_path / "plain.moos"
    plain.write_text("ServerPort = 9001\n")
    assert expanded_mission(plain, {}, {}, out)[1] == plain.resolve()
    with pytest.raises(MissionFileError, match=r"meta.moos:1: ServerPort = '\$\(PORT\)'"):
        expanded_mission(meta, {}, {}, out)
    with pytest.raises(MissionFileError, match=r"<command line>:1: MOOSTimeWarp = 'fast' is not a positive number"):
        expanded_mission(meta, {"PORT": "1"}, {"MOOSTimeWarp": "fast"}, out)
    assert mission.antler is None and read_mission(child_file).server_port == 9555


def pantler(*args, cwd=None):
    return subprocess.Popen([sys.executable, "-m", "moosdb_py.antler", *map(str, args)], cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})


def test_unreadable_mission_starts_nothing(tmp_path):
    path = write(tmp_path, "  Run = MOOSDB\n  Run = sleep @ Bad")
    proc = pantler(path)
    out, _ = proc.communicate(timeout=20)
    assert proc.returncode == 1
    assert f"{path}:9: Run option 'Bad' is not key=value" in out and "nothing started" in out
    assert "launched" not in out


class Output:
    """Collects a process's output lines on a thread, so the test can wait on them."""

    def __init__(self, proc):
        self.lines: list[str] = []
        self.thread = threading.Thread(target=lambda: self.lines.extend(proc.stdout), daemon=True)
        self.thread.start()

    @property
    def text(self) -> str:
        return "".join(self.lines)


def interrupted_after(proc, output: Output, scenario):
    """What the scenario (a coroutine) returns; then Ctrl-C to pAntler and its exit awaited (killed if it hangs)."""
    try:
        result = asyncio.run(scenario)
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)
    finally:
        if proc.poll() is None:
            proc.kill()
    output.thread.join(5)
    return result


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:   # a zombie is dead; one reaped between the two looks is gone
        return "\nState:\tZ" not in Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_every_child_and_dead_children_are_reported(tmp_path, free_port, sig):
    path = write(tmp_path, "\n".join([
        "  Run = MOOSDB",
        "  Run = sleep @ InhibitMOOSParams = true, ExtraProcessParams = SleepArgs",
        "  Run = sleep @ InhibitMOOSParams = true, ExtraProcessParams = SleepArgs ~ sleep_2",
        "  Run = ls @ InhibitMOOSParams = true, ExtraProcessParams = LsArgs",
        "  Run = head @ InhibitMOOSParams = true, ExtraProcessParams = HeadArgs",   # one 200 kB line
    ]), port=free_port())
    proc = pantler(path, cwd=tmp_path)
    output = Output(proc)
    try:
        wait_until(lambda: re.search(r"ls \(pid \d+\) exited with code 2", output.text)
                   and re.search(r"head \(pid \d+\) exited with code 0", output.text), timeout=20)
        pids = [int(p) for p in re.findall(r"launched \S+ \(pid (\d+)\)", output.text)]
        assert len(pids) == 5
        assert "/no/such/folder/for/pantler" in output.text.split("exited with code 2; last output:")[1]
        proc.send_signal(sig)
        proc.wait(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
    output.thread.join(5)
    assert proc.returncode == 1   # ls failed on its own
    assert not [pid for pid in pids if alive(pid)]


HELLO = Path(__file__).resolve().parents[2] / "missions" / "hello"


async def tool(name, *args):
    proc = await asyncio.create_subprocess_exec(sys.executable, "-m", f"moosdb_py.{name}", *map(str, args),
                                                stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE)
    out, err = await asyncio.wait_for(proc.communicate(), 20)
    assert proc.returncode == 0, err.decode()
    return out.decode()


@pytest.mark.parametrize("one_process", [False, True], ids=["processes", "one-process"])
def test_hello_mission_end_to_end(tmp_path, free_port, one_process):
    """pAntler runs missions/hello; uPokeDB deploys, the vehicle heads east, uXMS shows it; the alog has it all;
    nothing is left behind."""
    port = free_port()
    proc = pantler(HELLO / "hello.moos", "--nsplug", f"PORT={port}", "--nsplug", f"LOGDIR={tmp_path}",
                   "--nsplug", f"BHV_DIR={HELLO}", "--MOOSTimeWarp=4", *(["--one-process"] if one_process else []),
                   cwd=tmp_path)
    output = Output(proc)

    async def scenario():
        latest = {}
        watcher = MOOSClient("watcher", "127.0.0.1", port, time_warp=4,
                             on_mail=lambda mail: latest.update((m.key, m.value) for m in mail),
                             on_connect=lambda: [watcher.register(k) for k in
                                                 ("LOGGER_DIRECTORY", "IVPHELM_STATE", "NAV_X", "NAV_SPEED")])
        comms = asyncio.create_task(watcher.run())
        try:
            # the logger, the simulator and the helm are up and registered once their first posts are seen
            await async_wait_until(lambda: {"LOGGER_DIRECTORY", "IVPHELM_STATE", "NAV_X"} <= latest.keys(), timeout=60)
            # no --warp: uPokeDB stamps with the DB's clock, as the helm and the PID want under warp 4
            await tool("poke", "--port", port, "DEPLOY=true", "MOOS_MANUAL_OVERRIDE=false")
            await async_wait_until(lambda: latest.get("NAV_SPEED", 0) > 0.5 and latest["NAV_X"] > 1, timeout=60)
            return await tool("xms", "--port", port, "--warp", 4, "DEPLOY", "DESIRED_SPEED", "IVPHELM_STATE", "--once")
        finally:
            watcher.close()
            await asyncio.wait([comms], timeout=5)

    shown = interrupted_after(proc, output, scenario())
    rows = {line.split()[0]: line.split()[-1] for line in shown.splitlines()[2:]}
    assert rows == {"DEPLOY": '"true"', "DESIRED_SPEED": "1.5", "IVPHELM_STATE": '"DRIVE"'}
    pids = [int(p) for p in re.findall(r"launched \S+ \(pid (\d+)\)", output.text)]
    assert len(pids) == (1 if one_process else 5) and proc.returncode == 0, output.text
    assert not [pid for pid in pids if alive(pid)]
    (folder,) = tmp_path.glob("LOG_HELLO_*")
    log = read_alog(folder / f"{folder.name}.alog")
    assert log.last("DEPLOY").value == "true" and log.last("DEPLOY").source == "uPokeDB"
    assert 1.5 in log.values("DESIRED_SPEED") and "DRIVE" in log.values("IVPHELM_STATE")
    assert log.last("NAV_X").value > 1 and log.last("NAV_X").source == "uSimMarineV22"
    assert f"ServerPort   = {port}" in (folder / f"{folder.name}._moos").read_text()
    # the helm asks the logger (PLOGGER_CMD = COPY_FILE_REQUEST) for a copy of its behaviour file
    assert (folder / f"{folder.name}._bhv").read_text() == (HELLO / "hello.bhv").read_text()


def test_missions_hosted_together_run_in_one_process_and_stop_together(tmp_path, free_port):
    """pAntler a.moos --with b.moos: both communities' MOOSDBs serve on their own ports and both apps tick,
    all in pAntler's process (nothing launched); one Ctrl-C stops both."""
    ports = [free_port(), free_port()]
    paths = [write(tmp_path, "  Run = MOOSDB\n  Run = uLoadWatch", port=port, name=f"{name}.moos")
             for name, port in zip("ab", ports)]
    proc = pantler(paths[0], "--with", paths[1], "--MOOSTimeWarp=4", cwd=tmp_path)
    output = Output(proc)

    async def statuses():
        seen = {}
        clients = [MOOSClient(f"watch{i}", "127.0.0.1", port, time_warp=4,
                              on_mail=lambda mail, i=i: seen.update({(i, m.key): m.string for m in mail}))
                   for i, port in enumerate(ports)]
        for client in clients:
            client.register("ULOADWATCH_STATUS")
        tasks = [asyncio.create_task(c.run()) for c in clients]
        try:
            await async_wait_until(lambda: {(0, "ULOADWATCH_STATUS"), (1, "ULOADWATCH_STATUS")} <= seen.keys(),
                                   timeout=30)
        finally:
            for client in clients:
                client.close()
            await asyncio.wait(tasks, timeout=5)
        return seen

    seen = interrupted_after(proc, output, statuses())
    assert proc.returncode == 0, output.text
    assert all("MOOSName=uLoadWatch" in text for text in seen.values())
    assert output.text.count("hosting uLoadWatch in-process") == 2 and "launched" not in output.text
    assert sorted(re.findall(r"hosting MOOSDB in-process on port (\d+)", output.text)) == sorted(map(str, ports))


@pytest.mark.parametrize("one_process", [False, True], ids=["processes", "one-process"])
def test_an_app_with_a_bad_config_is_reported_with_its_error(tmp_path, free_port, one_process):
    path = tmp_path / "bad.moos"
    path.write_text(f"ServerPort = {free_port()}\nProcessConfig = ANTLER\n{{\n  MSBetweenLaunches = 10\n"
                    "  Run = MOOSDB\n  Run = pLogger\n}\nProcessConfig = pLogger\n{\n  Log = NAV_X @ soon\n}\nstray words\n")
    proc = pantler(path, *(["--one-process"] if one_process else []), cwd=tmp_path)
    output = Output(proc)
    try:
        reason = f"{path}:10: Log = 'NAV_X @ soon': period 'soon' is not a number"
        report = "pLogger (in-process) failed: " if one_process else "exited with code 1; last output:"
        wait_until(lambda: report in output.text and reason in output.text, timeout=20)
        assert f"pAntler: {path}:12: ignored line outside any block: stray words" in output.text
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 1


def test_entry_points_alone_say_which_apps_exist():
    from importlib import metadata

    from moosdb_py.antler import APP_GROUP, PROGRAM_GROUP, python_target
    for group in (APP_GROUP, PROGRAM_GROUP):
        for ep in metadata.entry_points(group=group):
            assert python_target(ep.name) is not None, ep.name
    assert python_target("uXMS") == "moosdb_py.xms:main" and python_target("pHelmIvP") == "behaviors.helm_app:HelmIvP"
    # a console script that no group declares (a tool, not a MOOS program) is not launched as an app
    assert python_target("nsplug") is None and python_target("moos-lint") is None
    source = (Path(__file__).resolve().parents[2] / "moosdb_py" / "antler.py").read_text()
    assert '"oilspill_moos"' not in source and '"behaviors"' not in source
