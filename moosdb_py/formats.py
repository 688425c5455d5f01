"""MOOS's small text formats, each with one meaning for every app, behaviour and tool.

MOOS passes everything as strings, so a handful of conventions carry the data: booleans,
numbers, `key=value` lists, point lists (seglists, `pts={x,y:...}`), `*`/`?` wildcards. Each is
defined here once; readers raise `FormatError` (a ValueError) naming what was wrong, and the
caller adds where it came from (file:line, sender).

The rules chosen (docs/formats.md says the same):

* **Booleans.** MOOS core's ProcessConfigReader reads `TRUE` (any case) or a number > 0 as
  true and anything else as false; the IvP apps (setBooleanOnString) take `true`/`on` and
  `false`/`off` in any case and reject the rest. One rule that agrees with both wherever both
  give an answer: `true`/`on` or a number > 0 is true, `false`/`off` or a number <= 0 is
  false, case-insensitive; anything else (`yes`, `no`, a typo) is an error rather than a
  silent false.
* **Numbers** parse as MOOS's atof on a numeric string: decimal or exponent form, finite.
  They print as MOOS's doubleToStringX: fixed point with `digits` decimals, trailing zeros
  and a bare point removed, `-0` as `0`.
* **key=value lists** split on commas outside braces (so `pts={1,2:3,4}` stays one value);
  keys are case-insensitive (lower-cased here), values are stripped, the last repeat wins,
  empty items are skipped and an item without `=` is an error.
* **Seglists**: `pts={x,y:x,y}` (the standard form, possibly inside a key=value list), the
  abbreviated `x,y:x,y` (optionally after `pts:` or `points:`), vertices as `x,y`, `x,y,z`
  (z ignored) or `x=..,y=..`; items like `label,foo` in the abbreviated form are properties,
  not vertices, but a lone word (`60,-40:oops`) is an error. Generated patterns (`format=lawnmower`, `radial:`...) are not point lists:
  the geometry library that builds them reads those.
* **Wildcards** are MOOSWildCmp: whole string, case-sensitive, only `*` and `?` special.
"""
from __future__ import annotations

import functools
import math
import os
import re
import sys
from collections.abc import Iterable, Mapping
from importlib import metadata


class FormatError(ValueError):
    """A string that does not follow the MOOS format it should."""


TRUE_WORDS = frozenset({"true", "on"})
FALSE_WORDS = frozenset({"false", "off"})

# MOOS's numeric strings: what atof reads completely; Python's extras (`1_0`, `nan`, `inf`) are not numbers here.
_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?\Z")
_NON_FINITE = re.compile(r"[+-]?(?:nan|inf|infinity)\Z", re.IGNORECASE)


def is_number(text: str) -> bool:
    return _NUMBER.match(str(text).strip()) is not None


def parse_number(text: str) -> float:
    """A MOOS number; FormatError for anything else, infinities included."""
    word = str(text).strip()
    value = float(word) if _NUMBER.match(word) or _NON_FINITE.match(word) else None
    if value is None:
        raise FormatError(f"expected a number, got {text!r}")
    if not math.isfinite(value):
        raise FormatError(f"expected a finite number, got {text!r}")
    return value


def format_number(value: float, digits: int = 5) -> str:
    """MOOS's doubleToStringX: `digits` decimals, trailing zeros and a bare point removed, never `-0`."""
    text = "%.*f" % (digits, float(value))     # printf-style: half an f-string's cost (every helm iteration)
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def format_fixed(value: float, digits: int = 5) -> str:
    """MOOS's doubleToString: exactly `digits` decimals (for strings that keep a fixed column width)."""
    return f"{float(value):.{digits}f}"


def parse_bool(text: str) -> bool:
    """`true`/`on`/number > 0 -> True, `false`/`off`/number <= 0 -> False (any case); else FormatError."""
    word = str(text).strip().lower()
    if word in TRUE_WORDS:
        return True
    if word in FALSE_WORDS:
        return False
    if is_number(word):
        return float(word) > 0
    raise FormatError(f"expected true or false, got {text!r}")


def format_bool(value: bool) -> str:
    """MOOS's boolToString."""
    return "true" if value else "false"


def split_fields(text: str, sep: str = ",") -> list[str]:
    """`text` split at `sep` outside braces and double quotes (MOOS's parseStringQ), quotes kept:
    `a=1,pts={1,2:3,4},s="x,y"` -> ['a=1', 'pts={1,2:3,4}', 's="x,y"']; an unclosed quote is an error."""
    if '"' not in text and "{" not in text:   # nothing to protect (every NODE_REPORT): a plain split
        return text.split(sep)
    fields, depth, quoted, start = [], 0, False, 0
    for i, char in enumerate(text):
        if char == '"':
            quoted = not quoted
        elif quoted:
            continue
        elif char == "{":
            depth += 1
        elif char == "}":
            depth = max(depth - 1, 0)
        elif char == sep and depth == 0:
            fields.append(text[start:i])
            start = i + 1
    if quoted:
        raise FormatError(f"unclosed double quote in {text!r}")
    fields.append(text[start:])
    return fields


def unquote(value: str) -> str:
    """A value without the double quotes around it (`"a, b"` -> `a, b`), as a quoted field means it."""
    value = value.strip()
    return value[1:-1] if len(value) >= 2 and value[0] == value[-1] == '"' else value


