"""The `.alog` format of pLogger: writing it as MOOS-IvP's alog tools read it, and reading it back.

Format (docs/spec/field-apps.md section 5): a `%%` header with the LOGSTART time, then one line per message,
`<rel time> <VAR> <source[:aux][@community]> <value> ` with fixed-width, left-justified columns that
grow when a field is longer, and one trailing blank. So a reader splits the first three
blank-separated tokens and takes the rest of the line as the value.

pLogger writes a string value as it is, so a value holding newlines (DB_VARSUMMARY, a multi-line
report) spans several lines: a line that does not start a new entry (its first word is no number)
continues the value of the entry above, as the file was written. (A value line that itself reads
as `<number> <word> <word>` cannot be told from a new entry; the format has no escape for it.)
"""
from __future__ import annotations

import re
import time as _time
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import BinaryIO

from .message import BINARY, DOUBLE, MOOSMsg

RULE = "%" * 59
DATATYPE_MARKING = "%% DATATYPE MARKING ON"
COLUMNS_KEPT = 4096    # AlogWriter's VAR/source columns kept (one per writer of a variable)
WRITE_BUFFER = 1 << 16   # bytes buffered per file: pLogger flushes every FLUSH_PERIOD (0.25 s), so a vessel's ~30 KB a
                         # wall second at warp 20 go in a write or two per flush, not a system call per 8 KB


class AlogFormatError(ValueError):
    """A line of an .alog file that does not follow the format; str() is `file:line: message`."""

    def __init__(self, file: Path | str, line: int, message: str):
        super().__init__(f"{file}:{line}: {message}")


def log_root_name(stem: str, when: datetime, timestamp: bool = True) -> str:
    """`LOG_ABE` -> `LOG_ABE_21_11_2026_____23_05_09`: day and month unpadded, the clock padded."""
    if not timestamp:
        return stem
    return f"{stem}_{when.day}_{when.month}_{when.year}_____{when.hour:02d}_{when.minute:02d}_{when.second:02d}"


def alog_header(shown_path: str, log_start: float, mark_data_type: bool = False) -> str:
    """The `%%` header block; LOGSTART (MOOS time, so warped) has 16 significant digits in 20 characters.

    The opening date is the wall clock, as the C library's ctime gives it.
    """
    lines = [RULE, f"%% LOG FILE:       {shown_path}", f"%% FILE OPENED ON  {_time.ctime()}",
             f"%% LOGSTART        {log_start:20.16g}"]
    if mark_data_type:
        lines.append(DATATYPE_MARKING)
    lines.append(RULE)
    return "\n".join(lines) + "\n"


# printf-style templates: half the cost of f-strings with format specs (pLogger writes every message).
TIME_COLUMN = "%-15.5f "
DOUBLE_VALUE = "%-12.*f"
LINE = TIME_COLUMN + "%s%s \n"                            # time, the VAR and source columns, value
DOUBLE_LINE = TIME_COLUMN + "%s" + DOUBLE_VALUE + " \n"   # ... with a double's value formatted in it


def format_double(value: float, precision: int = 5) -> str:
    return DOUBLE_VALUE % (precision, value)


def source_field(msg: MOOSMsg, log_aux_src: bool = False, external_community: bool = False) -> str:
    """`source`, plus `:aux` with LogAuxSrc and `@community` for a message from another community."""
    text = msg.source
    if log_aux_src and msg.source_aux:
        text += f":{msg.source_aux}"
    if external_community and msg.community:
        text += f"@{msg.community}"
    return text


def alog_columns(key: str, source: str) -> str:
    """The VAR and source columns of a line, with the blanks after them."""
    return "%-20s %-15s " % (key, source)


def format_alog_line(rel_time: float, key: str, source: str, value: str) -> str:
    return LINE % (rel_time, alog_columns(key, source), value)


@dataclass(frozen=True)
class AlogEntry:
    """One logged message. `value` is a float when the text reads as a number (or is marked D:)."""

    time: float          # seconds since LOGSTART
    key: str
    source: str
    source_aux: str
    community: str
    value: float | str
    line: int

    @property
    def is_double(self) -> bool:
        return isinstance(self.value, float)


@dataclass
class Alog:
    """A whole .alog file read into memory."""

    path: Path
    log_start: float
    entries: list[AlogEntry]

    def values(self, key: str) -> list[float | str]:
        return [e.value for e in self.entries if e.key == key]

    def keys(self) -> set[str]:
        return {e.key for e in self.entries}

    def last(self, key: str) -> AlogEntry | None:
        return next((e for e in reversed(self.entries) if e.key == key), None)


_LINE = re.compile(r"\s*(\S+)\s+(\S+)\s+(\S+)\s*(.*)", re.DOTALL)


def _number(text: str) -> float | None:
    try:
        return float(text)
    except ValueError:
        return None


def parse_alog_line(text: str, line: int = 0, path: Path | str = "<alog>", marked: bool = False) -> AlogEntry:
    """One entry (a line, or several for a multi-line value); the value is the rest after the third field,
    minus the trailing blank."""
    text = text[:-2] if text.endswith("\r\n") else text[:-1] if text.endswith("\n") else text
    match = _LINE.fullmatch(text)
    if match is None:
        raise AlogFormatError(path, line, f"expected TIME VAR SOURCE VALUE, got '{text}'")
    rel_time = _number(match.group(1))
    if rel_time is None:
        raise AlogFormatError(path, line, f"time '{match.group(1)}' is not a number")
    raw = match.group(4)
    raw = raw[:-1] if raw.endswith(" ") else raw
    who, _, community = match.group(3).partition("@")
    source, _, aux = who.partition(":")
    value: float | str = raw
    if marked and raw.startswith("D:"):
        value = _number(raw[2:])
        if value is None:
            raise AlogFormatError(path, line, f"'{raw}' is marked a double but is not a number")
    elif marked and raw.startswith("S:"):
        value = raw[2:]
    elif not marked and "\n" not in raw:
        number = _number(raw)
        value = raw if number is None else number
    return AlogEntry(rel_time, match.group(2), source, aux, community, value, line)


