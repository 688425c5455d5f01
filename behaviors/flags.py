"""Behaviour flags (`runflag = VAR = value [if] cond`) and `$[MACRO]` expansion at posting time.

Spec: docs/spec/mission-files.md §2.5 (flag grammar) and docs/spec/ivp-helm.md §5.8 (macros).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Callable, Mapping, Union

from .geometry import fmt_num
from .logic import Condition, ConditionError, Lookup, as_number, parse_condition

Value = Union[float, str]
FLAG_KINDS = ("runflag", "runxflag", "idleflag", "activeflag", "inactiveflag", "endflag",
              "configflag", "spawnflag", "spawnxflag")
_MACRO = re.compile(r"\$\[([^\]\[]+)\]|\$\(([^()]+)\)")


class FlagError(ValueError):
    """A flag line that does not follow `[@tag ][#dest ]VAR = value [[if] condition]`."""


@dataclass(frozen=True)
class FlagSpec:
    var: str
    value: Value
    tag: str = ""
    dest: str = ""
    condition: Condition | None = None

    def holds(self, lookup: Lookup) -> bool:
        return self.condition is None or self.condition.evaluate(lookup)


def parse_flag(text: str) -> FlagSpec | None:
    """Parse a flag value; None means `clearall` (empty this flag list)."""
    text = text.strip()
    if text.lower() == "clearall":
        return None
    tag = dest = ""
    words = text.split(None, 1)
    if words and words[0][:1] in "@<>" and len(words) == 2:
        tag, text = words[0], words[1]
        words = text.split(None, 1)
    if words and words[0].startswith("#") and len(words) == 2:
        dest, text = words[0], words[1]
    condition = None
    if "[if]" in text:
        text, cond_text = text.split("[if]", 1)
        try:
            condition = parse_condition(cond_text)
        except ConditionError as exc:
            raise FlagError(f"bad [if] condition: {exc}") from None
    var, sep, value = text.partition("=")
    var, value = var.strip(), value.strip()
    if not sep or not var or not value:
        raise FlagError(f"expected VAR = value, got '{text.strip()}'")
    if any(c.isspace() for c in var):
        raise FlagError(f"flag variable '{var}' contains blanks")
    number = as_number(value)
    return FlagSpec(var, number if number is not None else value, tag, dest, condition)


def expand_macros(value: Value, macros: Mapping[str, Value] | Callable[[str], Value | None]) -> Value:
    """Expand `$[NAME]`/`$(NAME)`; unknown macros stay as typed. A lone numeric macro stays a number."""
    if not isinstance(value, str) or "$" not in value:
        return value
    get = macros.get if isinstance(macros, Mapping) else macros
    whole = _MACRO.fullmatch(value)
    if whole:
        got = get(whole.group(1) or whole.group(2))
        if isinstance(got, (int, float)) and not isinstance(got, bool):
            return float(got)

    def one(m: re.Match) -> str:
        got = get(m.group(1) or m.group(2))
        if got is None:
            return m.group(0)
        return fmt_num(got) if isinstance(got, (int, float)) and not isinstance(got, bool) else str(got)

    return _MACRO.sub(one, value)
