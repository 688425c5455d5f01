"""Reading typed values out of a ProcessConfig block, with errors that name the parameter.

The functions take anything with `get(key, default)` whose keys are the lower-case
parameter names: a `moosdb_py.mission.ProcessConfig` (case-insensitive, last one
wins) or a plain dict, which keeps the vehicle models testable without a mission.
"""
from __future__ import annotations

import logging
import math
from typing import Protocol


class ConfigLike(Protocol):
    def get(self, key: str, default=None): ...


log = logging.getLogger("oilspill_moos.app_config")

# Parameters every MOOS app's block may hold; they are read by the MOOSApp base.
MOOS_APP_KEYS = frozenset({"apptick", "commstick", "maxappticks", "iteratemode", "verbose", "debug"})

TRUE_WORDS = {"true", "yes", "on", "1"}
FALSE_WORDS = {"false", "no", "off", "0"}


class ConfigValueError(ValueError):
    """A bad parameter value; `key` is the parameter, so the app can point at its file:line."""

    def __init__(self, what: str, message: str):
        self.key = what.split()[0]
        super().__init__(f"{what}: {message}")


def read_params(config, reader):
    """`reader(config)`, with a bad value reported at its mission-file line (`file:line: key: ...`)."""
    try:
        return reader(config)
    except ConfigValueError as err:
        entry = config.entry(err.key) if hasattr(config, "entry") else None
        if entry is None:
            raise
        raise entry.source.error(str(err)) from None


def unhandled_entries(config, known: set[str] | frozenset[str]) -> list[str]:
    """`file:line: key` for each parameter of the block that the app does not use."""
    return [f"{entry.source}: unhandled parameter {entry.key!r}" for entry in getattr(config, "entries", [])
            if entry.key.lower() not in known and entry.key.lower() not in MOOS_APP_KEYS]


def warn_unhandled(config, known: set[str] | frozenset[str]) -> None:
    """Log every unused parameter of the block: a misspelt key would otherwise fall back to its default unseen."""
    for warning in unhandled_entries(config, known):
        log.warning("%s", warning)


def parse_bool(text: str, what: str) -> bool:
    word = str(text).strip().lower()
    if word in TRUE_WORDS:
        return True
    if word in FALSE_WORDS:
        return False
    raise ConfigValueError(what, f"expected true or false, got {text!r}")


def parse_float(text: str, what: str, lo: float | None = None, hi: float | None = None) -> float:
    try:
        value = float(str(text).strip())
    except ValueError:
        raise ConfigValueError(what, f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise ConfigValueError(what, f"expected a finite number, got {text!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise ConfigValueError(what, f"{value:g} is outside [{lo}, {hi}]")
    return value


def config_float(cfg: ConfigLike, key: str, default: float, lo: float | None = None,
                 hi: float | None = None) -> float:
    text = cfg.get(key, None)
    if text is None or str(text).strip() == "":
        return default
    return parse_float(text, key, lo, hi)


def config_bool(cfg: ConfigLike, key: str, default: bool) -> bool:
    text = cfg.get(key, None)
    if text is None or str(text).strip() == "":
        return default
    return parse_bool(text, key)


def config_str(cfg: ConfigLike, key: str, default: str) -> str:
    text = cfg.get(key, None)
    if text is None or str(text).strip() == "":
        return default
    return str(text).strip()


def parse_pairs(text: str) -> dict[str, str]:
    """`a=1, b = x` -> {'a': '1', 'b': 'x'} (keys lower-cased; last one wins)."""
    pairs: dict[str, str] = {}
    for part in str(text).split(","):
        if not part.strip():
            continue
        key, sep, value = part.partition("=")
        if not sep:
            raise ValueError(f"{part.strip()!r} is not a key=value pair")
        pairs[key.strip().lower()] = value.strip()
    return pairs


def format_number(value: float, decimals: int = 2) -> str:
    """Fixed point with at most `decimals` places, trailing zeros (and a bare point) removed, as MOOS writes numbers into report strings."""
    text = f"{value:.{decimals}f}"
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text
