""".moos grammar: globals, ProcessConfig blocks, the Antler block, and clear errors for broken files."""
import pytest
from hypothesis import given, settings, strategies as st

from moosdb_py.mission import read_mission
from moosdb_py.source import MissionFileError


def mission(tmp_path, text, defines=None):
    path = tmp_path / "m.moos"
    path.write_text(text)
    return read_mission(path, defines)


BASIC = """// header comment
ServerHost = localhost   // inline comment
ServerPort = 9123
Community  = abe
MOOSTimeWarp = 10
LatOrigin = 43.8253
LongOrigin = -70.3304

Processconfig = ANTLER
{
  MSBetweenLaunches = 50
  ExecutablePath = /opt/moos/bin
  Run = MOOSDB        @ NewConsole = false
  Run = uXMS          @ NewConsole = true ~ uXMS_NAV
  Run = pLogger       @ NewConsole = false, ExtraProcessParams = LogArgs, Path = SYSTEM
  Run = bin/iRemote
  LogArgs = --verbose, --foo
}

PROCESSCONFIG=pHelmIvP
{
  behaviors = a.bhv
  behaviors = b.bhv
  points = 60,-40 : 60,-160     // comment
  msg = "keep // this"
  =orphan
  no_value_line
  [bracketed]
  empty =
}
"""


def test_globals_and_typed_fields(tmp_path):
    m = mission(tmp_path, BASIC)
    assert m.globals == {"ServerHost": "localhost", "ServerPort": "9123", "Community": "abe", "MOOSTimeWarp": "10",
                         "LatOrigin": "43.8253", "LongOrigin": "-70.3304"}
    assert (m.server_host, m.server_port, m.community, m.time_warp) == ("localhost", 9123, "abe", 10.0)
    assert (m.lat_origin, m.long_origin) == (43.8253, -70.3304)
    assert m.get_global("communITY") == "abe" and m.get_global("nothing", "x") == "x"


def test_defaults_when_globals_are_missing(tmp_path):
    m = mission(tmp_path, "ProcessConfig = a\n{\n}\n")
    assert (m.server_host, m.server_port, m.community, m.time_warp, m.lat_origin) == ("localhost", 9000, "#1", 1.0, None)


def test_block_entries_keep_order_case_and_inner_blanks(tmp_path):
    helm = mission(tmp_path, BASIC).process_config("phelmivp")
    assert helm.name == "pHelmIvP"
    assert [(e.key, e.value) for e in helm.entries] == [
        ("behaviors", "a.bhv"), ("behaviors", "b.bhv"), ("points", "60,-40 : 60,-160"),
        ("msg", '"keep // this"'), ("", "orphan"), ("[bracketed]", "")]
    assert helm.get("BEHAVIORS") == "b.bhv" and helm.get_all("behaviors") == ["a.bhv", "b.bhv"]
    assert helm.entry("points").moos_value == "60,-40:60,-160"
    assert helm.entry("msg").moos_value == "keep//this"
    assert helm.entry("points").source.line == 24 and helm.get("missing", "d") == "d"


def test_antler_block(tmp_path):
    antler = mission(tmp_path, BASIC).antler
    assert antler.ms_between_launches == 50 and antler.executable_path == "/opt/moos/bin"
    runs = [(r.exe, r.moos_name, r.new_console, r.extra_params, r.path) for r in antler.runs]
    assert runs == [("MOOSDB", "MOOSDB", False, [], None), ("uXMS", "uXMS_NAV", True, [], None),
                    ("pLogger", "pLogger", False, ["--verbose", "--foo"], "SYSTEM"),
                    ("bin/iRemote", "iRemote", False, [], None)]
    assert antler.runs[1].source.line == 14


def test_antler_defaults(tmp_path):
    antler = mission(tmp_path, "ProcessConfig = ANTLER\n{\n  Run = MOOSDB\n  ExecutablePath = SYSTEMPATH\n}\n").antler
    assert antler.ms_between_launches == 1000 and antler.executable_path is None
    assert not antler.runs[0].inhibit_moos_params


def test_global_lookup_quirk_first_line_anywhere_wins(tmp_path):
    text = "ProcessConfig = a\n{\n  Community = inside\n}\nCommunity = outside\nCommunity = later\n"
    m = mission(tmp_path, text)
    assert m.community == "inside" and m.globals == {"Community": "outside"}


def test_duplicate_blocks_first_wins_with_a_warning(tmp_path):
    m = mission(tmp_path, "ProcessConfig = a\n{\n x = 1\n}\nProcessConfig = A\n{\n x = 2\n}\n")
    assert m.process_config("a").get("x") == "1"
    assert m.warnings == [f"{tmp_path / 'm.moos'}:5: second block for A is ignored (MOOS uses the first, at "
                          f"{tmp_path / 'm.moos'}:1)"]


def test_tolerated_oddities_are_warnings(tmp_path):
    """What MOOS reads past without harm: a block whose header is commented out, stray braces."""
    m = mission(tmp_path, "//ProcessConfig = old\n{\n  Community = ghost\n}\n}\nProcessConfig = a\n{\n{\n x = 1\n}\n"
                          "just words\n")
    where = tmp_path / "m.moos"
    assert [b.name for b in m.blocks] == ["a"] and m.process_config("a").get("x") == "1"
    assert m.warnings == [f"{where}:2: block without a ProcessConfig header (commented out?) is ignored",
                          f"{where}:5: stray '}}' outside any block is ignored",
                          f"{where}:8: stray '{{' inside block a is ignored",
                          f"{where}:11: ignored line outside any block: just words"]
    assert m.community == "ghost"   # MOOS's global scan still sees the skipped block's lines


