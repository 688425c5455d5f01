"""moos-lint: every problem of a file at its line, with the severity of the app that reads the line."""
import os
import re
import subprocess
import sys
from importlib import metadata

import pytest

from behaviors.bhv_file import read_bhv
from behaviors.lint import main
from moosdb_py.formats import version_page
from moosdb_py.source import MissionFileError


def test_corpus_passes_from_each_folder(corpus, monkeypatch, capsys):
    files = sorted(corpus.glob("*/*.moos")) + sorted(corpus.glob("*/*.bhv"))
    for f in files:
        monkeypatch.chdir(f.parent)
        assert main([f.name]) == 0, f
    out, err = capsys.readouterr()
    assert out == ""
    summaries = [line for line in err.splitlines() if "warning:" not in line]
    assert len(summaries) == len(files) and all(re.fullmatch(r"1 file OK(, \d+ warnings?)?", s) for s in summaries)


def test_the_repos_own_missions_pass_as_the_readme_runs_it(monkeypatch, capsys, missions):
    """The README's command, from the top of a clone: no errors and no warnings in missions/."""
    monkeypatch.chdir(missions.parent)
    files = sorted(str(p.relative_to(missions.parent)) for p in missions.glob("*/*") if p.suffix in (".moos", ".bhv"))
    assert main(files) == 0
    out, err = capsys.readouterr()
    assert (out, err) == ("", f"{len(files)} files OK\n")


def test_problems_are_file_line_messages(tmp_path, capsys):
    bhv = tmp_path / "bad.bhv"
    bhv.write_text("Behavior = BHV_Waypoint\n{\n  name = w\n  speed = fast\n  capture_radius = -1\n"
                   "  points = $(START)\n}\n")
    moos = tmp_path / "bad.moos"
    moos.write_text("ServerPort = 90x\nProcessConfig = pHelmIvP\n{\n  domain = speed:0:4\n}\n")
    assert main([str(bhv), str(moos)]) == 1
    out, err = capsys.readouterr()
    out = out.splitlines()
    assert out[0] == f"{bhv}:4: BHV_Waypoint 'w': speed must be a number >= 0, got 'fast'"
    assert out[1].startswith(f"{bhv}:5: ")
    assert out[2].startswith(f"{moos}:1: ")
    assert out[3].startswith(f"{moos}:4: domain 'speed:0:4'")
    assert len(out) == 4
    assert err == "2 files: 4 errors, 0 warnings\n"


def test_defines_reach_nsplug(tmp_path, capsys):
    bhv = tmp_path / "m.bhv"
    bhv.write_text("#ifdef FAST yes\ninitialize SPEED = 3\n#else\nset MODE = {\n#endif\n")
    assert main([str(bhv), "-D", "FAST=yes"]) == 0
    assert main([str(bhv)]) == 1
    assert "m.bhv:4:" in capsys.readouterr().out


def test_console_script_runs(tmp_path):
    bhv = tmp_path / "ok.bhv"
    bhv.write_text("initialize DEPLOY = false\n")
    exe = os.path.join(os.path.dirname(sys.executable), "moos-lint")
    assert subprocess.run([exe, str(bhv)], capture_output=True, timeout=30).returncode == 0


def test_mission_warnings_go_to_stderr_without_failing(tmp_path, capsys):
    moos = tmp_path / "w.moos"
    moos.write_text("ServerPort = 9000\nstray words\nProcessConfig = a\n{\n}\nProcessConfig = a\n{\n}\n")
    assert main([str(moos)]) == 0
    out, err = capsys.readouterr()
    assert out == ""
    lines = err.splitlines()
    assert len(lines) == 3 and lines[2] == "1 file OK, 2 warnings" and lines[0] == f"{moos}:2: warning: ignored line outside any block: stray words"
    assert lines[1].startswith(f"{moos}:6: warning: second block for a is ignored")


