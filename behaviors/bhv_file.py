"""The `.bhv` helm behaviour file: initialize lines, `set` mode entries and Behavior blocks.

The parser follows the reference state machine (spec: docs/spec/mission-files.md §2.1-2.5) and turns the
file into validated pydantic structures; every problem is a MissionFileError naming file:line.
"""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Union

from pydantic import BaseModel, ConfigDict

from moosdb_py.source import MissionFileError, SourceLine

from .behavior import InfoBuffer, IvPBehavior, flag_param
from .domain import IvPDomain
from .flags import FLAG_KINDS
from .logic import ConditionError, Relation, as_number, parse_mode_condition
from .registry import PluginError, behavior_class

Value = Union[float, str]
_NAME_OK = re.compile(r"^[A-Za-z0-9_\-\[\]()#@+]+$")
# General lines checked as the file is read (the rest when the helm builds the behaviour).
CHECKED_AT_PARSE = {"condition", "pwt", "priority", "priwt", "duration", "perpetual", "spawnx_flag", "cycleflag",
                    "wptflag", *FLAG_KINDS}


class BhvParam(BaseModel):
    """One `param = value` line of a Behavior block (param lower-cased, value trimmed)."""

    key: str
    value: str
    file: Path
    line: int

    def error(self, message: str) -> MissionFileError:
        return MissionFileError(self.file, self.line, message)


class InitEntry(BaseModel):
    var: str
    value: Value
    deferred: bool = False
    file: Path
    line: int


class ModeEntry(BaseModel):
    """`set VAR = VALUE { conditions } ELSEVALUE`; `prefix` comes from a `VAR = X` condition."""

    model_config = ConfigDict(arbitrary_types_allowed=True)
    var: str
    value: str
    conditions: list[Any] = []
    else_value: str = ""
    prefix: str = ""
    mode_var_conditions: list[Any] = []
    file: Path
    line: int


class BehaviorSpec(BaseModel):
    """A Behavior block: its type and its config lines in file order."""

    type: str
    params: list[BhvParam] = []
    file: Path
    line: int

    def get(self, key: str, default: str | None = None) -> str | None:
        found = [p.value for p in self.params if p.key == key.lower()]
        return found[-1] if found else default

    def get_all(self, key: str) -> list[str]:
        return [p.value for p in self.params if p.key == key.lower()]

    @property
    def name(self) -> str:
        """The `name` line, else the type's default name (two unnamed ones of a type clash)."""
        given = self.get("name") or self.get("descriptor")
        if given:
            return given
        try:
            cls = behavior_class(self.type)
        except PluginError:
            cls = None     # reported where the helm builds it
        return cls.default_name if cls else self.type.lower()

    @property
    def templating(self) -> str:
        return (self.get("templating") or "").lower()


class BhvFile(BaseModel):
    path: Path
    initializes: list[InitEntry] = []
    modes: list[ModeEntry] = []
    behaviors: list[BehaviorSpec] = []

    def behavior(self, name: str) -> BehaviorSpec | None:
        return next((b for b in self.behaviors if b.name == name), None)


def _logical_lines(lines: list[SourceLine]) -> list[SourceLine]:
    """Join backslash continuations; keep the first line's position."""
    out: list[SourceLine] = []
    pending: SourceLine | None = None
    for src in lines:
        text = src.text.rstrip("\r\n")
        if pending is not None:
            src = SourceLine(pending.text + text, pending.file, pending.line)
            text = src.text
            pending = None
        if text.rstrip().endswith("\\"):
            pending = SourceLine(text.rstrip()[:-1], src.file, src.line)
            continue
        out.append(SourceLine(text, src.file, src.line))
    if pending is not None:
        out.append(pending)
    return out


def _pieces(src: SourceLine) -> list[SourceLine]:
    """Trim, drop comments, and split a leading/trailing `{` and a leading `}` off the text."""
    text = src.text.strip()
    if text.startswith("//") or text.startswith("#"):
        return [SourceLine("", src.file, src.line)]
    if "//" in text:
        text = text[:text.index("//")].rstrip()
    out: list[str] = []
    if len(text) > 1 and text[0] in "{}":
        out.append(text[0])
        text = text[1:].strip()
    trailing_brace = len(text) > 1 and text.endswith("{")
    if trailing_brace:
        text = text[:-1].rstrip()
    out.append(text)
    if trailing_brace:
        out.append("{")
    return [SourceLine(t, src.file, src.line) for t in out]


