"""The forecaster's command line: --help/--example/--interface and the subcommand dispatch."""
import pytest

from oilspill_moos.forecaster.__main__ import SUBCOMMANDS, main
from oilspill_moos.forecaster.kinds import DEFAULT_MODEL


def test_example_and_interface_describe_the_process(capsys):
    assert main(["--example"]) == 0
    example = capsys.readouterr().out
    for flag in ("--host 127.0.0.1", "--port 9100", f"--model {DEFAULT_MODEL}", "--interval 60", "--once"):
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


# ---------------------------------------------------------------------------------------------------
# Forcing files, watched folders, rejections

import asyncio
import json
import subprocess
import sys
from datetime import datetime, timedelta

from shapely.geometry import Point, mapping

from oilspill_moos.forecaster import operational
from oilspill_moos.forecaster.features import to_lonlat

T0 = datetime(2020, 6, 1, 6, 0)        # naive: UTC


def write_slick(path, hour: float, x_m: float = 0.0):
    geometry = to_lonlat(Point(x_m, 0).buffer(2_000 + 100 * hour))
    path.write_text(json.dumps({"type": "FeatureCollection", "features": [{
        "type": "Feature", "geometry": mapping(geometry),
        "properties": {"time": (T0 + timedelta(hours=hour)).isoformat()}}]}))
    return path


def write_forcing(path):
    rows = ["time,wind_u,wind_v,current_u,current_v"]
    rows += [f"{(T0 + timedelta(hours=h)).isoformat()},6.0,0.0,0.2,0.0" for h in range(0, 20)]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_example_names_the_default_model(capsys):
    assert main(["--example"]) == 0
    assert f"--model {DEFAULT_MODEL}" in capsys.readouterr().out


def test_forecast_command_takes_forcing_and_the_model_kind(tmp_path, capsys):
    files = [write_slick(tmp_path / f"s{h}.geojson", h, 720.0 * h) for h in (0, 1, 2)]
    forcing = write_forcing(tmp_path / "forcing.csv")
    assert main(["forecast", *map(str, files), "--model", "physics", "--forcing", str(forcing)]) == 0
    lines = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [line["horizon_h"] for line in lines] == [3, 7, 11, 15] and {line["source"] for line in lines} == {"physics"}
    # 0.2 m/s current + 3 % of 6 m/s wind = 0.38 m/s east: 15 h later the slick is ~20 km east
    lon_15 = sum(p[0] for p in lines[-1]["polygon"]) / len(lines[-1]["polygon"])
    lon_3 = sum(p[0] for p in lines[0]["polygon"]) / len(lines[0]["polygon"])
    assert lon_15 - lon_3 == pytest.approx(0.38 * 12 * 3600 / (111_320 * 0.876), rel=0.15)


def test_bad_forcing_file_is_a_clear_error_naming_the_line(tmp_path, capsys):
    files = [write_slick(tmp_path / f"s{h}.geojson", h) for h in (0, 1)]
    bad = tmp_path / "forcing.csv"
    bad.write_text("time,wind_u,wind_v,current_u,current_v\n2020-06-01T06:00,1,2,3,4\n2020-06-01T07:00,1,x,3,4\n")
    assert main(["forecast", *map(str, files), "--model", "physics", "--forcing", str(bad)]) == 1
    err = capsys.readouterr().err
    assert f"{bad}: line 3: wind and current must be numbers" in err and "Traceback" not in err


async def _capture(reply: bytes, run_args):
    received = []

    async def handle(reader, writer):
        while line := await reader.readline():
            received.append(json.loads(line))
            writer.write(reply)
            await writer.drain()
        writer.close()

    server = await asyncio.start_server(handle, "127.0.0.1", 0)
    async with server:
        port = str(server.sockets[0].getsockname()[1])
        code = await asyncio.to_thread(operational.main, [*run_args, "--port", port])
    return code, received


def test_watched_folder_skips_a_bad_file_with_a_warning_naming_it(tmp_path, capsys):
    folder = tmp_path / "obs"
    folder.mkdir()
    for h in (0, 1, 2):
        write_slick(folder / f"s{h}.geojson", h, 500.0 * h)
    (folder / "broken.geojson").write_text("{not json")
    forcing = write_forcing(tmp_path / "f.csv")
    code, received = asyncio.run(_capture(b"OK 1\n", ["--once", "--observations", str(folder), "--model", "physics",
                                                      "--forcing", str(forcing)]))
    assert code == 0 and len(received) == 4
    out = capsys.readouterr().out
    assert "skipped" in out and "broken.geojson" in out


def test_every_horizon_rejected_is_a_non_zero_exit(tmp_path, capsys):
    folder = tmp_path / "obs"
    folder.mkdir()
    for h in (0, 1):
        write_slick(folder / f"s{h}.geojson", h)
    code, received = asyncio.run(_capture(b"ERR polygon too small\n", ["--once", "--observations", str(folder),
                                                                       "--model", "persistence"]))
    assert code == 1 and len(received) == 4
    assert "rejected every horizon" in capsys.readouterr().err


def test_help_does_not_import_torch():
    """`--help` must answer fast: torch (seconds to import) is loaded only for the learned kinds."""
    probe = ("import sys, contextlib, io\n"
             "from oilspill_moos.forecaster.__main__ import main\n"
             "with contextlib.redirect_stdout(io.StringIO()):\n"
             "    try:\n        main(['--help'])\n    except SystemExit:\n        pass\n"
             "print('torch' in sys.modules)\n")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60)
    assert result.stdout.strip() == "False", result.stderr
