"""Reading `.moos` mission files into typed structures (spec: docs/spec/mission-files.md section 1).

The file always goes through `nsplug.preprocess` first (a plain .moos passes through unchanged), so
every entry keeps the template file and line it came from.

Two views of each value, because MOOS itself has two readers: `ConfigEntry.value` keeps inner
blanks and file order (the friendly view apps use through `ProcessConfig.get`), and
`ConfigEntry.moos_value` is what MOOS's blank-deleting reader hands to IvP apps
(`points = 60,-40 : 60,-160` -> `60,-40:60,-160`). Global lookups are the MOOS ones: blanks
removed, case-insensitive, and the first matching line anywhere in the file wins (spec 1.2 QUIRK).
"""
from __future__ import annotations

import os
import re
from pathlib import Path

from pydantic import BaseModel, Field, PrivateAttr

from .formats import FormatError, parse_bool, parse_pairs
from .nsplug import preprocess
from .source import MissionFileError, SourceLine

MAX_LINE = 1999
DEFAULT_MS_BETWEEN_LAUNCHES = 1000
_BLANKS = re.compile(r"[ \t]+")
_DOLLAR_BRACE = re.compile(r"\$\{([^{}]+)\}")


def _no_blanks(text: str) -> str:
    return _BLANKS.sub("", text)


class Where(BaseModel):
    """The template file and line an entry came from."""

    file: Path
    line: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}"

    def error(self, message: str) -> MissionFileError:
        return MissionFileError(self.file, self.line, message)


class ConfigEntry(BaseModel):
    """One `key = value` line, split at the first `=`, both sides trimmed, comments removed."""

    key: str
    value: str
    source: Where

    @property
    def moos_value(self) -> str:
        """The value as MOOS's space-deleting reader gives it: no blanks, no double quotes."""
        return _no_blanks(self.value).replace('"', "")


class ProcessConfig(BaseModel):
    """One `ProcessConfig = NAME { ... }` block, entries in file order."""

    name: str
    entries: list[ConfigEntry] = Field(default_factory=list)
    source: Where

    def get(self, key: str, default: str | None = None) -> str | None:
        """Case-insensitive; the last line wins (MOOS apps apply repeated keys in turn)."""
        values = self.get_all(key)
        return values[-1] if values else default

    def get_all(self, key: str) -> list[str]:
        """Every value of a repeatable key (`Run`, `Log`, `bridge`, ...), in file order."""
        return [e.value for e in self.entries if e.key.lower() == key.lower()]

    def entry(self, key: str) -> ConfigEntry | None:
        """The last entry for `key`, to name its file:line in an error about its value."""
        found = [e for e in self.entries if e.key.lower() == key.lower()]
        return found[-1] if found else None


class AntlerRun(BaseModel):
    """One `Run = <exe> [@ options] [~ MOOSName]` line of the Antler block."""

    exe: str
    moos_name: str
    options: dict[str, str] = Field(default_factory=dict)   # keys lower-cased
    extra_params: list[str] = Field(default_factory=list)   # from ExtraProcessParams = <Key>
    source: Where

    @property
    def new_console(self) -> bool:
        return self._option_bool("newconsole")

    @property
    def inhibit_moos_params(self) -> bool:
        return self._option_bool("inhibitmoosparams")

    def _option_bool(self, key: str) -> bool:
        try:
            return parse_bool(self.options.get(key, "false"))
        except ValueError as err:
            raise self.source.error(f"Run = {self.exe}: {key}: {err}") from None

    @property
    def path(self) -> str | None:
        """Per-process override of ExecutablePath (None: use the block's)."""
        return self.options.get("path")


class AntlerConfig(BaseModel):
    """The `ProcessConfig = ANTLER` block: what pAntler launches, in order."""

    ms_between_launches: float = DEFAULT_MS_BETWEEN_LAUNCHES
    executable_path: str | None = None   # None: SYSTEMPATH, look on PATH
    runs: list[AntlerRun] = Field(default_factory=list)


