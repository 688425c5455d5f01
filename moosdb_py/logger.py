"""pLogger: records a community's traffic in `.alog` files that MOOS-IvP's alog tools read.

Config parsing is pure (`LoggerConfig.from_block`); the app opens `<PATH>/<root>/`, copies the
mission in as `<root>._moos`, writes each message as it arrives (AsyncLog), optionally a
synchronous `.slog` table, and an `.xlog` of what the wildcard omitted (WildCardExclusionLog).
"""
from __future__ import annotations

import logging
import math
import shutil
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from .alog import AlogWriter, alog_header, log_root_name
from .app import MOOSApp
from .config import Param, Params, read_params
from .formats import parse_bool, wild_match
from .mission import ConfigEntry, ProcessConfig

ALWAYS_OMITTED = ("MISSION_FILE",)
CMD_VAR = "PLOGGER_CMD"
FLUSH_PERIOD = 0.25   # wall seconds between flushes of the logs: lines reach the files within it
LOGGER_PARAMS = Params(
    Param("File", str, "MOOSLog", "stem of the log folder and file names"),
    Param("PATH", str, "./", "folder the log folder is made in"),
    Param("FileTimeStamp", bool, True, "append _D_M_YYYY_____hh_mm_ss to the stem"),
    Param("UTCLogDirectories", bool, False, "time stamp in UTC instead of local time"),
    Param("AsyncLog", bool, True, "write the .alog, one line per message"),
    Param("SyncLog", str, "false @ 1", "`bool @ period`: write the .slog table every period seconds"),
    Param("LogAuxSrc", bool, False, "source column is source:aux"),
    Param("MarkExternals", bool, False, "append @community to the source of foreign messages"),
    Param("MarkDataType", bool, False, "prefix values with D: or S:"),
    Param("DoublePrecision", int, 5, "decimals of logged doubles, 0 to 15"),
    Param("Log", list, [], "`VAR @ period [NOSYNC] [MONITOR]` (repeatable); MONITOR also prints each value"),
    Param("WildCardLogging", bool, False, "log every variable"),
    Param("WildCardPattern", list, [], "variable patterns the wildcard takes (default *)"),
    Param("WildCardOmitPattern", list, [], "patterns left out of the wildcard (repeatable, comma lists allowed)"),
    Param("WildCardExclusionLog", bool, False, "write omitted variables to the .xlog"),
)
log = logging.getLogger("moosdb_py.logger")


@dataclass(frozen=True)
class LogRequest:
    """`Log = VAR @ period [NOSYNC] [MONITOR]`: subscribe at `period` s; in the .slog unless NOSYNC."""

    var: str
    period: float = 0.0
    sync: bool = True
    monitor: bool = False


def parse_log_line(entry: ConfigEntry) -> LogRequest:
    var, _, rest = entry.value.partition("@")
    var = var.strip()
    words = rest.split()
    if not var or " " in var:
        raise entry.source.error(f"Log = '{entry.value}': expected Log = VAR @ period [NOSYNC] [MONITOR]")
    period = 0.0
    if words:
        try:
            period = float(words[0])
        except ValueError:
            raise entry.source.error(f"Log = '{entry.value}': period '{words[0]}' is not a number") from None
        if period < 0:
            raise entry.source.error(f"Log = '{entry.value}': the period must not be negative")
    flags = {w.upper() for w in words[1:]}
    unknown = flags - {"NOSYNC", "MONITOR"}
    if unknown:
        raise entry.source.error(f"Log = '{entry.value}': unknown flag {', '.join(sorted(unknown))}")
    return LogRequest(var, period, "NOSYNC" not in flags, "MONITOR" in flags)


def _patterns(values: list[str]) -> list[str]:
    return [p.strip() for value in values for p in value.split(",") if p.strip()]