def test_every_bad_line_is_reported_not_only_the_first(tmp_path, capsys):
    bhv = tmp_path / "many.bhv"
    bhv.write_text("initialize DEPLOY = false\n"
                   "stray words\n"                                         # 2: outside any block
                   "Behavior = BHV_Waypoint\n{\n  name = a\n"
                   "  condition = DEPLOY = = true\n"                       # 6: bad condition
                   "  speed = fast\n"                                      # 7
                   "  points = 60,-40 : 60,-160 : oops\n"                  # 8: not a vertex
                   "}\n"
                   "Behavior = BHV_StationKeep\n{\n  name = b\n"
                   "  pwt = -3\n"                                          # 13
                   "  station_pt = 1,x\n"                                  # 14
                   "}\n"
                   "initialize DEPLOY\n")                                  # 16: no value
    assert main([str(bhv)]) == 1
    out, err = capsys.readouterr()
    out = out.splitlines()
    assert [int(line.split(":")[1]) for line in out] == [2, 6, 7, 8, 13, 14, 16]
    assert "vertex 3 'oops' is not x,y" in out[3]
    assert err == "1 file: 7 errors, 0 warnings\n"


def test_every_bad_moos_line_is_reported_not_only_the_first(tmp_path, capsys):
    moos = tmp_path / "many.moos"
    moos.write_text("ServerPort = 90x\nLatOrigin = 43\nLongOrigin = -70\nProcessConfig = ANTLER\n{\n"
                    "  MSBetweenLaunches = fast\n"                          # 6
                    "  Run = MOOSDB @ NewConsole = false\n"
                    "  Run = pHelmIvP @ NewConsole\n"                       # 8: option not key=value
                    "  Run = pLogger @ NewConsole = false ~\n"              # 9: no MOOS name after '~'
                    "}\nProcessConfig = pHelmIvP\n{\n  colour = red\n"    # 13
                    "  domain = speed:0:4\n}\n")                           # 14
    assert main([str(moos)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert [int(line.split(":")[1]) for line in out] == [1, 6, 8, 9, 13, 14]


def test_unclosed_block_is_named_at_the_helms_line(tmp_path, capsys):
    bhv = tmp_path / "open.bhv"
    bhv.write_text("initialize DEPLOY = false\n\nBehavior = BHV_Waypoint\n{\n  name = w\n  points = 0,0 : 10,0\n")
    with pytest.raises(MissionFileError) as helm:
        read_bhv(bhv)
    assert helm.value.line == 6
    assert main([str(bhv)]) == 1
    assert capsys.readouterr().out.splitlines()[0] == str(helm.value)


def test_run_lines_pantler_cannot_launch_are_warnings(tmp_path, capsys, monkeypatch):
    """pAntler launches the rest and says which it cannot: a warning each, at its line; exit 0."""
    (tmp_path / "bin").mkdir()
    tool = tmp_path / "bin" / "iCppOnly"        # a C++ app on PATH is launchable
    tool.write_text("#!/bin/sh\n")
    tool.chmod(0o755)
    monkeypatch.setenv("PATH", f"{tmp_path / 'bin'}{os.pathsep}{os.environ['PATH']}")
    moos = tmp_path / "runs.moos"
    moos.write_text("ServerPort = 9000\nProcessConfig = ANTLER\n{\n"
                    "  Run = MOOSDB @ NewConsole = false\n"
                    "  Run = pHelmIvP @ NewConsole = false ~ pHelmIvP_2\n"  # 5: ours, aliased
                    "  Run = iCppOnly @ NewConsole = false\n"              # 6: on PATH
                    "  Run = pLogger\n"                                    # 7: no options at all: fine
                    "  Run = pHelmIVP @ NewConsole = false\n"              # 8: no such app
                    "  Run = pNodeReporter NewConsole = false\n"           # 9: no '@'
                    "  Run = pMarinePID ~ pid2\n}\n")                     # 10: no '@' before '~'
    assert main([str(moos)]) == 0
    out, err = capsys.readouterr()
    assert out == ""
    assert err.splitlines() == [
        f"{moos}:8: warning: cannot launch pHelmIVP: not a project app and not found on PATH (did you mean pHelmIvP?)",
        f"{moos}:9: warning: Run line has no '@': pAntler takes all of 'pNodeReporterNewConsole=false' as the "
        "program name (write Run = <app> @ NewConsole = false [~ MOOSName])",
        f"{moos}:10: warning: Run line has no '@': pAntler takes all of 'pMarinePID~pid2' as the program name "
        "(write Run = <app> @ NewConsole = false [~ MOOSName])",
        "1 file OK, 3 warnings"]


HELM_MISSION = ("ServerPort = 9000\nLatOrigin = 43.8\nLongOrigin = -70.3\nProcessConfig = pHelmIvP\n{{\n"
                "  behaviors = t.bhv\n  domain = course:0:359:360\n  domain = speed:0:4:41\n  {line}\n}}\n")


@pytest.mark.parametrize("line, helm_status, severity", [
    ("MaxAppTick = 10", "PARK", None),                   # every MOOSApp reads it
    ("pmgen = length=4, beam=1.5", "PARK", None),        # the C++ helm's platform model: accepted
    ("term_report_interval = 0.8", "PARK", "warning"),   # the C++ helm warns and drives
    ("colour = red", "MALCONFIG", "error"),              # an unknown key: the helm never drives
    ("pmgen = oops", "MALCONFIG", "error"),              # not a key=value list
])
def test_helm_parameters_have_the_helms_own_severity(tmp_path, capsys, line, helm_status, severity):
    from behaviors.helm_app import HelmIvP
    (tmp_path / "t.bhv").write_text("Behavior = BHV_Waypoint\n{\n  name = go\n  points = 0,100\n  speed = 2\n}\n")
    moos = tmp_path / "t.moos"
    moos.write_text(HELM_MISSION.format(line=line))
    app = HelmIvP(moos)
    app.on_startup()
    assert app.helm.status == helm_status
    capsys.readouterr()
    assert main([str(moos)]) == (1 if severity == "error" else 0)
    out, err = capsys.readouterr()
    key = line.split()[0]
    if severity == "error":     # the very line the helm printed when it went MALCONFIG
        assert out.splitlines() == app.helm.config_warnings and out.startswith(f"{moos}:9: ")
    elif severity == "warning":
        assert (out, err) == ("", f"{moos}:9: warning: pHelmIvP ignores '{key}' (the C++ helm only warns about it)\n"
                                  "1 file OK, 1 warning\n")
    else:
        assert (out, err) == ("", "1 file OK\n")


@pytest.mark.parametrize("block", [
    "BHV_Waypoint\n{\n  name = mow\n  points = format=lawnmower, x=0, y=-100, width=200, height=100, swath=25, rows=ew\n",
    "BHV_Waypoint\n{\n  name = bow\n  points = format=bowtie, x=0, y=-100, height=50, wid1=20, wid2=40, wid3=10\n",
    "BHV_ConstantHeading\n{\n  name = ch\n  heading = 90\n  complete_thresh = 10\n  heading_mismatch_var = HDG_DIFF\n",
    "BHV_ConstantDepth\n{\n  name = cd\n  depth = 10\n  depth_mismatch_var = DEPTH_DIFF\n",
])
def test_what_the_cpp_behaviours_accept_passes_as_our_behaviours_accept_it(tmp_path, capsys, block):
    """Issue 15's rejected-but-valid lines: judged by the behaviour itself, so they pass once it takes them."""
    bhv = tmp_path / "ok.bhv"
    bhv.write_text(f"Behavior = {block}}}\n")
    assert main([str(bhv)]) == 0
    assert capsys.readouterr() == ("", "1 file OK\n")


def test_a_parameter_the_behaviour_rejects_is_an_error(tmp_path, capsys):
    bhv = tmp_path / "bad.bhv"
    bhv.write_text("Behavior = BHV_ConstantHeading\n{\n  name = ch\n  heading = 90\n  complete_thresh = wide\n"
                   "  colour = red\n}\n")
    assert main([str(bhv)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert [line.split(":")[1] for line in out] == ["5", "6"]
    assert out[0].startswith(f"{bhv}:5: BHV_ConstantHeading 'ch': ") and "'colour'" in out[1]


def test_example_interface_and_version(capsys):
    assert main(["--example"]) == 0 and main(["-e"]) == 0
    example = capsys.readouterr().out
    assert "$ moos-lint alpha.moos alpha.bhv\n2 files OK" in example
    assert main(["--interface"]) == 0 and main(["-i"]) == 0
    assert "is not a MOOS app" in capsys.readouterr().out
    assert main(["--version"]) == 0 and main(["-v"]) == 0
    assert capsys.readouterr().out == 2 * version_page("moos-lint")
    assert version_page("moos-lint").startswith(f"moos-lint {metadata.version('oilspill-moos')} (oilspill-moos")
    with pytest.raises(SystemExit) as done:
        main([])
    assert done.value.code == 2 and "at least one FILE" in capsys.readouterr().err
