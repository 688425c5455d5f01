"""moosdb_py.config: parameters declared once; --example, the docs table and the warnings read the declaration."""
import logging
import re
from importlib.metadata import entry_points
from pathlib import Path

import pytest

from moosdb_py.app import MOOSApp
from moosdb_py.config import MOOS_APP_KEYS, ConfigValueError, Param, Params
from moosdb_py.source import MissionFileError

DOCS = Path(__file__).resolve().parents[2] / "docs"
APPS = sorted({(ep.name, ep.load()) for ep in entry_points(group="moosdb_py.apps")}, key=lambda item: item[0])
DECLARING = {cls.default_name: cls for _, cls in APPS if cls.parameters is not None}


class Counter(MOOSApp):
    default_name = "pCounter"
    parameters = Params(Param("step", float, 1.0, "added each iteration", lo=0),
                        Param("enabled", bool, True, "count at all"),
                        Param("limit", int, 10, "stop here", 1, 100),
                        Param("tag", list, [], "repeatable"))


def mission(tmp_path, body: str) -> Path:
    path = tmp_path / "m.moos"
    path.write_text(f"ServerPort = 9000\nProcessConfig = pCounter\n{{\n{body}\n}}\n")
    return path


def test_typed_values_and_defaults(tmp_path):
    app = Counter(mission(tmp_path, "  step = 2.5\n  enabled = OFF\n  tag = a\n  tag = b\n  AppTick = 4"))
    assert app.read_settings() == {"step": 2.5, "enabled": False, "limit": 10, "tag": ["a", "b"]}
    assert Counter.parameters.read({}) == {"step": 1.0, "enabled": True, "limit": 10, "tag": []}


@pytest.mark.parametrize("line, message", [("step = -1", "m.moos:4: step: -1 is outside [0, None]"),
                                           ("enabled = yes", "m.moos:4: enabled: expected true or false"),
                                           ("limit = 2.5", "m.moos:4: limit: expected a whole number"),
                                           ("limit = 1000", "m.moos:4: limit: 1000 is outside [1, 100]")])
def test_a_bad_value_is_named_at_its_line(tmp_path, line, message):
    with pytest.raises(MissionFileError, match=re.escape(message)):
        Counter(mission(tmp_path, f"  {line}")).read_settings()


def test_undeclared_lines_are_warned_once_at_their_line_moos_app_keys_are_not(tmp_path, caplog):
    path = mission(tmp_path, "  stpe = 2\n  MaxAppTick = 10\n  AppTick = 4\n  term_reporting = true")
    with caplog.at_level(logging.WARNING):
        Counter(path)
    assert [r.getMessage() for r in caplog.records] == [f"{path}:4: unhandled parameter 'stpe'"]
    assert {"maxapptick", "apptick", "commstick"} <= MOOS_APP_KEYS


def test_a_declaration_can_be_looked_up_and_listed():
    assert Counter.parameters["STEP"].kind is float and Counter.parameters["Limit"].hi == 100
    assert [p.name for p in Counter.parameters] == ["step", "enabled", "limit", "tag"]
    assert Counter.parameters.names == {"step", "enabled", "limit", "tag"}


def test_dict_configs_read_like_blocks():
    with pytest.raises(ConfigValueError, match="step: expected a number"):
        Counter.parameters.read({"step": "fast"})


def example_keys(cls) -> set[str]:
    body = cls.example_config.split("{", 1)[1].rsplit("}", 1)[0]
    keys = set()
    for line in body.splitlines():
        line = line.split("//", 1)[0]
        if "=" in line:
            keys.add(line.split("=", 1)[0].strip().lower())
    return keys - MOOS_APP_KEYS


@pytest.mark.parametrize("name", sorted(DECLARING))
def test_example_shows_what_the_app_declares(name):
    cls = DECLARING[name]
    assert example_keys(cls) <= cls.parameters.names, f"{name}: --example shows undeclared parameters"


@pytest.mark.parametrize("name", sorted(DECLARING))
def test_docs_table_is_the_declaration(name):
    page = (DOCS / f"{name}.md").read_text()
    table = DECLARING[name].parameters.table()
    assert table in page, f"docs/{name}.md lacks its parameter table; it should read:\n{table}"


def test_every_app_of_this_project_declares_its_parameters():
    own = {cls.default_name for _, cls in APPS if cls.__module__.startswith(("moosdb_py", "oilspill_moos.marine",
                                                                            "oilspill_moos.field",
                                                                            "oilspill_moos.response"))}
    assert own <= set(DECLARING)