@dataclass
class LoggerConfig:
    """Every pLogger parameter with MOOS's default."""

    file: str = "MOOSLog"
    path: str = "./"
    file_timestamp: bool = True
    async_log: bool = True
    sync_log: bool = False
    sync_period: float = 1.0
    logs: list[LogRequest] = field(default_factory=list)
    wildcard_logging: bool = False
    wildcard_patterns: list[str] = field(default_factory=lambda: ["*"])
    wildcard_omit: list[str] = field(default_factory=list)
    wildcard_exclusion_log: bool = False
    log_aux_src: bool = False
    double_precision: int = 5
    mark_externals: bool = False
    mark_data_type: bool = False
    utc_log_directories: bool = False
    unhandled: list[str] = field(default_factory=list)   # `file:line: key` of lines pLogger does not use

    @classmethod
    def from_block(cls, block: ProcessConfig | None) -> "LoggerConfig":
        config = cls()
        if block is None:
            return config
        v = read_params(block, LOGGER_PARAMS.read)
        config.file, config.path = v["file"], v["path"]
        config.file_timestamp, config.async_log = v["filetimestamp"], v["asynclog"]
        sync = block.entry("SyncLog")
        if sync is not None:
            switch, at, period = sync.value.partition("@")
            try:
                config.sync_log = parse_bool(switch)
            except ValueError as err:
                raise sync.source.error(f"SyncLog = '{sync.value}': {err}") from None
            if at:
                config.sync_period = _number(sync, period)
        config.logs = [parse_log_line(e) for e in block.entries if e.key.lower() == "log"]
        config.wildcard_logging = v["wildcardlogging"]
        config.wildcard_patterns = _patterns(v["wildcardpattern"]) or ["*"]
        config.wildcard_omit = _patterns(v["wildcardomitpattern"])
        config.wildcard_exclusion_log = v["wildcardexclusionlog"]
        config.log_aux_src, config.mark_externals = v["logauxsrc"], v["markexternals"]
        config.mark_data_type, config.utc_log_directories = v["markdatatype"], v["utclogdirectories"]
        config.double_precision = v["doubleprecision"]
        if not 0 <= config.double_precision <= 15:
            raise block.entry("DoublePrecision").source.error("DoublePrecision must be between 0 and 15")
        config.unhandled = LOGGER_PARAMS.unhandled(block)
        return config

    def omitted(self, var: str) -> bool:
        """A wildcard-logged variable that is left out (MISSION_FILE always is)."""
        return var in ALWAYS_OMITTED or any(wild_match(p, var) for p in self.wildcard_omit)

    def wanted(self, var: str) -> bool:
        """Logged: named in a Log line, or caught by the wildcard and not omitted."""
        if any(r.var == var for r in self.logs):
            return True
        return self.wildcard_logging and any(wild_match(p, var) for p in self.wildcard_patterns) and not self.omitted(var)


