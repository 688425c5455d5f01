"""The MOOS-IvP logic-condition language (behaviour conditions, mode sets, flag `[if]` parts).

Grammar and evaluation quirks follow the reference (spec: docs/spec/mission-files.md §2.7): an unknown
variable makes every relation false, `==` on strings is a colon-field match, and `and`/`or`
need parenthesised operands.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator, Union

from moosdb_py.formats import is_number, parse_number

Value = Union[float, str]
Lookup = Callable[[str], "Value | None"]

RELATION_OPS = ("==", "=", "!=", ">=", "<=", ">", "<")
_BAD_NAME_CHARS = set('"><=!()')


class ConditionError(ValueError):
    """A condition string that does not parse; the message says what was expected."""


def as_number(text: str) -> float | None:
    """A MOOS number (moosdb_py.formats: decimal or exponent form, finite), or None."""
    return parse_number(text) if is_number(text) else None


@dataclass(frozen=True)
class Relation:
    var: str
    op: str
    literal: Value | None = None  # number or string; None when comparing with another variable
    other_var: str | None = None

    def variables(self) -> Iterator[str]:
        yield self.var
        if self.other_var:
            yield self.other_var

    def evaluate(self, lookup: Lookup) -> bool:
        left = lookup(self.var)
        right = lookup(self.other_var) if self.other_var else self.literal
        if left is None or right is None:
            return False
        return compare(left, self.op, right)

    def __str__(self) -> str:
        rhs = f"$({self.other_var})" if self.other_var else _fmt_literal(self.literal)
        return f"{self.var}{self.op}{rhs}"


@dataclass(frozen=True)
class Not:
    operand: "Condition"

    def variables(self) -> Iterator[str]:
        yield from self.operand.variables()

    def evaluate(self, lookup: Lookup) -> bool:
        return not self.operand.evaluate(lookup)

    def __str__(self) -> str:
        return f"!({self.operand})"


@dataclass(frozen=True)
class Junction:
    op: str  # "and" | "or"
    left: "Condition"
    right: "Condition"

    def variables(self) -> Iterator[str]:
        yield from self.left.variables()
        yield from self.right.variables()

    def evaluate(self, lookup: Lookup) -> bool:
        if self.op == "and":
            return self.left.evaluate(lookup) and self.right.evaluate(lookup)
        return self.left.evaluate(lookup) or self.right.evaluate(lookup)

    def __str__(self) -> str:
        return f"({self.left}) {self.op} ({self.right})"


Condition = Union[Relation, Not, Junction]


def _fmt_literal(v: Value | None) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def field_match(a: str, b: str) -> bool:
    """`a == b` on strings: the shorter colon-field list must be a run of fields in the other.

    Reproduces the reference's slip that makes any pattern of three or more fields fail.
    """
    if a not in b and b not in a:
        return False
    fa = [f.strip() for f in a.split(":")]
    fb = [f.strip() for f in b.split(":")]
    pattern, target = (fa, fb) if len(fa) < len(fb) else (fb, fa)
    k = len(pattern)
    if k >= 3:
        return False
    return any(target[i:i + k] == pattern for i in range(len(target) - k + 1))


def compare(left: Value, op: str, right: Value) -> bool:
    """Compare an info-buffer value with a literal or another variable's value, MOOS style."""
    if isinstance(left, str) and isinstance(right, str):
        right = right.strip('"') if len(right) >= 2 and right[0] == right[-1] == '"' else right
        if op == "==":
            return field_match(left, right)
        a, b = left, right
    else:
        a = left if isinstance(left, float) else as_number(left)
        b = right if isinstance(right, float) else as_number(right)
        if a is None or b is None:
            return False
    if op in ("=", "=="):
        return a == b
    if op == "!=":
        return a != b
    if op == "<":
        return a < b
    if op == ">":
        return a > b
    if op == "<=":
        return a <= b
    return a >= b