def split_quoted(text: str, sep: str = ",") -> list[str]:
    """The non-empty fields of `text`, stripped, each value without its surrounding double quotes
    (`a=1, b="x,y"` -> ['a=1', 'b=x,y']): how NODE_MESSAGE and contact-manager alert lines are read."""
    parts = []
    for item in split_fields(str(text), sep):
        key, eq, value = item.partition("=")
        if item.strip():
            parts.append(f"{key.strip()}={unquote(value)}" if eq else unquote(item))
    return parts


def parse_pairs(text: str, sep: str = ",", unquoted: bool = False) -> dict[str, str]:
    """`a=1, B = x,pts={1,2:3,4}` -> {'a': '1', 'b': 'x', 'pts': '{1,2:3,4}'}; with `unquoted`, values
    lose their surrounding double quotes (`s="x,y"` -> 'x,y')."""
    pairs: dict[str, str] = {}
    for item in split_fields(str(text), sep):
        if not item.strip():
            continue
        key, eq, value = item.partition("=")
        if not eq or not key.strip():
            raise FormatError(f"{item.strip()!r} is not key=value")
        pairs[key.strip().lower()] = unquote(value) if unquoted else value.strip()
    return pairs


def format_pairs(pairs: Mapping[str, object] | Iterable[tuple[str, object]], sep: str = ",") -> str:
    """{'a': 1, 'b': 'x'} -> `a=1,b=x`; numbers are written with format_number."""
    items = pairs.items() if isinstance(pairs, Mapping) else pairs
    return sep.join(f"{key}={format_number(value) if isinstance(value, float) else value}" for key, value in items)


def _vertex(item: str, index: int, abbreviated: bool) -> tuple[float, float] | None:
    """One `x,y[,z]` or `x=..,y=..` vertex; None for a `label,foo` property item of the abbreviated form."""
    if "=" in item:
        props = parse_pairs(item)
        if "x" not in props or "y" not in props:
            raise FormatError(f"vertex {index} {item!r} needs x= and y=")
        return _coordinate(props["x"], item, index), _coordinate(props["y"], item, index)
    fields = item.split(",")
    if not is_number(fields[0]) and abbreviated and len(fields) > 1:
        return None    # `oops` alone is neither a vertex nor a property: MOOS-IvP rejects the whole list
    if len(fields) < 2:
        raise FormatError(f"vertex {index} {item!r} is not x,y")
    if len(fields) > 3:
        raise FormatError(f"vertex {index} {item!r} has more than x,y,z")
    return _coordinate(fields[0], item, index), _coordinate(fields[1], item, index)


def _coordinate(text: str, item: str, index: int) -> float:
    try:
        return parse_number(text)
    except FormatError:
        raise FormatError(f"vertex {index} {item!r} is not x,y") from None


def parse_seglist(text: str) -> list[tuple[float, float]]:
    """The vertices of a point list in standard (`pts={...}`) or abbreviated (`x,y:x,y`) form."""
    s = "".join(str(text).split())
    low = s.lower()
    if low.startswith("format=") or low.startswith("radial:"):
        raise FormatError(f"{text!r} is a generated pattern, not a point list")
    abbreviated = not (low.startswith("{") or "pts={" in low)
    if not abbreviated:
        pairs = parse_pairs(s) if not low.startswith("{") else {"pts": s}
        if "pts" not in pairs:
            raise FormatError(f"no pts={{...}} in {text!r}")
        body = pairs["pts"]
        if not (body.startswith("{") and body.endswith("}")):
            raise FormatError(f"unclosed 'pts={{' in {text!r}")
        body = body[1:-1]
    else:
        body = s
        for prefix in ("pts:", "points:"):
            if low.startswith(prefix):
                body = s[len(prefix):]
    items = [item for item in body.split(":") if item]
    points = [v for v in (_vertex(item, i, abbreviated) for i, item in enumerate(items, 1)) if v is not None]
    if not points:
        raise FormatError(f"no points in {text!r}")
    return points


def format_points(points: Iterable[Iterable[float]], digits: int = 3, fixed: bool = False) -> str:
    """The abbreviated `x,y:x,y` form (numbers as format_number, or format_fixed when `fixed`)."""
    number = format_fixed if fixed else format_number
    return ":".join(f"{number(x, digits)},{number(y, digits)}" for x, y, *_ in points)


def format_seglist(points: Iterable[Iterable[float]], digits: int = 3, fixed: bool = False) -> str:
    """The standard `pts={x,y:x,y}` form."""
    return "pts={" + format_points(points, digits, fixed) + "}"


@functools.lru_cache(maxsize=4096)
def _glob(pattern: str) -> re.Pattern:
    return re.compile("".join(".*" if c == "*" else "." if c == "?" else re.escape(c) for c in pattern) + r"\Z",
                      re.DOTALL)


def wild_match(pattern: str, text: str) -> bool:
    """MOOSWildCmp: `pattern` matches the whole of `text`, case-sensitive, `*` any run, `?` one character."""
    return _glob(pattern).match(text) is not None


def is_pattern(text: str) -> bool:
    return "*" in text or "?" in text


def version_page(name: str) -> str:
    """What `APP --version` prints: the app's MOOS name and this package's release."""
    try:
        release = metadata.version("oilspill-moos")
    except metadata.PackageNotFoundError:   # run from a source tree that was never installed
        release = "unknown"
    return f"{name} {release} (oilspill-moos: the MOOS-IvP app in Python)\n"


def print_page(text: str) -> None:
    """Print a --help/--example/--interface page; a reader that stops early (`| head`) is no error."""
    try:
        sys.stdout.write(text)
        sys.stdout.flush()
    except BrokenPipeError:
        # Python flushes stdout again at exit: point it at /dev/null so that flush cannot fail too.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
