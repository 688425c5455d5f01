"""Every console script resolves; every app answers --help, --example and --interface; every one has a
docs page linked from docs/index.md, an app's page carrying its --example block; a reader that closes
the pipe early gets no traceback."""
from __future__ import annotations

import importlib
import inspect
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
SCRIPTS = PROJECT["scripts"]
APPS = PROJECT["entry-points"]["moosdb_py.apps"]     # the MOOSApp classes pAntler can host
TOOLS = {"nsplug", "moos-lint"}          # file tools, not MOOS apps: --help only
NOT_DB_CLIENTS = {"oilspill-forecaster"}  # talks TCP to pPathAssign: its interface is input and output
DOCS = {"oilspill-forecaster": "forecaster.md", "nsplug": "mission-files.md", "pantler": "pAntler.md",
        "uSimMarineV22": "uSimMarine.md", "pMarinePIDV22": "pMarinePID.md"}


def entry(name: str, table: dict = SCRIPTS):
    module, _, attr = table[name].partition(":")
    return getattr(importlib.import_module(module), attr)


def page(name: str, flag: str, capsys) -> str:
    try:
        code = entry(name)([flag])
    except SystemExit as exc:     # argparse's --help
        code = exc.code
    out = capsys.readouterr().out
    assert code == 0, f"{name} {flag} exited {code}"
    return out


@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_script_resolves_and_answers_help(name, capsys):
    assert callable(entry(name))
    assert len(page(name, "--help", capsys).strip()) > 40


@pytest.mark.parametrize("name", sorted(set(SCRIPTS) - TOOLS))
def test_app_answers_example_and_interface(name, capsys):
    assert page(name, "--example", capsys).strip()
    interface = page(name, "--interface", capsys).upper()
    assert "OUTPUT" in interface if name in NOT_DB_CLIENTS else "SUBSCRI" in interface and "PUBLI" in interface


@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_docs_page_linked_from_the_index(name):
    doc = DOCS.get(name, f"{name}.md")
    assert (ROOT / "docs" / doc).is_file(), doc
    assert f"]({doc})" in (ROOT / "docs" / "index.md").read_text(), f"docs/index.md does not link {doc}"


@pytest.mark.parametrize("name", sorted(APPS))
def test_docs_page_carries_the_example_block(name):
    app = entry(name, APPS)
    page = (ROOT / "docs" / f"{app.default_name}.md").read_text()
    missing = [line.strip() for line in inspect.cleandoc(app.example_config).splitlines()
               if line.strip() and line.strip() not in page]
    assert not missing, f"docs/{app.default_name}.md lacks these --example lines: {missing}"


@pytest.mark.parametrize("name", ["moosdb", "uPokeDB", "uSimMarine"])   # the DB, a tool, a MOOSApp
def test_a_reader_that_stops_early_is_no_error(name):
    """`APP --example | head -1`: the closed pipe ends the page quietly."""
    proc = subprocess.Popen([str(Path(sys.executable).parent / name), "--example"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(30) == 0 and "Traceback" not in err, err
