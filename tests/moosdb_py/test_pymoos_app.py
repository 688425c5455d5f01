"""pymoos `app()` scripts and the worked example of docs/pymoos.md, against a real moosdb."""
from __future__ import annotations

import logging
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from helpers import wait_until
from moosdb_py import pymoos
from moosdb_py.source import MissionFileError

DOCS = Path(__file__).resolve().parents[2] / "docs" / "pymoos.md"


@pytest.fixture(autouse=True)
def process_wide_time(monkeypatch):
    """A mission's MOOSTimeWarp is process-wide in pymoos; restore 1 and skew 0 after each test."""
    monkeypatch.setattr(pymoos, "_warp", 1.0)
    monkeypatch.setattr(pymoos, "_skew", 0.0)


def test_app_with_mission_file_iterate_and_mail(moosdb_server, tmp_path, caplog):
    port = moosdb_server.port
    mission = tmp_path / "script.moos"
    mission.write_text(f"ServerHost = localhost\nServerPort = {port}\nMOOSTimeWarp = 4\n\n"
                       "ProcessConfig = pScript\n{\n  AppTick = 20\n}\n")
    app = pymoos.app()
    iterations, mail, result = [], [], []

    def on_startup():
        app.set_comms_freq(10)
        return True

    def on_connect_to_server():
        return app.register("COMMAND", 0)

    def on_new_mail(msgs):
        mail.extend(msgs)
        return True

    def iterate():
        iterations.append(pymoos.time())
        app.notify("ITERATIONS", len(iterations))
        if len(iterations) == 3:
            raise RuntimeError("third iteration fails")
        return True

    app.set_on_start_up_callback(on_startup)
    app.set_on_connect_to_server_callback(on_connect_to_server)
    app.set_on_new_mail_callback(on_new_mail)
    app.set_iterate_callback(iterate)
    with caplog.at_level(logging.ERROR, logger="moosdb_py.comms"):
        runner = threading.Thread(target=lambda: result.append(app.run("localhost", port, "pScript", str(mission))))
        runner.start()
        watcher = pymoos.comms()
        seen = []
        watcher.set_on_connect_callback(lambda: watcher.register("ITERATIONS", 0))
        watcher.set_on_mail_callback(lambda: seen.extend(watcher.fetch()) or True)
        watcher.run("localhost", port, "watcher")
        wait_until(lambda: app.is_connected() and watcher.is_connected(), timeout=5)
        wait_until(lambda: watcher.notify("COMMAND", "go") and mail, timeout=5, interval=0.05)
        wait_until(lambda: len(seen) >= 5, timeout=5)
    assert "pScript Iterate: caught an exception" in caplog.text and len(iterations) > 3
    assert {m.string() for m in mail} == {"go"} and mail[0].source() == "watcher"
    assert [m.double() for m in seen[:2]] == [seen[0].double(), seen[0].double() + 1]
    assert pymoos.get_moos_timewarp() == 4 and watcher.time() > pymoos.local_time(False) * 3.9
    assert (app.get_app_freq(), app.get_comms_freq()) == (20, 10)
    assert app.get_app_name() == "pScript" and app.get_community_name() == "#1"
    assert app.is_registered_for("COMMAND") and not app.is_registered_for("ITERATIONS")
    assert app.set_app_freq(40) and app.get_app_freq() == 40
    assert app.request_quit()
    runner.join(5)
    assert result == [True] and not runner.is_alive() and not app.is_connected()
    watcher.close(True)