def _starts_entry(text: str) -> bool:
    words = text.split(maxsplit=3)
    return len(words) >= 3 and _number(words[0]) is not None


def iter_alog(path: Path | str) -> Iterator[AlogEntry | float]:
    """Stream an .alog: yields LOGSTART (a float) once it is seen, then every entry."""
    marked = False
    entry: list[str] = []       # the lines of the entry being read (more than one: a multi-line value)
    first = 0                   # its line number
    with open(path, encoding="latin-1", newline="") as stream:
        for number, text in enumerate(stream, 1):
            if entry and not text.startswith("%%") and not _starts_entry(text):
                entry.append(text)
                continue
            if entry:
                yield parse_alog_line("".join(entry), first, path, marked)
                entry = []
            if text.startswith("%%"):
                words = text.split()
                if len(words) >= 3 and words[1] == "LOGSTART":
                    try:
                        yield float(words[2])
                    except ValueError:
                        raise AlogFormatError(path, number, f"LOGSTART '{words[2]}' is not a number") from None
                marked = marked or text.startswith(DATATYPE_MARKING)
            elif text.strip():
                entry, first = [text], number
        if entry:
            yield parse_alog_line("".join(entry), first, path, marked)


def read_alog(path: Path | str) -> Alog:
    """Read a whole .alog (ours or one written by MOOS-IvP's pLogger)."""
    log_start, entries = None, []
    for item in iter_alog(path):
        if isinstance(item, float):
            log_start = item
        else:
            entries.append(item)
    if log_start is None:
        raise AlogFormatError(path, 0, "no %% LOGSTART line in the header")
    return Alog(Path(path), log_start, entries)


class AlogWriter:
    """Appends messages to one .alog (binary payloads go to the matching .blog, as pLogger does)."""

    def __init__(self, path: Path, log_start: float, *, shown_path: str | None = None, double_precision: int = 5,
                 log_aux_src: bool = False, mark_externals: bool = False, community: str = "",
                 mark_data_type: bool = False):
        self.path = Path(path)
        self.log_start = log_start
        self.double_precision = double_precision
        self.log_aux_src = log_aux_src
        self.mark_externals = mark_externals
        self.community = community
        self.mark_data_type = mark_data_type
        self._blog_path = self.path.with_suffix(".blog")
        self._blog: BinaryIO | None = None
        self._columns: dict[tuple[str, str, str, str], str] = {}
        self._stream = open(self.path, "w", encoding="latin-1", newline="\n", buffering=WRITE_BUFFER)
        self._stream.write(alog_header(shown_path or str(self.path), log_start, mark_data_type))

    def value_text(self, msg: MOOSMsg) -> str:
        data_type = msg.data_type
        if data_type == DOUBLE:
            text = DOUBLE_VALUE % (self.double_precision, msg.double)     # format_double, without the call
            return f"D:{text}" if self.mark_data_type else text
        if data_type == BINARY:
            return self._write_binary(msg.binary)
        return f"S:{msg.string}" if self.mark_data_type else msg.string

    def _write_binary(self, payload: bytes) -> str:
        if self._blog is None:
            self._blog = open(self._blog_path, "wb")
        offset = self._blog.tell()
        self._blog.write(payload)
        return f"<MOOS_BINARY>File={self._blog_path.name},Offset={offset},Bytes={len(payload)}</MOOS_BINARY>"

    def line(self, msg: MOOSMsg) -> str:
        """`format_alog_line` of the message, its VAR and source columns made once per writer (a vessel's
        pLogger writes a few thousand lines a simulated minute, nearly all from a few dozen writers)."""
        columns = self._columns.get((msg.key, msg.source, msg.source_aux, msg.community))
        if columns is None:
            columns = self._new_columns(msg)
        if msg.data_type == DOUBLE and not self.mark_data_type:     # most lines: value_text in the one template
            return DOUBLE_LINE % (msg.time - self.log_start, columns, self.double_precision, msg.double)
        return LINE % (msg.time - self.log_start, columns, self.value_text(msg))

    def _new_columns(self, msg: MOOSMsg) -> str:
        """The `VAR source ` columns of format_alog_line, kept for the next message of that writer (forgotten
        every COLUMNS_KEPT: the helm's aux, logged with LogAuxSrc, names its iteration)."""
        external = self.mark_externals and bool(msg.community) and msg.community != self.community
        columns = alog_columns(msg.key, source_field(msg, self.log_aux_src, external))
        if len(self._columns) >= COLUMNS_KEPT:
            self._columns.clear()
        self._columns[(msg.key, msg.source, msg.source_aux, msg.community)] = columns
        return columns

    def write(self, msg: MOOSMsg) -> None:
        self._stream.write(self.line(msg))

    def write_all(self, msgs: list[MOOSMsg]) -> None:
        """Several messages in one write (pLogger's mail of an AppTick)."""
        self._stream.write("".join(map(self.line, msgs)))

    def flush(self) -> None:
        self._stream.flush()
        if self._blog is not None:
            self._blog.flush()

    def close(self) -> None:
        self._stream.close()
        if self._blog is not None:
            self._blog.close()