def _number(entry: ConfigEntry, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise entry.source.error(f"{entry.key} = '{entry.value}': '{text.strip()}' is not a number") from None
    if value < 0 or math.isnan(value):
        raise entry.source.error(f"{entry.key} = '{entry.value}' must not be negative")
    return value


class SyncLog:
    """The .slog: every period, one row with the latest value of each synchronous variable."""

    def __init__(self, path: Path, shown: str, log_start: float, variables: list[str], precision: int):
        self.variables = variables
        self.latest: dict[str, float | str] = {}
        self.precision = precision
        self.stream = open(path, "w", encoding="latin-1", newline="\n")
        header = alog_header(shown, log_start).splitlines()
        columns = [f"%%   ({i}) {name}" for i, name in enumerate(["TIME", *variables], 1)]
        labels = "%% " + " ".join(f"{name:<15}" for name in ["TIME", *variables])
        self.stream.write("\n".join([*header[:-1], *columns, header[-1], labels]) + "\n")

    def update(self, var: str, value: float | str) -> None:
        if var in self.variables:
            self.latest[var] = value

    def write_row(self, rel_time: float) -> None:
        cells = []
        for var in self.variables:
            value = self.latest.get(var, "NaN")
            cells.append(f"{value:.{self.precision}f}" if isinstance(value, float) else str(value))
        self.stream.write(f"{rel_time:<15.5f} " + " ".join(f"{c:<15}" for c in cells) + "\n")

    def close(self) -> None:
        self.stream.close()


class Logger(MOOSApp):
    """pLogger: writes every logged message to <PATH>/<root>/<root>.alog, in MOOS-IvP's alog format.

    root = File, plus `_D_M_YYYY_____hh_mm_ss` with FileTimeStamp (local time, or UTC with
    UTCLogDirectories). The mission file is copied in as <root>._moos; PLOGGER_CMD =
    COPY_FILE_REQUEST=<file> copies another file in as <root>._<ext>. Log = VAR @ period lines pick
    variables; WildCardLogging logs everything that no WildCardOmitPattern matches.
    """

    default_name = "pLogger"
    posts_iteration_load = False   # a core-MOOS app: no ITER_GAP / ITER_LEN
    parameters = LOGGER_PARAMS
    alog: AlogWriter | None = None     # files are opened in on_startup
    xlog: AlogWriter | None = None
    slog: SyncLog | None = None
    example_config = """\
ProcessConfig = pLogger
{
  AppTick   = 5          // how often the .slog row is written (files flushed every 0.25 s at most)
  CommsTick = 5

  File          = MOOSLog   // stem of the log folder and file names (default MOOSLog)
  PATH          = ./        // folder the log folder is made in (default ./)
  FileTimeStamp = true      // append _D_M_YYYY_____hh_mm_ss to the stem (default true)
  UTCLogDirectories = false // time stamp in UTC instead of local time (default false)
  AsyncLog      = true      // write the .alog, one line per message (default true)
  SyncLog       = false @ 1 // write the .slog table every period seconds (default false @ 1)
  LogAuxSrc     = false     // source column is source:aux (default false)
  MarkExternals = false     // append @community to the source of foreign messages (default false)
  MarkDataType  = false     // prefix values with D: or S: (default false)
  DoublePrecision = 5       // decimals of logged doubles (default 5)

  Log = NAV_X @ 0           // VAR @ period [NOSYNC] [MONITOR]; repeatable (default none);
                            // MONITOR also prints each value on the console
  WildCardLogging      = false  // log every variable (default false)
  WildCardPattern      = *      // variable patterns the wildcard takes (default *)
  WildCardOmitPattern  = *_STATUS  // repeatable, comma lists allowed (default none)
  WildCardExclusionLog = false  // write omitted variables to the .xlog (default false)
}
"""
    interface = """\
SUBSCRIPTIONS:
  every Log = VAR (at its period); with WildCardLogging every variable (pattern *), and PLOGGER_CMD
PUBLICATIONS:
  LOGGER_DIRECTORY   the folder being written, e.g. ./MOOSLog_21_11_2026_____23_05_09
  PLOGGER_STATUS     the app status, plus directory=, lines= (alog lines written), excluded=
"""

    def on_startup(self) -> None:
        self.settings = LoggerConfig.from_block(self.config)
        self.monitored = {r.var for r in self.settings.logs if r.monitor}
        self._wanted: dict[str, bool] = {}   # settings.wanted per variable: asked once, not for every message
        self.lines_written = 0
        self.excluded = 0
        self._open_files()

    def _open_files(self) -> None:
        settings = self.settings
        self.log_start = self.moos_time()
        now = datetime.now(timezone.utc) if settings.utc_log_directories else datetime.now()
        self.root = log_root_name(settings.file, now, settings.file_timestamp)
        self.directory = Path(settings.path) / self.root
        self.directory.mkdir(parents=True, exist_ok=True)
        shown = str(Path(settings.path) / self.root / self.root)
        writer_options = dict(double_precision=settings.double_precision, log_aux_src=settings.log_aux_src,
                              mark_externals=settings.mark_externals, community=self._community(),
                              mark_data_type=settings.mark_data_type)
        self.alog = AlogWriter(self.directory / f"{self.root}.alog", self.log_start, shown_path=shown + ".alog",
                               **writer_options) if settings.async_log else None
        self.xlog = AlogWriter(self.directory / f"{self.root}.xlog", self.log_start, shown_path=shown + ".xlog",
                               **writer_options) if settings.wildcard_exclusion_log and settings.wildcard_logging else None
        sync_vars = [r.var for r in settings.logs if r.sync]
        self.slog = SyncLog(self.directory / f"{self.root}.slog", shown + ".slog", self.log_start, sync_vars,
                            settings.double_precision) if settings.sync_log else None
        self._next_sync = self.log_start
        self._next_flush = 0.0
        if self.mission is not None:
            shutil.copyfile(self.mission.path, self.directory / f"{self.root}._moos")

    def _community(self) -> str:
        return self.mission.community if self.mission is not None else ""

    def on_connect(self) -> None:
        for request in self.settings.logs:
            self.register(request.var, request.period)
        if self.settings.wildcard_logging:
            for pattern in self.settings.wildcard_patterns:
                self.register_wildcard(pattern, "*", 0.0)
        self.register(CMD_VAR)
        self.notify("LOGGER_DIRECTORY", str(self.directory))

    def on_new_mail(self, mail) -> None:
        logged, excluded, wanted_of = [], [], self._wanted
        for msg in mail:
            key = msg.key
            if key == CMD_VAR and msg.is_string():
                self._command(msg.string)
            if key in self.monitored:
                print(f"{self.name}: {key} = {msg.value!r} (from {msg.source})", flush=True)
            wanted = wanted_of.get(key)
            if wanted is None:
                wanted = wanted_of[key] = self.settings.wanted(key)
            (logged if wanted else excluded).append(msg)
        if self.alog is not None and logged:
            self.alog.write_all(logged)
            self.lines_written += len(logged)
        if self.slog is not None:
            for msg in logged:
                if not msg.is_binary():
                    self.slog.update(msg.key, msg.value)
        if self.xlog is not None and excluded:
            self.xlog.write_all(excluded)
            self.excluded += len(excluded)

    def _command(self, text: str) -> None:
        name, _, value = text.partition("=")
        if name.strip().upper() != "COPY_FILE_REQUEST":
            return
        source = Path(value.strip())
        try:
            shutil.copyfile(source, self.directory / f"{self.root}._{source.suffix.lstrip('.') or 'file'}")
        except OSError as exc:
            self.notify("PLOGGER_WARNING", f"COPY_FILE_REQUEST {source}: {exc.strerror}")

    def iterate(self) -> None:
        now = self.moos_time()
        if self.slog is not None and now >= self._next_sync:
            self.slog.write_row(now - self.log_start)
            self._next_sync = now + self.settings.sync_period
        mono = time.monotonic()
        if mono >= self._next_flush:    # at warp 10 an AppTick of 8 would flush 80 times a second
            self._next_flush = mono + FLUSH_PERIOD
            for writer in (self.alog, self.xlog):
                if writer is not None:
                    writer.flush()
            if self.slog is not None:
                self.slog.stream.flush()

    async def run_async(self) -> None:
        try:
            await super().run_async()
        finally:
            for writer in (self.alog, self.xlog, self.slog):
                if writer is not None:
                    writer.close()

    def status_fields(self) -> dict:
        return {"directory": str(self.directory), "lines": self.lines_written, "excluded": self.excluded}


main = Logger.main
