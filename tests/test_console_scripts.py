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
# --version: the forecaster is the forecaster engineer's (issue 14 asks it of them too); every other
# script answers it here.
SHORT_PAGES = {"uXMS", "uPokeDB"} | {name for name in SCRIPTS if SCRIPTS[name].rpartition(":")[0] in
                                    {value.rpartition(":")[0] for value in APPS.values()}}
NOT_DB_CLIENTS = {"oilspill-forecaster"}  # talks TCP to pPathAssign: its interface is input and output
DOCS = {"oilspill-forecaster": "forecaster.md", "nsplug": "mission-files.md", "pantler": "pAntler.md", "MOOSDB": "moosdb.md",
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


@pytest.mark.parametrize("name", sorted(SCRIPTS))   # moos-lint too: its interface says it has none
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


@pytest.mark.parametrize("name", sorted(SCRIPTS))
def test_script_answers_version(name, capsys):
    text = page(name, "--version", capsys)
    assert PROJECT["version"] in text and "oilspill-moos" in text and len(text.splitlines()) == 1


@pytest.mark.parametrize("name", sorted(SHORT_PAGES - {"pShare"}))
def test_ivp_short_forms_e_and_i(name, capsys):
    """MOOS-IvP apps take -e and -i for --example and --interface (pShare's -i is its input routes)."""
    assert page(name, "-e", capsys) == page(name, "--example", capsys)
    assert page(name, "-i", capsys) == page(name, "--interface", capsys)


def test_moosdb_is_also_MOOSDB():
    assert SCRIPTS["MOOSDB"] == SCRIPTS["moosdb"]
    assert (Path(sys.executable).parent / "MOOSDB").is_file()


@pytest.mark.parametrize("flag", ["-i", "-i=", "--input", "-o"])
def test_pshare_switch_without_routes_is_an_error_not_a_silent_start(flag, capsys):
    assert entry("pShare")([flag]) == 1
    err = capsys.readouterr().err
    assert f"pShare: {flag.rstrip('=')} needs routes" in err and "--interface" in err


def test_nsplug_example_expands(tmp_path, capsys):
    from moosdb_py.nsplug import EXAMPLE
    (tmp_path / "meta_vehicle.moos").write_text(EXAMPLE)
    (tmp_path / "plug_origin_warp.moos").write_text("MOOSTimeWarp = 1\n")
    assert entry("nsplug")([str(tmp_path / "meta_vehicle.moos"), "-t", "VNAME=abe", "PORT=9001"]) == 0
    out = capsys.readouterr().out
    assert "ServerPort = 9001" in out and "Community  = abe" in out and "START_POS = 0,-20" in out
    assert "MOOSTimeWarp = 1" in out and "50,-20" not in out


def test_an_app_whose_db_does_not_answer_says_it_is_retrying(tmp_path, free_port):
    """As MOOS apps do: a real app process, pointed at a port nobody listens on, says so at once."""
    port = free_port()
    mission = tmp_path / "m.moos"
    mission.write_text(f"ServerHost = localhost\nServerPort = {port}\nCommunity = abe\n")
    proc = subprocess.Popen([str(Path(sys.executable).parent / "pCoordinates"), str(mission)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stderr.readline()     # blocks until the first line; the process keeps retrying
        assert line.strip() == f"pCoordinates: connecting to 127.0.0.1:{port} ... retrying", line
        assert proc.poll() is None
    finally:
        proc.terminate()
        proc.wait(10)