class Mission(BaseModel):
    """A read `.moos` file: globals, ProcessConfig blocks in file order, and the Antler block."""

    path: Path
    globals: dict[str, str] = Field(default_factory=dict)   # top-level `key = value` (first per name, blanks removed)
    blocks: list[ProcessConfig] = Field(default_factory=list)
    antler: AntlerConfig | None = None
    warnings: list[str] = Field(default_factory=list)        # `file:line: message`
    _entries: list[ConfigEntry] = PrivateAttr(default_factory=list)   # every entry, file order

    def get_global(self, name: str, default: str | None = None) -> str | None:
        """MOOS global lookup: first line anywhere (blocks included) whose key matches, blanks removed."""
        entry = self._global_entry(name)
        return default if entry is None else entry.moos_value

    def _global_entry(self, name: str) -> ConfigEntry | None:
        wanted = name.lower()
        return next((e for e in self._entries if _no_blanks(e.key).lower() == wanted), None)

    def process_config(self, name: str) -> ProcessConfig | None:
        """The block for an app's MOOS name (case-insensitive, blanks ignored; first block wins)."""
        wanted = _no_blanks(name).lower()
        return next((b for b in self.blocks if _no_blanks(b.name).lower() == wanted), None)

    def _typed_global(self, name: str, default, convert, what: str):
        entry = self._global_entry(name)
        if entry is None:
            return default
        try:
            return convert(entry.moos_value)
        except ValueError:
            hint = " (unexpanded nsplug macro: give it with --nsplug/-D)" if "$(" in entry.value or "%(" in entry.value else ""
            raise entry.source.error(f"{entry.key} = '{entry.value}' is not {what}{hint}") from None

    @property
    def server_host(self) -> str:
        return self.get_global("ServerHost", "localhost")

    @property
    def server_port(self) -> int:
        return self._typed_global("ServerPort", 9000, _port, "a TCP port number")

    @property
    def community(self) -> str:
        return self.get_global("Community", "#1")

    @property
    def time_warp(self) -> float:
        return self._typed_global("MOOSTimeWarp", 1.0, _positive_float, "a positive number")

    @property
    def lat_origin(self) -> float | None:
        return self._typed_global("LatOrigin", None, float, "a latitude")

    @property
    def long_origin(self) -> float | None:
        return self._typed_global("LongOrigin", None, float, "a longitude")

    def check(self) -> None:
        """Raise MissionFileError on the first global that does not convert (moos-lint, pAntler)."""
        for name in ("server_port", "time_warp", "lat_origin", "long_origin"):
            getattr(self, name)


def db_address(mission: Mission | None, host: str | None = None, port: int | None = None,
               time_warp: float | None = None) -> tuple[str, int, float]:
    """(host, port, time warp) of the MOOSDB: the command line over the mission's globals over MOOS's defaults."""
    if mission is None:
        return host or "localhost", port or 9000, time_warp or 1.0
    return host or mission.server_host, port or mission.server_port, time_warp or mission.time_warp


def add_db_arguments(parser, warp_help: str) -> None:
    """The command-line options `db_address` takes (MOOS's uXMS/uPokeDB names first, then the short ones)."""
    parser.add_argument("--serverhost", "--host", "--moos_host", dest="host",
                        help="MOOSDB host (default: mission or localhost)")
    parser.add_argument("--serverport", "--port", "--moos_port", dest="port", type=int,
                        help="MOOSDB port (default: mission or 9000)")
    parser.add_argument("--moos_time_warp", "--warp", dest="time_warp", type=float, help=warp_help)


def _port(value: str) -> int:
    port = int(value)
    if not 0 < port < 65536:
        raise ValueError(value)
    return port


def _positive_float(value: str) -> float:
    number = float(value)
    if not number > 0:
        raise ValueError(value)
    return number