def test_moos_dollar_brace_defines(tmp_path, monkeypatch):
    monkeypatch.setenv("MOOS_TEST_HOME", "/home/x")
    m = mission(tmp_path, "define: PORT = 9555\nServerPort = ${PORT}\nPath = ${MOOS_TEST_HOME}/log ${NOPE}\n")
    assert m.server_port == 9555 and m.globals["Path"] == "/home/x/log${NOPE}"


def test_nsplug_runs_first(tmp_path):
    m = mission(tmp_path, "ServerPort = $(PORT=9001)\nCommunity = %(V)\n", {"V": "abe"})
    assert (m.server_port, m.community) == (9001, "ABE")


def test_unexpanded_macro_fails_only_when_the_value_is_used(tmp_path):
    m = mission(tmp_path, "ServerPort = $(MOOS_PORT)\n")
    with pytest.raises(MissionFileError, match=r"m.moos:1: ServerPort = '\$\(MOOS_PORT\)' is not a TCP port.*--nsplug"):
        m.check()


@pytest.mark.parametrize("text,message", [
    ("ProcessConfig = a\n{\n x = 1\n", r"m.moos:1: block a is never closed"),
    ("ProcessConfig = a\n x = 1\n}\n", r"m.moos:1: ProcessConfig = a is not followed by '\{'"),
    ("ProcessConfig = a {\n}\n", r"m.moos:1: '\{' must be on its own line"),
    ("ProcessConfig = a\n{\n x = 1\nProcessConfig = b\n{\n}\n", r"m.moos:4: ProcessConfig = b inside block a"),
    ("{\n x = 1\n", r"m.moos:1: block \(no header\) is never closed"),
    ("ProcessConfig =\n{\n}\n", r"m.moos:1: ProcessConfig needs a process name"),
    ("ProcessConfig = a\n", r"m.moos:1: ProcessConfig = a is not followed by"),
    ("ServerPort = 70000\n", r"m.moos:1: ServerPort = '70000' is not a TCP port number"),
    ("MOOSTimeWarp = 0\n", r"m.moos:1: MOOSTimeWarp = '0' is not a positive number"),
    ("x = " + "a" * 2000 + "\n", r"m.moos:1: line longer than 1999"),
])
def test_broken_files_name_file_and_line(tmp_path, text, message):
    with pytest.raises(MissionFileError, match=message):
        mission(tmp_path, text).check()


@pytest.mark.parametrize("run,message", [
    ("@ NewConsole = false", "without a program name"),
    ("pLogger ~", "'~' but no MOOS name"),
    ("pLogger @ NewConsole", "'NewConsole' is not key=value"),
    ("pLogger ~ a ~ b", "wrong place"),
    ("pLogger @ ExtraProcessParams = Missing", "has no 'Missing = ...' line"),
])
def test_malformed_run_lines(tmp_path, run, message):
    text = f"ProcessConfig = ANTLER\n{{\n  MSBetweenLaunches = 10\n  Run = {run}\n}}\n"
    with pytest.raises(MissionFileError, match=rf"m.moos:4: .*{message}"):
        mission(tmp_path, text)


def test_bad_ms_between_launches(tmp_path):
    with pytest.raises(MissionFileError, match=r"m.moos:3: MSBetweenLaunches = 'soon'"):
        mission(tmp_path, "ProcessConfig = ANTLER\n{\n MSBetweenLaunches = soon\n}\n")


def test_missing_file_is_a_mission_file_error(tmp_path):
    with pytest.raises(MissionFileError, match="file not found"):
        read_mission(tmp_path / "none.moos")


KEYS = st.from_regex(r"[A-Za-z_][A-Za-z0-9_]{0,10}", fullmatch=True).filter(lambda k: k.lower() != "processconfig")
VALUES = st.from_regex(r"[A-Za-z0-9_.:,@~=\-\[\]]([A-Za-z0-9_.:,@~=\- ]{0,20}[A-Za-z0-9_.:,@~=\-])?", fullmatch=True)
BLANKS = st.sampled_from(["", " ", "  ", "\t", " \t "])
BLOCKS = st.lists(st.tuples(KEYS, st.lists(st.tuples(KEYS, VALUES, BLANKS, st.booleans()), max_size=6)),
                  min_size=1, max_size=4, unique_by=lambda b: b[0].lower())


@settings(max_examples=30, deadline=None)
@given(blocks=BLOCKS, pad=BLANKS)
def test_render_then_parse_property(tmp_path_factory, blocks, pad):
    """Whatever the spacing and comments, every block comes back with its entries in order."""
    lines = []
    for name, entries in blocks:
        lines += [f"{pad}ProcessConfig{pad}={pad}{name}", "// between", f"{pad}{{"]
        for key, value, blank, comment in entries:
            lines.append(f"{blank}{key}{blank}={blank}{value}{blank}" + ("// note = x" if comment else ""))
        lines.append(f"{pad}}}")
    path = tmp_path_factory.mktemp("prop") / "p.moos"
    path.write_text("\n".join(lines) + "\n")
    m = read_mission(path)
    assert [b.name for b in m.blocks] == [name for name, _ in blocks]
    for block, (_, entries) in zip(m.blocks, blocks):
        assert [(e.key, e.value) for e in block.entries] == [(k, v) for k, v, _, _ in entries]