def _init_entries(src: SourceLine, rest: str, deferred: bool) -> list[InitEntry]:
    items, buf, quoted = [], "", False
    for ch in rest:
        if ch == '"':
            quoted = not quoted
        if ch == "," and not quoted:
            items.append(buf)
            buf = ""
        else:
            buf += ch
    items.append(buf)
    entries = []
    for item in items:
        var, sep, value = item.partition("=")
        var, value = var.strip(), value.strip()
        if not sep or not var or not value or any(c.isspace() for c in var):
            raise MissionFileError.at(src, f"bad initialize '{item.strip()}': expected VAR = value")
        number = as_number(value)
        if number is None and len(value) >= 2 and value[0] == value[-1] == '"':
            value = value[1:-1]
        entries.append(InitEntry(var=var, value=number if number is not None else value,
                                 deferred=deferred, file=src.file, line=src.line))
    return entries


def _check_general(spec: BehaviorSpec) -> None:
    """Syntax checks every behaviour type shares: conditions, flags, pwt, name, duration.

    A value still holding an nsplug macro (`$(X)`, `%(X)`) that fails is let through: a template
    is judged after expansion (the helm re-checks every value when it builds the behaviour).
    """
    for p in spec.params:
        problem = _general_problem(p.key.lstrip("_"), p.value)
        if problem and not ("$(" in p.value or "%(" in p.value):
            raise p.error(f"{p.key}: {problem}")


def _general_problem(key: str, value: str) -> str | None:
    """What the helm would reject in a general line, judged by the parameter's own declaration."""
    if key in ("name", "descriptor") and not _NAME_OK.match(value):
        return f"bad behavior name '{value}'"
    spec = IvPBehavior.spec_for(key)
    if key in ("cycleflag", "wptflag"):
        spec = flag_param(key)
    if spec is None or key not in CHECKED_AT_PARSE:
        return None
    try:
        spec.apply(IvPBehavior(IvPDomain(vars=[]), InfoBuffer()), value, key)
    except ValueError as exc:
        return str(exc).removeprefix(f"{key} ")
    return None


