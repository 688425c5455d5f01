"""pLogger: configuration, and a real logger against a real moosdb whose .alog is read back."""
import asyncio

import pytest

from helpers import async_wait_until
from moosdb_py.alog import read_alog
from moosdb_py.client import MOOSClient
from moosdb_py.logger import Logger, LoggerConfig, LogRequest
from moosdb_py.mission import read_mission
from moosdb_py.source import MissionFileError


def block(tmp_path, body):
    path = tmp_path / "m.moos"
    path.write_text(f"ProcessConfig = pLogger\n{{\n{body}\n}}\n")
    return read_mission(path).process_config("pLogger")


def test_defaults():
    config = LoggerConfig.from_block(None)
    assert (config.file, config.path, config.file_timestamp, config.async_log, config.sync_log) == \
        ("MOOSLog", "./", True, True, False)
    assert (config.wildcard_logging, config.log_aux_src, config.double_precision) == (False, False, 5)


def test_config_lines(tmp_path):
    config = LoggerConfig.from_block(block(tmp_path, """
  File = LOG_ABE
  PATH = logs
  FileTimeStamp = false
  SyncLog = true @ 0.5
  Log = NAV_X @ 0
  Log = IVPHELM_LIFE_EVENT @ 0 nosync
  Log = NAV_Y @ 2.5 NOSYNC MONITOR
  WildCardLogging = true
  WildCardOmitPattern = *_STATUS
  WildCardOmitPattern = NAV_PITCH, NAV_YAW
  LogAuxSrc = TRUE
  AppTick = 4
  Colour = blue
  DoublePrecision = 3"""))
    assert (config.file, config.path, config.file_timestamp, config.sync_log, config.sync_period) == \
        ("LOG_ABE", "logs", False, True, 0.5)
    assert config.logs == [LogRequest("NAV_X", 0.0, True, False), LogRequest("IVPHELM_LIFE_EVENT", 0.0, False, False),
                           LogRequest("NAV_Y", 2.5, False, True)]
    assert config.wildcard_omit == ["*_STATUS", "NAV_PITCH", "NAV_YAW"] and config.log_aux_src
    assert config.double_precision == 3
    assert config.unhandled == [f"{tmp_path / 'm.moos'}:16: unhandled parameter 'Colour'"]
    assert config.wanted("NAV_X") and config.wanted("DEPLOY")
    assert not config.wanted("PHELMIVP_STATUS") and not config.wanted("NAV_YAW") and not config.wanted("MISSION_FILE")


@pytest.mark.parametrize("line,message", [
    ("Log = NAV_X @ soon", r"m.moos:3: Log = 'NAV_X @ soon': period 'soon' is not a number"),
    ("Log = @ 0", r"m.moos:3: Log = '@ 0': expected Log = VAR @ period"),
    ("Log = NAV_X @ 0 NOSINK", r"m.moos:3: .*unknown flag NOSINK"),
    ("SyncLog = true @ -1", r"m.moos:3: SyncLog = 'true @ -1' must not be negative"),
    ("DoublePrecision = 40", r"m.moos:3: DoublePrecision must be between 0 and 15"),
])
def test_bad_config_names_the_line(tmp_path, line, message):
    with pytest.raises(MissionFileError, match=message):
        LoggerConfig.from_block(block(tmp_path, line))


def test_logs_a_real_community(tmp_path, moosdb_server):
    mission = tmp_path / "log.moos"
    mission.write_text(f"""ServerHost = {moosdb_server.host}
ServerPort = {moosdb_server.port}
Community = logtest
MOOSTimeWarp = 4
ProcessConfig = pLogger
{{
  AppTick = 20
  File = LOG_T
  PATH = {tmp_path / "logs"}
  SyncLog = true @ 0.2
  Log = NAV_X @ 0
  LogAuxSrc = true
  WildCardLogging = true
  WildCardOmitPattern = *_STATUS, NOISE
  WildCardExclusionLog = true
}}
""")

    async def scenario():
        logger = Logger(mission)
        running = asyncio.create_task(logger.run_async())
        seen = []
        poker = MOOSClient("poker", moosdb_server.host, moosdb_server.port, time_warp=4,
                           on_mail=seen.extend, on_connect=lambda: poker.register("LOGGER_DIRECTORY"))
        comms = asyncio.create_task(poker.run())
        # LOGGER_DIRECTORY is posted after the logger's registrations, so once it is seen they hold
        await async_wait_until(lambda: any(m.key == "LOGGER_DIRECTORY" for m in seen), timeout=10)
        for x in (1.0, 2.5):
            poker.notify("NAV_X", x)
        poker.notify("DEPLOY", "true", source_aux="button")
        poker.notify("NOISE", "omit me")
        poker.notify("POKER_STATUS", "omit me too")
        poker.notify("BLOB", b"\x01\x02")
        await async_wait_until(lambda: logger.lines_written >= 5 and logger.excluded >= 2, timeout=10)
        logger.stop()
        poker.close()
        await asyncio.wait_for(asyncio.gather(running, comms), 10)
        return logger

    logger = asyncio.run(scenario())
    folder = tmp_path / "logs"
    (root,) = [p for p in folder.iterdir()]
    assert root.name.startswith("LOG_T_") and root == logger.directory
    log = read_alog(root / f"{root.name}.alog")
    assert log.values("NAV_X") == [1.0, 2.5]
    deploy = log.last("DEPLOY")
    assert (deploy.value, deploy.source, deploy.source_aux) == ("true", "poker", "button")
    assert "NOISE" not in log.keys() and "POKER_STATUS" not in log.keys() and "MISSION_FILE" not in log.keys()
    assert log.last("BLOB").value.startswith(f"<MOOS_BINARY>File={root.name}.blog,Offset=0,Bytes=2")
    ours = [e for e in log.entries if e.source in ("poker", "pLogger")]
    assert ours and all(0 <= e.time < 60 for e in ours)   # relative to LOGSTART, both in warped MOOS time
    assert {"NOISE", "POKER_STATUS"} <= read_alog(root / f"{root.name}.xlog").keys()
    assert (root / f"{root.name}._moos").read_text() == mission.read_text()
    slog = (root / f"{root.name}.slog").read_text().splitlines()
    assert "%%   (2) NAV_X" in slog and slog[-1].split()[1] in ("NaN", "1.00000", "2.50000")
