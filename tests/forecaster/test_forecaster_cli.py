"""The forecaster's command line: --help/--example/--interface and the subcommand dispatch."""
import pytest

from oilspill_moos.forecaster.__main__ import SUBCOMMANDS, main


def test_example_and_interface_describe_the_process(capsys):
    assert main(["--example"]) == 0
    example = capsys.readouterr().out
    for flag in ("--host 127.0.0.1", "--port 9100", "--model ltc-fused", "--interval 60", "--once"):
        assert flag in example
    assert main(["--interface"]) == 0
    interface = capsys.readouterr().out
    assert '"type":"boundary"' in interface and "OK <seq>" in interface


@pytest.mark.parametrize("argv", [["--help"], *([command, "--help"] for command in SUBCOMMANDS)])
def test_help_for_the_loop_and_every_subcommand(argv, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 0
    assert "usage:" in capsys.readouterr().out


def test_missing_weights_is_a_clear_error(tmp_path, capsys):
    assert main(["--once", "--weights", str(tmp_path)]) == 1
    assert "no such checkpoint" in capsys.readouterr().err
