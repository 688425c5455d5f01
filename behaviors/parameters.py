"""Declared behaviour parameters: each behaviour type states once what it accepts.

A parameter is a `ParamSpec`: its names (the first is the one documented, the rest are aliases),
a parser turning the `.bhv` text into a value, what setting it does (an attribute or a method),
its default and a one-line description. `IvPBehavior.apply`, the docs tables
(`parameter_table`) and moos-lint all read `cls.parameters`, so they cannot disagree.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Iterable

from moosdb_py import formats


@dataclass(frozen=True)
class Parser:
    """A named text-to-value conversion; `kind` is what the docs table says the value is."""

    kind: str
    convert: Callable[[str, str], Any]

    def __call__(self, value: str, key: str) -> Any:
        return self.convert(value, key)


def parse_bool(value: str, what: str) -> bool:
    """A MOOS boolean (moosdb_py.formats: true/on/number > 0, false/off/number <= 0, any case)."""
    try:
        return formats.parse_bool(value)
    except formats.FormatError:
        raise ValueError(f"{what} must be true or false (on/off, or a number), got '{value}'") from None


def parse_number(value: str, what: str, minimum: float | None = None) -> float:
    """A MOOS number (moosdb_py.formats), at least `minimum` when given."""
    number = formats.parse_number(value) if formats.is_number(value) else None
    if number is None or (minimum is not None and number < minimum):
        bound = f" >= {minimum:g}" if minimum is not None else ""
        raise ValueError(f"{what} must be a number{bound}, got '{value}'")
    return number


TEXT = Parser("string", lambda value, key: value)
BOOLEAN = Parser("boolean", parse_bool)
NUMBER = Parser("number", parse_number)
NON_NEGATIVE = Parser("number >= 0", lambda value, key: parse_number(value, key, 0))


def positive(value: str, key: str) -> float:
    number = parse_number(value, key, 0)
    if number <= 0:
        raise ValueError(f"{key} must be > 0, got '{value}'")
    return number


POSITIVE = Parser("number > 0", positive)


def one_of(*choices: str) -> Parser:
    """A word from a fixed list (case-insensitive), returned lower-cased."""
    def convert(value: str, key: str) -> str:
        low = value.strip().lower()
        if low not in choices:
            raise ValueError(f"{key} must be {', '.join(choices[:-1])} or {choices[-1]}, got '{value}'")
        return low
    return Parser(" \\| ".join(choices), convert)


@dataclass(frozen=True)
class ParamSpec:
    """One parameter: `setter(bhv, parsed)` does the work. An `attr` parameter's attribute is set at
    construction to its parsed default (None without one), so a declared default is the real one."""

    names: tuple[str, ...]
    parse: Parser
    setter: Callable[[Any, Any], None]
    default: str | None = None
    doc: str = ""
    attr: str = ""

    @property
    def name(self) -> str:
        return self.names[0]

    def apply(self, bhv: Any, value: str, key: str) -> None:
        self.setter(bhv, self.parse(value, key))


def attr(names: str | tuple[str, ...], attribute: str, parse: Parser = TEXT, default: str | None = None,
         doc: str = "") -> ParamSpec:
    """A parameter that sets one attribute to its parsed value."""
    names = (names,) if isinstance(names, str) else names
    return ParamSpec(names, parse, lambda bhv, v: setattr(bhv, attribute, v), default, doc, attribute)


def accepted(names: Iterable[str], doc: str, parse: Parser = TEXT) -> ParamSpec:
    """A parameter read (and checked) for compatibility that changes nothing here."""
    return ParamSpec(tuple(names), parse, lambda bhv, v: None, None, doc)


def pair_bound(name: str, low: str, high: str, sets_low: bool, default: str, doc: str) -> ParamSpec:
    """One end of a (low, high) pair of attributes, MOOS-IvP's min/max "part of pair": setting one
    end moves the other with it when they would cross."""
    def set_end(bhv: Any, value: float) -> None:
        lo, hi = getattr(bhv, low), getattr(bhv, high)
        lo, hi = (value, max(hi, value)) if sets_low else (min(lo, value), value)
        setattr(bhv, low, lo)
        setattr(bhv, high, hi)
    return ParamSpec((name,), NON_NEGATIVE, set_end, default, doc)


def param(*names: str, parse: Parser = TEXT, default: str | None = None, doc: str = ""):
    """Decorator: the method `(self, parsed_value)` sets the parameter."""
    def wrap(fn):
        fn.param_spec = ParamSpec(names, parse, fn, default, doc)
        return fn
    return wrap


def collect(cls: type, inherited: dict[str, ParamSpec]) -> dict[str, ParamSpec]:
    """The class's table: the inherited one, then its `params` tuple and `@param` methods."""
    table = dict(inherited)
    own = list(vars(cls).get("params", ()))
    own += [fn.param_spec for fn in vars(cls).values() if hasattr(fn, "param_spec")]
    for spec in own:
        for name in spec.names:
            table[name] = spec
    return table


def unique_specs(table: dict[str, ParamSpec]) -> list[ParamSpec]:
    return list({id(s): s for s in table.values()}.values())


def parameter_table(table: dict[str, ParamSpec], skip: dict[str, ParamSpec] | None = None) -> str:
    """The markdown table of a behaviour type's parameters, less those in `skip` (the general ones);
    docs/behaviors.md embeds these tables and a test keeps them in step."""
    skipped = {id(s) for s in (skip or {}).values()}
    rows = ["| parameter | value | default | meaning |", "|---|---|---|---|"]
    for spec in unique_specs(table):
        if id(spec) in skipped:
            continue
        names = ", ".join(f"`{n}`" for n in spec.names)
        default = f"`{spec.default}`" if spec.default not in (None, "") else ""
        rows.append(f"| {names} | {spec.parse.kind} | {default} | {spec.doc} |")
    return "\n".join(rows)
