"""missions/fleet: the templates expand into one community per vehicle, and the fleet talks."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

from moosdb_py.mission import read_mission

FLEET = Path(__file__).resolve().parents[2] / "missions" / "fleet"


def load_launcher():
    spec = importlib.util.spec_from_file_location("fleet_launch", FLEET / "launch.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


def test_templates_expand_into_separate_communities(tmp_path):
    launcher = load_launcher()
    files = launcher.generate(launcher.plan(3, 10.0, 9500, 9700), tmp_path)
    missions = [read_mission(f) for f in files]
    assert [m.community for m in missions] == ["shoreside", "abe", "ben", "cal"]
    assert [m.server_port for m in missions] == [9500, 9501, 9502, 9503]
    assert {m.time_warp for m in missions} == {10.0}
    routes = [m.process_config("pShare").get("input") for m in missions]
    assert routes == [f"route = localhost:{9700 + i}" for i in range(4)]
    for vehicle in missions[1:]:
        broker = vehicle.process_config("uFldNodeBroker")
        assert broker.get("try_shore_host") == "pshare_route=localhost:9700"
        assert "src=NODE_REPORT_LOCAL,  alias=NODE_REPORT" in broker.get_all("bridge")
        bhv = (tmp_path / f"targ_{vehicle.community}.bhv").read_text()
        assert "$(" not in bhv
    shore = missions[0].process_config("uFldShoreBroker")
    assert any("DEPLOY" in q for q in shore.get_all("qbridge"))
    assert [r.exe for r in missions[1].antler.runs][:1] == ["MOOSDB"]


def test_launcher_rejects_bad_fleet_sizes(tmp_path):
    launcher = load_launcher()
    with pytest.raises(ValueError, match="--vehicles"):
        launcher.plan(0, 1.0)
    assert launcher.main(["--vehicles", "99", "--generate-only", "--dir", str(tmp_path)]) == 2