def test_app_without_mission_file_fetches_its_mail(moosdb_server):
    app = pymoos.app()
    with pytest.raises(RuntimeError, match=r"call run\(\) first"):
        app.notify("BLOB", 1.0)
    assert app.set_app_freq(50) and app.get_app_freq() == 50 and app.fetch() == []
    payload = bytes(range(256))
    fetched = []

    def iterate():
        if not fetched:
            app.notify_binary("BLOB", payload)
            app.notify("NOTE", "stamped", 1000.0)
        fetched.extend(app.fetch())
        if {m.name() for m in fetched} >= {"BLOB", "NOTE"}:
            app.request_quit()
        return True

    app.set_on_connect_to_server_callback(lambda: app.register("BLOB", 0) and app.register("NOTE", 0))
    app.set_iterate_callback(iterate)
    guard = threading.Timer(10.0, app.request_quit)     # ends a run that never sees its mail
    guard.start()
    try:
        assert app.run("localhost", moosdb_server.port, "pFetcher") is True
    finally:
        guard.cancel()
    blob = next(m for m in fetched if m.name() == "BLOB")
    note = next(m for m in fetched if m.name() == "NOTE")
    assert blob.is_binary() and blob.binary_data() == payload and note.time() == 1000.0
    assert app.get_app_freq() == 50


def test_app_start_up_failure_quits(free_port, caplog):
    """OnStartUp comes before connecting, so no DB is needed to see the app quit."""
    refusing, raising = pymoos.app(), pymoos.app()
    refusing.set_on_start_up_callback(lambda: False)
    raising.set_on_start_up_callback(lambda: 1 / 0)
    with caplog.at_level(logging.ERROR):
        assert refusing.run("localhost", free_port(), "pRefusing") is False
        assert raising.run("localhost", free_port(), "pRaising") is False
    assert "pRefusing: OnStartUp returned false" in caplog.text
    assert "pRaising OnStartUp: caught an exception" in caplog.text and "ZeroDivisionError" in caplog.text


def test_app_with_a_broken_mission_file_names_file_and_line(free_port, tmp_path):
    mission = tmp_path / "broken.moos"
    mission.write_text("ServerPort = 9000\nMOOSTimeWarp = fast\n\nProcessConfig = pScript\n{\n  AppTick = -2\n}\n")
    with pytest.raises(MissionFileError, match=r"broken.moos:6: AppTick = '-2' is not a positive number"):
        pymoos.app().run("localhost", free_port(), "pScript", str(mission))
    mission.write_text("MOOSTimeWarp = fast\n")
    with pytest.raises(MissionFileError, match=r"broken.moos:1: MOOSTimeWarp = 'fast' is not a positive number"):
        pymoos.app().run("localhost", free_port(), "pScript", str(mission))
    assert pymoos.get_moos_timewarp() == 1.0


def _worked_example() -> str:
    text = DOCS.read_text()
    return re.search(r"## Worked example.*?```python\n(.*?)```", text, re.S).group(1)


def test_worked_example_of_the_docs_runs_unchanged(moosdb_server, tmp_path):
    """The ported script, as docs/pymoos.md prints it, in its own process."""
    script = tmp_path / "depth_watch.py"
    script.write_text(_worked_example())
    assert "from moosdb_py import pymoos" in script.read_text()
    proc = subprocess.Popen([sys.executable, str(script), str(moosdb_server.port)], stderr=subprocess.PIPE,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})
    test = pymoos.comms()
    alarms, beats = [], []

    def on_mail():
        for msg in test.fetch():
            (alarms if msg.is_name("DEPTH_ALARM") else beats).append(msg)
        return True

    test.set_on_connect_callback(lambda: test.register("DEPTH_ALARM", 0) and test.register("DEPTH_WATCH_BEAT", 0))
    test.set_on_mail_callback(on_mail)
    test.run("localhost", moosdb_server.port, "tester")
    try:
        wait_until(lambda: beats or proc.poll() is not None, timeout=10)    # it runs, so it has registered
        assert proc.poll() is None, proc.stderr.read().decode()
        test.notify("DEPTH", 50.0)
        test.notify("DEPTH", 150.0)
        wait_until(lambda: alarms, timeout=5)
        assert [m.string() for m in alarms] == ["depth=150,max=100"] and alarms[0].source() == "depth_watch"
    finally:
        proc.terminate()
        proc.wait(5)
        test.close(True)