def strip_comment(text: str) -> str:
    """Cut `// ...` unless the `//` sits between a pair of double quotes (MOOS verbatim quoting)."""
    if text.count('"') >= 2:
        out, quoted = [], False
        for i, char in enumerate(text):
            if char == '"':
                quoted = not quoted
            elif not quoted and text.startswith("//", i):
                break
            out.append(char)
        return "".join(out)
    cut = text.find("//")
    return text if cut < 0 else text[:cut]


def read_mission(path, defines: dict[str, str | None] | None = None, include_paths=()) -> Mission:
    """Preprocess (nsplug) and parse a `.moos` file. Raises MissionFileError naming file:line."""
    lines = preprocess(path, defines, include_paths)
    return parse_mission(Path(path), lines)


def parse_mission(path: Path, lines: list[SourceLine]) -> Mission:
    """Parse already preprocessed lines (the grammar of spec 1.1-1.4)."""
    lines = _substitute_defines(lines)
    mission = Mission(path=path)
    block: ProcessConfig | None = None
    pending: ProcessConfig | None = None        # header read, waiting for its `{`
    for src in lines:
        if len(src.text) > MAX_LINE:
            raise MissionFileError.at(src, f"line longer than {MAX_LINE} characters (MOOS stops reading here)")
        text = strip_comment(src.text.strip()).strip()
        if not text or text.lower().startswith("define:"):
            continue
        where = Where(file=src.file, line=src.line)
        header = _header_name(text)
        if header is not None:
            if block is not None:
                raise MissionFileError.at(src, f"ProcessConfig = {header} inside block {block.name} "
                                               f"opened at {block.source} (missing '}}'?)")
            if pending is not None:
                raise pending.source.error(f"ProcessConfig = {pending.name} is not followed by '{{'")
            if not header:
                raise MissionFileError.at(src, "ProcessConfig needs a process name")
            if header.endswith("{"):
                raise MissionFileError.at(src, "'{' must be on its own line after the ProcessConfig header")
            pending = ProcessConfig(name=header, source=where)
        elif pending is not None:
            if not text.startswith("{"):
                raise pending.source.error(f"ProcessConfig = {pending.name} is not followed by '{{' "
                                           f"(found '{text}' at line {src.line})")
            if text[1:].strip():
                mission.warnings.append(f"{where}: text after '{{' is ignored: {text[1:].strip()}")
            block, pending = pending, None
        elif block is not None:
            if text.startswith("}"):
                _close_block(mission, block)
                block = None
            elif text.startswith("{"):
                mission.warnings.append(f"{where}: stray '{{' inside block {block.name or '(no header)'} is ignored")
            else:
                entry = _entry(text, where)
                if entry is not None:
                    block.entries.append(entry)
                    mission._entries.append(entry)
        elif text.startswith("{"):
            # MOOS skips a block whose header is missing or commented out; so do we, with a warning
            block = ProcessConfig(name="", source=where)
        elif text.startswith("}"):
            mission.warnings.append(f"{where}: stray '}}' outside any block is ignored")
        else:
            entry = _entry(text, where)
            if entry is None or not entry.key:
                mission.warnings.append(f"{where}: ignored line outside any block: {text}")
            else:
                mission._entries.append(entry)
                key = _no_blanks(entry.key)
                if not any(k.lower() == key.lower() for k in mission.globals):
                    mission.globals[key] = entry.moos_value
    if block is not None:
        raise block.source.error(f"block {block.name or '(no header)'} is never closed with '}}'")
    if pending is not None:
        raise pending.source.error(f"ProcessConfig = {pending.name} is not followed by '{{'")
    return mission


def _header_name(text: str) -> str | None:
    squeezed = _no_blanks(text)
    if squeezed.lower().startswith("processconfig="):
        return squeezed[len("processconfig="):]
    return None


