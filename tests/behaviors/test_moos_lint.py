import os
import subprocess
import sys

import pytest

from behaviors.lint import main


def test_corpus_passes_from_each_folder(corpus, monkeypatch, capsys):
    files = sorted(corpus.glob("*/*.moos")) + sorted(corpus.glob("*/*.bhv"))
    for f in files:
        monkeypatch.chdir(f.parent)
        assert main([f.name]) == 0, f
    assert capsys.readouterr().out == ""


def test_problems_are_file_line_messages(tmp_path, capsys):
    bhv = tmp_path / "bad.bhv"
    bhv.write_text("Behavior = BHV_Waypoint\n{\n  name = w\n  speed = fast\n  capture_radius = -1\n"
                   "  points = $(START)\n}\n")
    moos = tmp_path / "bad.moos"
    moos.write_text("ServerPort = 90x\nProcessConfig = pHelmIvP\n{\n  domain = speed:0:4\n}\n")
    assert main([str(bhv), str(moos)]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0] == f"{bhv}:4: BHV_Waypoint 'w': speed must be a number >= 0, got 'fast'"
    assert out[1].startswith(f"{bhv}:5: ")
    assert out[2].startswith(f"{moos}:1: ")
    assert out[3].startswith(f"{moos}:4: domain 'speed:0:4'")
    assert len(out) == 4


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
    assert len(lines) == 2 and lines[0] == f"{moos}:2: warning: ignored line outside any block: stray words"
    assert lines[1].startswith(f"{moos}:6: warning: second block for a is ignored")
