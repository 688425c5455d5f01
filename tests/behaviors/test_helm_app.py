"""pHelmIvP as a real process against a real moosdb, driven by a test client."""
import asyncio
import os
import subprocess
import sys
from pathlib import Path

import pytest

from behaviors.helm_app import main
from moosdb_py.client import MOOSClient

WARP = 10
BHV = """initialize DEPLOY = false
Behavior = BHV_Waypoint
{
  name = go
  condition = DEPLOY = true
  points = 100,0
  speed = 2
  endflag = ARRIVED = true
}
"""


def exe(name: str) -> str:
    return os.path.join(os.path.dirname(sys.executable), name)


def write_mission(folder: Path, port: int, bhv: str = BHV) -> Path:
    (folder / "t.bhv").write_text(bhv)
    moos = folder / "t.moos"
    moos.write_text(f"ServerHost = localhost\nServerPort = {port}\nCommunity = abe\nMOOSTimeWarp = {WARP}\n"
                    "LatOrigin = 43.8253\nLongOrigin = -70.3304\n\nProcessConfig = pHelmIvP\n{\n  AppTick = 4\n"
                    "  behaviors = t.bhv\n  domain = course:0:359:360\n  domain = speed:0:4:41\n}\n")
    return moos


def test_help_example_interface(capsys):
    for flag, fragment in (("--help", "IvP helm"), ("--example", "ProcessConfig = pHelmIvP"),
                           ("--interface", "DESIRED_HEADING")):
        assert main([flag]) == 0
        assert fragment in capsys.readouterr().out


def test_skewed_mail_is_ignored_but_fresh_registrations_pass(tmp_path):
    from behaviors.helm_app import HelmIvP
    from moosdb_py.message import MOOSMsg

    app = HelmIvP(write_mission(tmp_path, 9000))   # t.bhv is found beside the mission file
    app.on_startup()
    now = app.moos_time()
    app.registered_at = {"DEPLOY": now - 500}
    app.on_new_mail([MOOSMsg.notification("DEPLOY", "true", time=now - 100, source="uPokeDB")])
    assert app.helm.info.get("DEPLOY") == "false"          # stale by 100 s, registered long ago
    app.on_new_mail([MOOSMsg.notification("DEPLOY", "true", time=now - 5, source="uPokeDB")])
    assert app.helm.info.get("DEPLOY") == "true"
    app.registered_at["RETURN"] = now
    app.on_new_mail([MOOSMsg.notification("RETURN", "x", time=now - 1000, source="uPokeDB")])
    assert app.helm.info.get("RETURN") == "x"              # arrived just after registering


@pytest.mark.parametrize("block, message", [
    ("behaviors = missing.bhv", "behaviors: file 'missing.bhv' not found"),
    ("behaviors = t.bhv\n  behaviors = t.bhv", "a file is named twice"),
    ("behaviors = t.bhv\n  domain = speed:0:4", "domain: domain 'speed:0:4'"),
])
def test_bad_helm_config_is_a_startup_error(tmp_path, block, message):
    from behaviors.helm_app import HelmIvP
    moos = write_mission(tmp_path, 9000)
    moos.write_text(moos.read_text().replace("behaviors = t.bhv", block))
    with pytest.raises(ValueError, match=message):
        HelmIvP(moos).on_startup()


def test_unknown_behavior_type_stops_startup(tmp_path, free_port):
    moos = write_mission(tmp_path, free_port(), "Behavior = BHV_Nonesuch\n{\n  speed = 1\n}\n")
    out = subprocess.run([exe("pHelmIvP"), moos.name], cwd=tmp_path, capture_output=True, text=True, timeout=30)
    assert out.returncode == 1
    assert "t.bhv:1: unknown behavior type 'BHV_Nonesuch'" in out.stderr


def test_helm_drives_after_override_and_deploy(tmp_path, moosdb_server):
    moos = write_mission(tmp_path, moosdb_server.port)
    helm = subprocess.Popen([exe("pHelmIvP"), moos.name], cwd=tmp_path, stderr=subprocess.PIPE, text=True)
    try:
        seen = asyncio.run(drive(moosdb_server.port))
    finally:
        helm.terminate()
        helm.wait(timeout=10)
    summary = {k: v[-5:] for k, v in seen.items()}
    assert "DRIVE" in seen["IVPHELM_STATE"], summary
    assert 90.0 in seen["DESIRED_HEADING"] and 2.0 in seen["DESIRED_SPEED"], summary
    assert seen["DESIRED_SPEED"][-1] == 0.0, summary          # all-stop zeros once the waypoint is reached
    assert seen["ARRIVED"] == ["true"], summary


async def drive(port: int) -> dict:
    seen: dict = {}
    x = [0.0]

    def on_mail(mail):
        for m in mail:
            seen.setdefault(m.key, []).append(m.value)

    client = MOOSClient("tester", port=port, on_mail=on_mail, time_warp=WARP)
    task = asyncio.create_task(client.run())
    assert await client.wait_connected(10)
    for var in ("IVPHELM_STATE", "DESIRED_HEADING", "DESIRED_SPEED", "ARRIVED"):
        client.register(var)

    async def until(var, value, timeout=45.0, after=0):
        deadline = asyncio.get_running_loop().time() + timeout
        while value not in seen.get(var, [])[after:]:
            assert asyncio.get_running_loop().time() < deadline, f"no {var}={value}; seen {seen}"
            for key, v in dict(NAV_X=x[0], NAV_Y=0.0, NAV_HEADING=90.0, NAV_SPEED=2.0).items():
                client.notify(key, v)
            await asyncio.sleep(0.05)

    await until("IVPHELM_STATE", "PARK")
    client.notify("MOOS_MANUAL_OVERRIDE", "false")
    client.notify("DEPLOY", "true")
    await until("DESIRED_HEADING", 90.0)
    x[0] = 99.0
    driving = len(seen["DESIRED_SPEED"])
    await until("ARRIVED", "true")
    await until("DESIRED_SPEED", 0.0, after=driving)
    client.close()
    await task
    return seen