def _entry(text: str, where: Where) -> ConfigEntry | None:
    """Split at the first `=`; an empty value drops the line unless it holds `[` or `]` (spec 1.3)."""
    key, sep, value = text.partition("=")
    key, value = key.strip(), value.strip()
    if not value and "[" not in text and "]" not in text:
        return None
    return ConfigEntry(key=key if sep else text, value=value, source=where)


def _close_block(mission: Mission, block: ProcessConfig) -> None:
    if not block.name:
        mission.warnings.append(f"{block.source}: block without a ProcessConfig header (commented out?) is ignored")
        return
    if mission.process_config(block.name) is not None:
        first = mission.process_config(block.name)
        mission.warnings.append(f"{block.source}: second block for {block.name} is ignored "
                                f"(MOOS uses the first, at {first.source})")
    mission.blocks.append(block)
    if _no_blanks(block.name).upper() == "ANTLER" and mission.antler is None:
        mission.antler = parse_antler(block)


def parse_antler(block: ProcessConfig) -> AntlerConfig:
    """The Antler block's launch list (spec 1.4). A malformed `Run` line is an error at its line."""
    config = AntlerConfig()
    entry = block.entry("MSBetweenLaunches")
    if entry is not None:
        try:
            config.ms_between_launches = float(entry.moos_value)
        except ValueError:
            raise entry.source.error(f"MSBetweenLaunches = '{entry.value}' is not a number of milliseconds") from None
        if config.ms_between_launches < 0:
            raise entry.source.error("MSBetweenLaunches must not be negative")
    path = block.get("ExecutablePath")
    if path is not None and _no_blanks(path).upper() not in ("SYSTEMPATH", "SYSTEM"):
        config.executable_path = _no_blanks(path)
    for line in (e for e in block.entries if e.key.lower() == "run"):
        config.runs.append(_run_line(block, line))
    return config


def _run_line(block: ProcessConfig, line: ConfigEntry) -> AntlerRun:
    text = line.moos_value
    head, tilde, alias = text.partition("~")
    exe, at, options_text = head.partition("@")
    if not exe:
        raise line.source.error(f"Run line without a program name: 'Run = {line.value}'")
    if tilde and not alias:
        raise line.source.error(f"Run line with '~' but no MOOS name after it: 'Run = {line.value}'")
    if "@" in options_text or "~" in alias or "@" in alias:
        raise line.source.error(f"Run line has '@' or '~' in the wrong place: 'Run = {line.value}' "
                                "(expected Run = <exe> [@ key=value, ...] [~ MOOSName])")
    try:
        options = parse_pairs(options_text)
    except FormatError as err:
        raise line.source.error(f"Run option {err}: 'Run = {line.value}'") from None
    extra: list[str] = []
    if "extraprocessparams" in options:
        params = block.get(options["extraprocessparams"])
        if params is None:
            raise line.source.error(f"ExtraProcessParams = {options['extraprocessparams']} but the Antler block "
                                    f"has no '{options['extraprocessparams']} = ...' line")
        extra = [p for p in _no_blanks(params).split(",") if p]
    return AntlerRun(exe=exe, moos_name=alias or Path(exe).name, options=options, extra_params=extra,
                     source=line.source)


def _substitute_defines(lines: list[SourceLine]) -> list[SourceLine]:
    """MOOS's own `${NAME}`: from a `define: NAME = value` line anywhere in the file, else the environment."""
    table: dict[str, str] = {}
    for src in lines:
        text = strip_comment(src.text.strip())
        if text.lower().startswith("define:"):
            name, _, value = text[len("define:"):].partition("=")
            table[name.strip()] = value.strip()

    def lookup(match: re.Match) -> str:
        name = match.group(1)
        return table.get(name, os.environ.get(name, match.group(0)))

    return [SourceLine(_DOLLAR_BRACE.sub(lookup, s.text), s.file, s.line) if "${" in s.text else s for s in lines]