def _depth0_positions(text: str) -> Iterator[int]:
    depth = 0
    in_quote = False
    for i, ch in enumerate(text):
        if ch == '"':
            in_quote = not in_quote
        elif not in_quote and ch == "(":
            depth += 1
        elif not in_quote and ch == ")":
            depth -= 1
            if depth < 0:
                raise ConditionError("unbalanced ')'")
        elif depth == 0 and not in_quote:
            yield i
    if depth != 0:
        raise ConditionError("unbalanced '('")


def _one_group(text: str) -> bool:
    """True when text is `( ... )` with the first parenthesis closing at the very end."""
    if not (text.startswith("(") and text.endswith(")")):
        return False
    depth = 0
    for i, ch in enumerate(text):
        depth += ch == "("
        depth -= ch == ")"
        if depth == 0 and i < len(text) - 1:
            return False
    return True


def _strip_outer_parens(text: str) -> str:
    text = text.strip()
    while _one_group(text):
        text = text[1:-1].strip()
    return text


def _is_grouped(text: str) -> bool:
    t = text.strip()
    return _one_group(t[1:].strip() if t.startswith("!") else t)


def parse_condition(text: str) -> Condition:
    """Parse one condition; raises ConditionError naming what is wrong."""
    raw = text
    text = _strip_outer_parens(text)
    if not text:
        raise ConditionError(f"empty condition in '{raw}'")
    lowered = text.lower()
    positions = list(_depth0_positions(text))
    for word in (" or ", " and "):
        for i in positions:
            if lowered.startswith(word, i):
                left, right = text[:i], text[i + len(word):]
                if not (_is_grouped(left) and _is_grouped(right)):
                    raise ConditionError(
                        f"both sides of '{word.strip()}' must be in parentheses: '{raw}'")
                return Junction(word.strip(), parse_condition(left), parse_condition(right))
    if text.startswith("!") and _is_grouped(text):
        return Not(parse_condition(text[1:]))
    for i in positions:
        for op in RELATION_OPS:
            if text.startswith(op, i):
                return _relation(text[:i], op, text[i + len(op):], raw)
    raise ConditionError(f"no relation operator (=, ==, !=, <, <=, >, >=) in '{raw}'")


def _relation(lhs: str, op: str, rhs: str, raw: str) -> Relation:
    var, rhs = lhs.strip(), rhs.strip()
    if not var or any(c in _BAD_NAME_CHARS for c in var) or var.lower() in ("and", "or") or " " in var:
        raise ConditionError(f"bad variable name '{var}' in '{raw}'")
    if not rhs:
        raise ConditionError(f"missing value after '{op}' in '{raw}'")
    unquoted = rhs[1:-1] if len(rhs) >= 2 and rhs[0] == rhs[-1] == '"' else None
    if unquoted is None and not rhs.startswith("$(") and any(c in "=<>!()" for c in rhs):
        raise ConditionError(f"bad value '{rhs}' in '{raw}'")
    if rhs.startswith("$(") and rhs.endswith(")"):
        return Relation(var, op, other_var=rhs[2:-1].strip())
    if unquoted is not None:
        return Relation(var, op, literal=unquoted)
    number = as_number(rhs)
    return Relation(var, op, literal=number if number is not None else rhs)


def parse_behavior_condition(text: str) -> Condition:
    """A behaviour's `condition =` value: every comma becomes `=` first (legacy `VAR,value`)."""
    return parse_condition(text.replace(",", "="))


def parse_mode_condition(text: str) -> Condition:
    """A condition inside a `set` block, where a top-level `==` is not allowed."""
    cond = parse_condition(text)
    if isinstance(cond, Relation) and cond.op == "==":
        raise ConditionError(f"'==' is not allowed in a mode (set) block: '{text}'")
    return cond


def condition_variables(conditions) -> list[str]:
    """All variable names the conditions read, in first-seen order."""
    seen: dict[str, None] = {}
    for c in conditions:
        for v in c.variables():
            seen.setdefault(v, None)
    return list(seen)