class _Parser:
    def __init__(self, path: Path):
        self.result = BhvFile(path=path)
        self.state = "top"
        self.mode: ModeEntry | None = None
        self.bhv: BehaviorSpec | None = None

    def close_mode(self) -> None:
        if self.mode is not None:
            self.result.modes.append(self.mode)
            self.mode = None

    def feed(self, src: SourceLine) -> None:
        text = src.text
        state = self.state
        if not text:
            if state == "misc-defined-ish":
                self.state = "top"
            elif state == "set-defined-ish":
                self.close_mode()
                self.state = "top"
            return
        if text == "{":
            nxt = {"top": "misc-defining", "bhv-declared": "bhv-defining",
                   "set-declared": "set-defining"}.get(state)
            if nxt is None:
                raise MissionFileError.at(src, "unexpected '{'")
            self.state = nxt
            return
        if text == "}":
            if state == "misc-defining":
                self.state = "misc-defined-ish"
            elif state == "bhv-defining":
                spec, self.bhv, self.state = self.bhv, None, "top"
                self.result.behaviors.append(spec)
                _check_general(spec)      # after closing the block: a caller collecting errors reads on
            elif state == "set-defining":
                self.state = "set-defined-ish"
            else:
                raise MissionFileError.at(src, "unexpected '}'")
            return
        if state == "misc-defining":
            return
        if state == "bhv-defining":
            key, sep, value = text.partition("=")
            if not sep or not key.strip():
                raise MissionFileError.at(src, f"expected 'param = value' in Behavior block, got '{text}'")
            self.bhv.params.append(BhvParam(key="".join(key.split()).lower(), value=value.strip(),
                                            file=src.file, line=src.line))
            return
        if state == "set-defining":
            self.add_mode_condition(src, text)
            return
        if state in ("bhv-declared", "set-declared"):
            raise MissionFileError.at(src, f"expected '{{' after the header, got '{text}'")
        if self.statement(src, text):
            return
        if state == "set-defined-ish":
            if len(text.split()) != 1:
                raise MissionFileError.at(src, f"mode else-value must be one word, got '{text}'")
            self.mode.else_value = text
            self.close_mode()
            self.state = "top"
            return
        raise MissionFileError.at(src, f"unexpected line outside any block: '{text}'")

    def statement(self, src: SourceLine, text: str) -> bool:
        low = text.lower()
        if low.startswith("initialize ") or low.startswith("initialize_ "):
            self.close_mode()
            deferred = text.startswith("initialize_ ")
            self.result.initializes += _init_entries(src, text.split(None, 1)[1], deferred)
            self.state = "top"
            return True
        if low.startswith("set "):
            self.close_mode()
            var, sep, value = text[4:].partition("=")
            var, value = var.strip(), value.strip()
            if not sep or not var or not value or any(c.isspace() for c in var):
                raise MissionFileError.at(src, f"expected 'set VAR = VALUE', got '{text}'")
            self.mode = ModeEntry(var=var, value=value, file=src.file, line=src.line)
            self.state = "set-declared"
            return True
        if low.startswith("behavior"):
            self.close_mode()
            _, sep, btype = text.partition("=")
            btype = btype.strip()
            if not sep or not btype or any(c.isspace() for c in btype):
                raise MissionFileError.at(src, f"expected 'Behavior = BHV_Type', got '{text}'")
            self.bhv = BehaviorSpec(type=btype, file=src.file, line=src.line)
            self.state = "bhv-declared"
            return True
        return False

    def add_mode_condition(self, src: SourceLine, text: str) -> None:
        try:
            cond = parse_mode_condition(text)
        except ConditionError as exc:
            raise MissionFileError.at(src, f"bad mode condition: {exc}") from None
        self.mode.conditions.append(cond)
        if isinstance(cond, Relation) and cond.var == self.mode.var and cond.op == "=":
            self.mode.mode_var_conditions.append(cond)
            if not self.mode.prefix:
                self.mode.prefix = str(cond.literal) if cond.literal is not None else ""

    def finish(self, last: SourceLine | None) -> BhvFile:
        if self.state in ("bhv-declared", "bhv-defining", "set-declared", "set-defining", "misc-defining"):
            where = last or SourceLine("", self.result.path, 0)
            raise MissionFileError.at(where, f"unexpected end of file (unclosed block, state {self.state})")
        self.close_mode()
        seen: dict[str, BehaviorSpec] = {}
        for spec in self.result.behaviors:
            if spec.name in seen:
                raise MissionFileError(spec.file, spec.line,
                                       f"duplicate behavior name '{spec.name}' (first at line {seen[spec.name].line})")
            seen[spec.name] = spec
        return self.result


def parse_bhv(lines: list[SourceLine], path: Path | str | None = None,
              errors: list[MissionFileError] | None = None) -> BhvFile:
    """Parse preprocessed `.bhv` lines (e.g. nsplug output) into a BhvFile.

    The helm stops at the first bad line. Given `errors` (moos-lint), each bad line is recorded there
    and skipped instead, so one pass names them all; the BhvFile then holds what did parse.
    """
    path = Path(path) if path is not None else (lines[0].file if lines else Path("<bhv>"))
    parser = _Parser(path)
    last = None
    for src in _logical_lines(lines):
        for piece in _pieces(src):
            try:
                parser.feed(piece)
            except MissionFileError as exc:
                if errors is None:
                    raise
                errors.append(exc)
            last = piece
    try:
        return parser.finish(last)
    except MissionFileError as exc:
        if errors is None:
            raise
        errors.append(exc)
        return parser.result


def read_bhv(path: Path | str) -> BhvFile:
    """Read a `.bhv` file as the helm does (no nsplug: `#` lines are comments)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="latin-1")
    except OSError as exc:
        raise MissionFileError(path, 0, f"cannot read behavior file: {exc.strerror}") from None
    return parse_bhv([SourceLine(t, path, i) for i, t in enumerate(text.splitlines(), 1)], path)
